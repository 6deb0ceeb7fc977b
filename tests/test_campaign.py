"""Campaign runner and CLI: bad config, determinism across executors, resume after SIGKILL, report."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from daa_sil.study.campaign.run import run_campaign
from daa_sil.study.campaign.config import CampaignConfig
from daa_sil.study.campaign.files import checksum_path, chunk_paths, read_results
from daa_sil.cli import main
from daa_sil.errors import UsageError

SMALL = dict(groups=("B-2", "IC-1"), n_encounters=12, seed=5, chunk_size=5, preset="paper", duration_s=60.0)


def _tables(out: Path) -> dict:
    return {kind: read_results(out, kind) for kind in ("encounters", "decisions")}


def _assert_same(a: dict, b: dict) -> None:
    for kind in a:
        ta, tb = a[kind], b[kind]
        assert ta.schema.equals(tb.schema) and ta.num_rows == tb.num_rows, kind
        for name in ta.column_names:
            x, y = ta[name].to_numpy(zero_copy_only=False), tb[name].to_numpy(zero_copy_only=False)
            np.testing.assert_array_equal(x, y, err_msg=f"{kind}.{name}")


@pytest.mark.parametrize("argv, message", [
    (["--groups", "B-1,B-9"], "unknown group 'B-9'"),
    (["--encounters", "0"], "--encounters must be an integer within [1, 10,000,000], got 0"),
    (["--encounters", "-3"], "--encounters must be an integer within [1, 10,000,000], got -3"),
    (["--chunk-size", "x"], "--chunk-size must be an integer, got 'x'"),
    (["--preset", "nope"], "unknown --preset"),
    (["--waitmap", "nosuchgrid"], "--waitmap 'nosuchgrid'"),
    (["--wt", "-1"], "--wt must be a number within [0, 120], got -1"),
    (["--projl-horizon", "nan"], "--projl-horizon must be a number within"),
    (["--projl-lookahead", "121"], "--projl-horizon must be a number within [0, 120], got 121"),
    (["--gamma", "1.5"], "--gamma must be within"),
    (["--latency", "gauss:5"], "bad delay spec 'gauss:5'"),
    (["--intruders", "0"], "--intruders must be"),
    (["--reading", "yards"], "unknown reading 'yards'"),
    (["--reading-set", "units=yards"], "units must be one of metres, feet"),
])
def test_bad_config_is_one_line_exit_2_and_writes_nothing(tmp_path, capsys, argv, message):
    out = tmp_path / "camp"
    rc = main(["campaign", "run", "--out", str(out)] + argv)
    err = capsys.readouterr().err
    assert rc == 2 and message in err and err.count("\n") == 1
    assert not out.exists()


def test_unwritable_out_and_non_empty_out(tmp_path, capsys):
    blocker = tmp_path / "file.txt"
    blocker.write_text("x")
    rc = main(["campaign", "run", "--out", str(blocker / "sub"), "--encounters", "2"])
    err = capsys.readouterr().err
    assert rc == 2 and "cannot create output directory" in err and "Not a directory" in err
    full = tmp_path / "full"
    full.mkdir()
    (full / "keep.txt").write_text("mine")
    rc = main(["campaign", "run", "--out", str(full), "--encounters", "2"])
    err = capsys.readouterr().err
    assert rc == 2 and "not empty; pass --resume" in err
    assert sorted(p.name for p in full.iterdir()) == ["keep.txt"]


def test_same_tables_for_one_and_two_workers(tmp_path):
    cfg = CampaignConfig(**SMALL)
    s1 = run_campaign(cfg, tmp_path / "w1", workers=1, progress=False)
    s2 = run_campaign(cfg, tmp_path / "w2", workers=2, progress=False)
    assert s1.chunks_run == s2.chunks_run == 2 * cfg.n_chunks == 6
    _assert_same(_tables(tmp_path / "w1"), _tables(tmp_path / "w2"))
    meta = json.loads((tmp_path / "w1" / "campaign.json").read_text())
    assert meta["status"] == "complete" and meta["preset"] == "paper" and meta["seed"] == 5
    enc = read_results(tmp_path / "w1", "encounters")
    assert enc.num_rows == 2 * cfg.n_encounters
    assert set(enc["group"].to_pylist()) == {"B-2", "IC-1"}
    # the same encounter set (ids and seeds) in every group
    by_group = {g: enc.filter(enc["group"].to_numpy(zero_copy_only=False) == g) for g in cfg.group_names}
    assert by_group["B-2"]["seed"].equals(by_group["IC-1"]["seed"])


def test_dask_local_matches_process_pool(tmp_path):
    pytest.importorskip("dask.distributed")
    cfg = CampaignConfig(**{**SMALL, "groups": ("ID-2",), "n_encounters": 8, "chunk_size": 4})
    run_campaign(cfg, tmp_path / "pool", workers=2, progress=False)
    run_campaign(cfg, tmp_path / "dask", workers=2, scheduler="local-dask", progress=False)
    _assert_same(_tables(tmp_path / "pool"), _tables(tmp_path / "dask"))


def test_resume_with_different_settings_is_refused(tmp_path):
    cfg = CampaignConfig(**{**SMALL, "groups": ("B-1",), "n_encounters": 3})
    run_campaign(cfg, tmp_path / "c", progress=False)
    with pytest.raises(UsageError, match="different settings \\(seed\\)"):
        run_campaign(CampaignConfig(**{**SMALL, "groups": ("B-1",), "n_encounters": 3, "seed": 6}),
                     tmp_path / "c", resume=True, progress=False)
    # resuming a complete campaign recomputes nothing
    s = run_campaign(cfg, tmp_path / "c", resume=True, progress=False)
    assert s.chunks_run == 0 and s.chunks_skipped == 1


def _cli(*args) -> list:
    return [sys.executable, "-m", "daa_sil.cli", "campaign", "run", *args]


def test_resume_after_sigkill_gives_the_uninterrupted_tables(tmp_path):
    args = ["--groups", "B-1,IC-1", "--encounters", "12", "--chunk-size", "3", "--seed", "3", "--no-progress"]
    killed = tmp_path / "killed"
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    proc = subprocess.Popen(_cli(*args, "--out", str(killed)), stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, env=env, start_new_session=True)
    try:
        first = checksum_path(killed, "B-1", 0)  # written last: the first chunk is complete
        while not first.exists() and proc.poll() is None:
            time.sleep(0.02)
        assert proc.poll() is None, "the campaign finished before it could be killed"
        os.killpg(proc.pid, signal.SIGKILL)
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait()
    done = list(killed.rglob("chunk-*.sha256"))  # written last: one per complete chunk
    assert 1 <= len(done) < 8, "kill should land after the first and before the last chunk"
    assert json.loads((killed / "campaign.json").read_text())["status"] == "running"
    # resume needs only --out: the stored config is used
    res = subprocess.run(_cli("--out", str(killed), "--resume", "--json"), capture_output=True, text=True,
                         env=env)
    assert res.returncode == 0, res.stderr
    info = json.loads(res.stdout)
    assert info["chunks_skipped"] == len(done) and info["chunks_run"] == 8 - len(done)
    full = tmp_path / "full"
    res = subprocess.run(_cli(*args, "--out", str(full)), capture_output=True, text=True, env=env)
    assert res.returncode == 0, res.stderr
    for g in ("B-1", "IC-1"):
        for c in range(4):
            for a, b in zip(chunk_paths(killed, g, c), chunk_paths(full, g, c)):
                assert pq.read_table(a).equals(pq.read_table(b)) or _same_values(a, b), a.name
    assert not list(killed.rglob(".*.tmp"))  # no half-written file survived the kill


def _same_values(a: Path, b: Path) -> bool:
    ta, tb = pq.read_table(a), pq.read_table(b)
    _assert_same({"t": ta}, {"t": tb})
    return True


def test_report_from_a_campaign(tmp_path, capsys):
    cfg = CampaignConfig(**{**SMALL, "groups": ("B-2", "ID-2"), "n_encounters": 6})
    run_campaign(cfg, tmp_path / "c", progress=False)
    rc = main(["campaign", "report", str(tmp_path / "c"), "--out", str(tmp_path / "rep")])
    assert rc == 0, capsys.readouterr().err
    text = (tmp_path / "rep" / "report.md").read_text()
    assert "ID-2" in text and "B-2" in text
    rc = main(["campaign", "report", str(tmp_path / "nothing")])
    assert rc == 2 and "not a campaign directory" in capsys.readouterr().err


def test_every_knob_is_recorded_and_checked_on_resume(tmp_path, capsys):
    out = tmp_path / "knobs"
    argv = ["campaign", "run", "--groups", "B-2,ID-2-projl", "--encounters", "4", "--chunk-size", "4",
            "--duration", "60", "--wt", "7", "--projl-lookahead", "12", "--latency", "const:0.5",
            "--waitmap", "paper", "--out", str(out), "--no-progress"]
    assert main(argv) == 0
    meta = json.loads((out / "campaign.json").read_text())
    c = meta["config"]
    # the default reading (paper) sets its own grid, so an explicit --waitmap is recorded as the reading's grid
    assert (c["settings"]["wait_threshold_s"], c["settings"]["projl_horizon_s"], c["latency"], c["reading_set"]["waitmap"]) == (7.0, 12.0, "const:0.5", "paper")
    assert meta["groups"]["ID-2-projl"]["wait_threshold_s"] == 7.0 and meta["groups"]["B-2"]["wait_threshold_s"] == 4.0
    assert meta["groups"]["B-2"]["latency"] == {"type": "constant", "seconds": 0.5}
    assert meta["seeds"]["campaign"] == 0 and meta["waitmap"] is None  # neither group reads the map
    capsys.readouterr()
    assert main(argv[:-3] + ["--wt", "8", "--out", str(out), "--resume", "--no-progress"]) == 2
    assert "different settings (--wt)" in capsys.readouterr().err
    assert main(["campaign", "run", "--out", str(out), "--resume", "--no-progress"]) == 0  # stored knobs reused


def test_campaign_json_records_the_kernel_compiler_versions(tmp_path):
    """Provenance: campaign.json names the numba / llvmlite that compiled the DAA kernels (issue 21)."""
    import json

    import llvmlite
    import numba

    from daa_sil.cli import main

    out = tmp_path / "c"
    assert main(["campaign", "run", "--groups", "B-2", "--encounters", "3", "--seed", "5", "--out", str(out),
                 "--no-progress"]) == 0
    versions = json.loads((out / "campaign.json").read_text())["versions"]
    assert versions["numba"] == numba.__version__ and versions["llvmlite"] == llvmlite.__version__
