"""campaign sweep: parsing, one campaign per value on the same encounters, resume, table, collate."""

import json
from pathlib import Path

import numpy as np
import pytest

from daa_sil.study.campaign.files import read_results
from daa_sil.cli import main
from daa_sil.errors import UsageError
from daa_sil.study.analysis.sweep import parse_vary


def test_parse_vary():
    v = parse_vary("wt=2,4,8")
    assert (v.name, v.field, v.values, v.numeric) == ("wt", "wait_threshold_s", (2.0, 4.0, 8.0), True)
    lat = parse_vary("latency=const:0.2;gauss:5,3")
    assert lat.values == ("const:0.2", "gauss:5,3") and not lat.numeric
    assert parse_vary("intruders=1,2").values == (1, 2) and parse_vary("intruders=1,2").field == "n_intruders"
    for bad, msg in (("colour=1,2", "NAME one of"), ("wt=2", "at least two values"), ("wt=a,b", "must be floats"),
                     ("wt=2,2", "given twice"), ("wt", "NAME=V1,V2")):
        with pytest.raises(UsageError, match=msg):
            parse_vary(bad)


def test_sweep_runs_each_value_on_the_same_encounters_and_resumes(tmp_path, capsys):
    out = tmp_path / "sw"
    argv = ["campaign", "sweep", "--vary", "wt=2,30", "--groups", "ID-2", "--encounters", "30", "--duration", "240",
            "--chunk-size", "30", "--waitmap", "paper", "--out", str(out), "--no-progress"]
    assert main(argv) == 0, capsys.readouterr().err
    meta = json.loads((out / "sweep.json").read_text())
    assert meta["values"] == [2.0, 30.0] and [p["dir"] for p in meta["points"]] == ["points/wt=2", "points/wt=30"]
    a, b = (read_results(out / p["dir"], "encounters") for p in meta["points"])
    assert a.column("encounter_id").to_pylist() == b.column("encounter_id").to_pylist()
    assert json.loads((out / "points/wt=30/campaign.json").read_text())["groups"]["ID-2"]["wait_threshold_s"] == 30.0
    # a higher W_T waits less and hands more steps to the DAA (the sweep sees the knob)
    nw = [int(np.sum(t.column("n_no_wait").to_numpy())) for t in (a, b)]
    assert nw[1] > nw[0]
    md = (out / "sweep.md").read_text()
    assert "| 30.0 |" in md and "[" in md and (out / "sensitivity_no_wait.png").stat().st_size > 5000
    assert "wait maps `paper`, reading `paper`" in md  # the maps the points read, not the campaign's default
    rows = (out / "sweep.csv").read_text().splitlines()
    assert rows[0].startswith("vary,value,group,metric,estimate,lo,hi")
    # again without --resume: refused; with --resume: nothing to do, same tables
    capsys.readouterr()
    assert main(argv) == 2 and "not empty; pass --resume" in capsys.readouterr().err
    assert main(argv + ["--resume"]) == 0
    other = list(argv)
    other[other.index("wt=2,30")] = "wt=2,31"
    assert main(other + ["--resume"]) == 2  # other values: refused
    assert "different settings (values" in capsys.readouterr().err
    # collate into one page
    assert main(["campaign", "sweep", "--collate", str(out), "--out", str(tmp_path / "page")]) == 0
    page = (tmp_path / "page" / "sensitivity.md").read_text()
    assert "## Sensitivity to `wt`" in page and (tmp_path / "page" / "wt_sensitivity_no_wait.png").is_file()


def test_sweep_refuses_a_fixed_value_of_the_varied_setting(tmp_path, capsys):
    rc = main(["campaign", "sweep", "--vary", "wt=2,4", "--wt", "4", "--out", str(tmp_path / "x")])
    assert rc == 2 and "drop --wt" in capsys.readouterr().err and not (tmp_path / "x").exists()


def test_pilot_and_grid_sweeps_set_the_pilot_mode_and_the_readings_grid():
    from daa_sil.study.campaign.config import CampaignConfig
    from daa_sil.study.analysis.sweep import point_configs

    base = CampaignConfig(groups=("B-2", "ID-2", "ID-2-projl"), pilot={"prob_turn": 0.5})
    pts = point_configs(base, parse_vary("pilot=guendel,nasa_rayleigh5"))
    assert [p.pilot_config().mode for p in pts] == ["guendel", "nasa_rayleigh5"]
    assert all(p.pilot_config().prob_turn == 0.5 for p in pts)  # the base's other pilot settings stay
    assert pts[1].pilot_config().stream_until == "safe-avoidance"  # and the reading's
    with pytest.raises(UsageError, match="pilot=fast.*pilot mode must be one of"):
        point_configs(base, parse_vary("pilot=guendel,fast"))
    grid = point_configs(base, parse_vary("grid=paper,alerting"))  # the paper reading sets its own grid
    assert [g.map_source for g in grid] == ["paper", "alerting"]
    ext = point_configs(CampaignConfig(groups=("ID-2",), reading="extended"), parse_vary("grid=paper,alerting"))
    assert [g.map_source for g in ext] == ["paper", "alerting"] and ext[0].reading_set == {}


def test_a_sweep_started_by_the_previous_version_resumes(tmp_path, capsys):
    """tests/data/sweep-0.3.json is the sweep.json the previous version wrote for the command below (its
    base records W_T, ProjL's look-ahead and the link under their old keys): --resume reads it as the
    same configuration, and still refuses one that differs."""
    old = json.loads((Path(__file__).parent / "data" / "sweep-0.3.json").read_text())
    assert "wt" in old["base"] and "settings" not in old["base"]  # the old keys
    argv = ["campaign", "sweep", "--vary", "wt=2,4", "--groups", "ID-2", "--encounters", "10", "--duration", "60",
            "--chunk-size", "10", "--waitmap", "paper", "--no-progress", "--resume"]
    out = tmp_path / "old"
    out.mkdir()
    (out / "sweep.json").write_text(json.dumps(old))
    assert main(argv + ["--out", str(out)]) == 0, capsys.readouterr().err
    assert (out / "points/wt=4/campaign.json").is_file()
    other = tmp_path / "other"
    other.mkdir()
    old["base"]["n_encounters"] = 11  # another campaign: refused
    (other / "sweep.json").write_text(json.dumps(old))
    capsys.readouterr()
    assert main(argv + ["--out", str(other)]) == 2
    assert "different settings (base)" in capsys.readouterr().err
