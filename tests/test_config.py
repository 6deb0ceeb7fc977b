"""One run configuration with presets (daa_sil/config/run_config.py): YAML load/save, one-line
errors, explicit flags over the file, and the record of the full configuration in outputs.

Expected values are worked by hand from the presets (docs in the module) and the paper's groups.
"""

from __future__ import annotations

import json
import math

import pytest
import yaml

from daa_sil.config.settings import WAIT_THRESHOLD
from daa_sil.cli import main
from daa_sil.config.run_config import PRESET_NAMES, config_from_dict, load_config, preset, save_config
from daa_sil.errors import UsageError
from daa_sil.geometry.units import FT, NMI


def test_presets_carry_their_thresholds():
    # DO-365B: DMOD 4000 ft; the paper: HMD* 1220 m; DAIDALUS DO_365B_no_SUM: DTHR 0.66 nmi
    assert preset("do365").daa_config().th.dthr == pytest.approx(4000 * FT)
    assert preset("paper").daa_config().th.dthr == pytest.approx(1220.0)
    assert preset("daidalus").daa_config().th.dthr == pytest.approx(0.66 * NMI)
    # only daidalus changes the band grid: 1 deg track steps against the project's 5 deg
    assert math.degrees(preset("daidalus").daa_config().trk_step) == pytest.approx(1.0)
    assert math.degrees(preset("paper").daa_config().trk_step) == pytest.approx(5.0)


def test_a_file_changes_only_what_it_names(tmp_path):
    f = tmp_path / "c.yaml"
    f.write_text("base: do365\nallocation: {wt: 8}\nwaitmap: {gamma: 0.9}\ngroups: [B-2, ID-2]\n")
    cfg = load_config(f)
    assert (cfg.base, cfg.thresholds) == ("do365", "do365")
    assert cfg.allocation == {"wait_threshold_s": 8, "projl_horizon_s": None}  # (the old key wt, read as W_T)
    assert cfg.waitmap == {"source": "alerting", "gamma": 0.9}
    assert cfg.groups == ("B-2", "ID-2")
    from daa_sil.study.campaign.config import CampaignConfig

    cc = CampaignConfig.from_run_config(cfg)
    assert (cc.settings.of(WAIT_THRESHOLD), cc.gamma, cc.preset, cc.group_names) == (8, 0.9, "do365", ("B-2", "ID-2"))
    # W_T applies to the groups with a wait function only (B-2 has none: it keeps the table's 4 s)
    assert cc.policy("ID-2").wait_threshold_s == 8.0 and cc.policy("B-2").wait_threshold_s == 4.0


def test_save_and_load_round_trip(tmp_path):
    cfg = config_from_dict({"base": "daidalus", "daa": {"lookahead_s": 120.0}, "pilot": {"prob_left": 0.5},
                            "link": {"link_timeout_s": 12}, "latency": "const:3",
                            "reading": {"name": "preventive", "set": {}}}, "x")
    path = save_config(cfg, tmp_path / "saved.yaml")
    back = load_config(path)
    assert back == cfg
    assert back.daa_config().lookahead_s == 120.0 and back.pilot_config().prob_left == 0.5


@pytest.mark.parametrize("text, named", [
    ("allocation: {wt: 8, wait: 3}\n", "allocation.wait"),
    ("daa: {turn_rat: 0.05}\n", "daa.turn_rat"),
    ("pilot: {prob_lft: 0.5}\n", "pilot.prob_lft"),
    ("waitmaps: {gamma: 0.9}\n", "waitmaps"),
    ("waitmap: {gamma: 1.5}\n", "waitmap.gamma"),
    ("groups: [B-2, XX-9]\n", "XX-9"),
    ("latency: gauss:5\n", "latency"),
    ("study: {encounters: 0}\n", "study.encounters"),
    ("reading: {name: nonsense}\n", "nonsense"),
    ("thresholds: metric\n", "thresholds"),
])
def test_a_bad_file_is_one_line_naming_the_key(tmp_path, capsys, text, named):
    f = tmp_path / "bad.yaml"
    f.write_text(text)
    rc = main(["config", "show", str(f)])
    err = capsys.readouterr().err
    assert rc == 2
    assert err.count("\n") == 1 and err.startswith("daa-sil: error: ") and named in err and str(f) in err


def test_an_unknown_preset_or_missing_file(capsys):
    assert main(["config", "show", "nosuch"]) == 2
    err = capsys.readouterr().err
    assert "nosuch" in err and all(p in err for p in PRESET_NAMES)


def test_config_show_prints_a_loadable_file(tmp_path, capsys):
    assert main(["config", "show", "daidalus"]) == 0
    text = capsys.readouterr().out
    f = tmp_path / "shown.yaml"
    f.write_text(text)
    assert load_config(f) == preset("daidalus")
    assert main(["config", "show", "paper", "--full", "--json"]) == 0
    full = json.loads(capsys.readouterr().out)
    assert full["resolved"]["thresholds"]["dthr"] == pytest.approx(1220.0)
    assert full["resolved"]["groups"]["ID-2"]["wait"] == "map"


def test_config_show_full_lists_each_shared_setting_once_and_loads_back(tmp_path, capsys):
    assert main(["config", "show", "do365", "--full"]) == 0
    text = capsys.readouterr().out
    shown = yaml.safe_load(text)["settings"]
    # the numbers the paper and the SIL use, written here by hand
    assert shown["allocation.wait_threshold_s"] == {"default": 4.0, "unit": "s", "range": [0.0, 120.0],
                                                   "help": shown["allocation.wait_threshold_s"]["help"],
                                                   "flag": "--wt", "mavlink": "DAA_WT"}
    assert (shown["allocation.projl_horizon_s"]["default"], shown["allocation.constant_wait_s"]["default"],
            shown["link.epoch_s"]["default"], shown["study.duration_s"]["default"]) == (25.0, 5.0, 10.0, 240.0)
    assert (shown["thresholds"]["default"], shown["scenario.thresholds"]["default"]) == ("paper", "do365")
    f = tmp_path / "full.yaml"
    f.write_text(text)
    assert load_config(f) == preset("do365")  # the derived sections are ignored when read back


def test_the_daa_section_reaches_the_daa_command(tmp_path, capsys):
    """Ownship 55 m/s north, intruder 13 km ahead at 100 m/s south, co-altitude (paper thresholds:
    DMOD 1220 m, TTHR 35 s). tau_mod <= 35 s once r^2 - 155*35 r - 1220^2 <= 0, i.e. r <= 5686.7 m,
    which is (13000 - 5686.7) / 155 = 47.2 s away: within the corrective alerting time 55 s
    (corrective), beyond a configured 20 s (then only the preventive level, 55 s, is met)."""
    argv = ["daa", "--own", "0,0,1000,0,55,0", "--intruder", "0,13000,1000,0,-100,0", "--json"]
    assert main(argv + ["--preset", "paper"]) == 0
    assert json.loads(capsys.readouterr().out)["alert_levels"] == ["corrective"]
    f = tmp_path / "short.yaml"
    f.write_text("daa: {alert_time_corrective_s: 20}\n")
    assert main(argv + ["--config", str(f)]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["alert_levels"] == ["preventive"]
    assert rep["preset"] == "paper" and rep["config"]["resolved"]["daa"]["alert_time_corrective_s"] == 20
    # an explicit --preset overrides the file's thresholds, the file's daa change still applies
    assert main(argv + ["--config", str(f), "--preset", "do365"]) == 0
    assert json.loads(capsys.readouterr().out)["preset"] == "do365"


def test_campaign_records_the_file_and_flags_override_it(tmp_path, capsys):
    f = tmp_path / "camp.yaml"
    f.write_text("allocation: {wt: 8}\ngroups: [B-2, ID-2]\nstudy: {encounters: 6, seed: 3}\n"
                 "link: {link_timeout_s: 12}\n")
    out = tmp_path / "run"
    assert main(["campaign", "run", "--config", str(f), "--out", str(out), "--no-progress"]) == 0
    meta = json.loads((out / "campaign.json").read_text())
    assert meta["config"]["settings"]["wait_threshold_s"] == 8 and meta["config"]["n_encounters"] == 6 and meta["config"]["seed"] == 3
    pol = meta["resolved_config"]["policies"]
    assert pol["ID-2"]["wait_threshold_s"] == 8.0 and pol["B-2"]["wait_threshold_s"] == 4.0
    assert pol["ID-2"]["link_timeout_s"] == 12.0 and pol["ID-2"]["stale_command_s"] == 15.0
    assert meta["resolved_config"]["thresholds"]["dthr"] == pytest.approx(1220.0)
    # an explicit flag wins over the file
    out2 = tmp_path / "run2"
    assert main(["campaign", "run", "--config", str(f), "--wt", "6", "--encounters", "4", "--out", str(out2),
                 "--no-progress"]) == 0
    meta2 = json.loads((out2 / "campaign.json").read_text())
    assert meta2["config"]["settings"]["wait_threshold_s"] == 6.0 and meta2["config"]["n_encounters"] == 4
    assert meta2["resolved_config"]["policies"]["ID-2"]["wait_threshold_s"] == 6.0
    capsys.readouterr()
    # --config with --resume: the campaign's own configuration is in campaign.json
    assert main(["campaign", "run", "--config", str(f), "--out", str(out), "--resume", "--no-progress"]) == 2
    assert "--resume" in capsys.readouterr().err


def test_no_config_keeps_the_campaign_defaults():
    """The default campaign (no --config) is the paper preset: same groups, thresholds, maps."""
    from daa_sil.study.campaign.config import CampaignConfig

    assert CampaignConfig.from_run_config(preset("paper")).to_dict() == CampaignConfig().to_dict()


def test_a_section_is_checked_by_building_it():
    with pytest.raises(UsageError, match="daa"):
        config_from_dict({"daa": {"recovery": "sideways"}}, "x.yaml")
    with pytest.raises(UsageError, match="x.yaml"):
        config_from_dict(yaml.safe_load("[1, 2]"), "x.yaml")
