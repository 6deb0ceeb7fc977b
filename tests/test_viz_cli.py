"""``daa-sil viz steplog|replay`` and ``log_waitmap``: exit codes, one-line errors, files read back."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest

rr = pytest.importorskip("rerun")

from daa_sil import steplog, viz  # noqa: E402
from daa_sil.cli import main  # noqa: E402
from test_viz import read_rrd, scalars  # noqa: E402
from sil_helpers import wait_for_vehicle_time  # noqa: E402
from viz_encounter import make_steplog, rerun_env  # noqa: E402,F401


pytestmark = pytest.mark.usefixtures("rerun_env")


@pytest.fixture(scope="module")
def steplog_file(tmp_path_factory) -> Path:
    a, b = make_steplog(encounter_id=3), make_steplog(n_steps=40, encounter_id=4)
    table = pa.concat_tables([a, b]).cast(steplog.STEP_SCHEMA)
    path = tmp_path_factory.mktemp("logs") / "steps.parquet"
    steplog.write_steplog(table, path, metadata={"preset": "paper"})
    return path


def test_steplog_to_rrd(tmp_path, steplog_file, capsys):
    out = tmp_path / "enc.rrd"
    assert main(["viz", "steplog", str(steplog_file), "--encounter", "3", "--rrd", str(out)]) == 0
    assert "240 steps" in capsys.readouterr().out
    data = read_rrd(out)
    assert data["/world/ownship"].num_rows == 240
    hmd_star = scalars(data["/plots/hmd/threshold"])
    assert np.allclose(hmd_star, 1220.0), "the preset comes from the step log's metadata (paper)"
    # never overwritten silently; --force replaces it
    assert main(["viz", "steplog", str(steplog_file), "--encounter", "3", "--rrd", str(out)]) == 1
    assert "refusing to overwrite" in capsys.readouterr().err
    assert main(["viz", "steplog", str(steplog_file), "--encounter", "4", "--rrd", str(out), "--force",
                 "--preset", "do365", "--until", "9"]) == 0
    data = read_rrd(out)
    assert data["/world/ownship"].num_rows == 10
    assert np.allclose(scalars(data["/plots/hmd/threshold"]), 1219.2)


@pytest.mark.parametrize("argv, message", [
    (["--rrd", "X"], "holds 2 encounters"),
    (["--encounter", "3"], "choose an output"),
    (["--encounter", "3", "--rrd", "x.txt"], "should end in .rrd"),
    (["--encounter", "99", "--rrd", "X"], "encounter 99 is not in the step log"),
    (["--encounter", "3", "--rrd", "X", "--preset", "bogus"], "unknown --preset"),
    (["--encounter", "3", "--connect", "localhost:1"], "not a Rerun gRPC URL"),
])
def test_usage_errors_are_one_line(tmp_path, steplog_file, capsys, argv, message):
    argv = [str(tmp_path / "o.rrd") if a == "X" else a for a in argv]
    assert main(["viz", "steplog", str(steplog_file)] + argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("daa-sil: error: ") and message in err and err.count("\n") == 1
    assert list(tmp_path.iterdir()) == []


def test_not_a_steplog(tmp_path, capsys):
    bad = tmp_path / "bad.parquet"
    bad.write_bytes(b"not parquet")
    assert main(["viz", "steplog", str(bad), "--rrd", str(tmp_path / "o.rrd")]) == 2
    assert "not a readable Parquet file" in capsys.readouterr().err


def test_headless_spawn_viewer_warns_and_still_writes(tmp_path, steplog_file, capsys):
    out = tmp_path / "enc.rrd"
    assert main(["viz", "steplog", str(steplog_file), "--encounter", "4", "--rrd", str(out), "--spawn-viewer"]) == 0
    err = capsys.readouterr().err
    assert "daa-sil: warning: --spawn-viewer needs a display" in err
    assert out.stat().st_size > 0


def test_replay_worst_encounter(tmp_path, capsys):
    """A tiny real campaign, then the replay of its worst encounter equals the stored result."""
    from daa_sil.study.campaign import run as campaign
    from daa_sil.study.campaign import files as campaign_files

    cfg = campaign.CampaignConfig(groups=("B-1",), n_encounters=12, seed=5, chunk_size=12)
    campaign.run_campaign(cfg, tmp_path / "camp", workers=1, progress=False)
    rows = campaign_files.read_results(tmp_path / "camp", "encounters", groups=["B-1"])
    out = tmp_path / "worst.rrd"
    log = tmp_path / "worst.parquet"
    assert main(["viz", "replay", str(tmp_path / "camp"), "--group", "b-1", "--worst", "--rrd", str(out),
                 "--save-steplog", str(log)]) == 0
    printed = capsys.readouterr()
    assert "warning" not in printed.err
    enc_id = int(printed.out.split("encounter ")[1].split(":")[0])
    row = rows.filter(pa.compute.equal(rows.column("encounter_id"), enc_id)).to_pylist()[0]
    other = rows.to_pylist()
    if any(r["lowc"] for r in other):
        assert row["lowc"] and row["pi"] == max(r["pi"] for r in other if r["lowc"])
    else:
        assert row["min_range_m"] == min(r["min_range_m"] for r in other)
    steps = steplog.read_steplog(log)
    rng = np.array([v[0] for v in steps.column("range_m").to_pylist()])
    assert np.isclose(rng.min(), row["min_range_m"], rtol=1e-6), "the replay reproduces the campaign encounter"
    data = read_rrd(out)
    assert data["/world/ownship"].num_rows == steps.num_rows == 240
    assert np.allclose(scalars(data["/plots/range/0"]), rng)
    assert main(["viz", "replay", str(tmp_path / "camp"), "--group", "B-1", "--encounter", "999",
                 "--rrd", str(tmp_path / "x.rrd")]) == 2
    assert "encounter 999 has no result" in capsys.readouterr().err


def test_log_waitmap_point_cloud(tmp_path):
    """A real (tiny) wait map solved by daa_sil.waitmap, shown as a coloured point cloud."""
    from daa_sil import waitmap

    grid = waitmap.resolve_grid("paper,dx=4,dy=4,dh=2,vi=2,vh=2,theta=4")
    params = waitmap.MdpParams(preset="paper", gamma=0.9, horizon=20.0)
    fam = waitmap.build_family(grid, params, [0.0])
    path, chosen, _ = viz.write_waitmap(fam, viz.SinkOptions(rrd=tmp_path / "wm.rrd"), vi=80.0, vh=5.0,
                                        theta_deg=170.0)
    assert path == tmp_path / "wm.rrd"
    assert np.isclose(chosen["theta"], 180.0) and chosen["vi"] == grid.axis("vi").values[0]
    chunks = [c for c in rr.chunk.RrdReader(path).stream() if c.entity_path == "/waitmap/points"]
    rb = chunks[0].to_record_batch()
    pts = np.array(rb.column("Points3D:positions").to_pylist()[0])
    colors = np.array(rb.column("Points3D:colors").to_pylist()[0], np.uint32)
    assert pts.shape == (4 * 4 * 2, 3)
    wm = fam.map_for(0.0)
    w = wm.wait_s[:, :, :, 0, grid.axis("vh").n - 1, 2].reshape(-1)
    assert np.array_equal(colors, _packed(viz.wait_colors(w)))
    assert np.allclose(np.sort(np.unique(pts[:, 0])), grid.axis("dx").values)


def _packed(rgba: np.ndarray) -> np.ndarray:
    rgba = rgba.astype(np.uint32)
    return (rgba[:, 0] << 24) | (rgba[:, 1] << 16) | (rgba[:, 2] << 8) | rgba[:, 3]


def test_waitmap_plot_rerun_flag(tmp_path, capsys):
    maps = tmp_path / "maps"
    assert main(["waitmap", "build", "--grid", "paper,dx=4,dy=4,dh=2,vi=2,vh=2,theta=4", "--turn-rates", "0",
                 "--horizon", "20", "--out", str(maps)]) == 0
    out = tmp_path / "wm.rrd"
    assert main(["waitmap", "plot", str(maps), "--out", str(tmp_path / "figs"), "--rerun", str(out),
                 "--vi", "300", "--vh", "-5", "--theta", "95"]) == 0
    assert str(out) in capsys.readouterr().out
    chunks = [c for c in rr.chunk.RrdReader(out).stream() if c.entity_path == "/waitmap/points"]
    pts = np.array(chunks[0].to_record_batch().column("Points3D:positions").to_pylist()[0])
    assert pts.shape == (4 * 4 * 2, 3)
    info = [c for c in rr.chunk.RrdReader(out).stream() if c.entity_path == "/waitmap/info"]
    text = info[0].to_record_batch().column("TextDocument:text").to_pylist()[0][0]
    assert "v_i = 300 m/s" in text and "theta = 90 deg" in text and "32 states" in text


# --------------------------------------------------------------------------------------------
# daa-sil run --rrd: the recording is prepared by a helper process while the SIL plays

ROOT = Path(__file__).resolve().parents[1]
RUN = [sys.executable, "-m", "daa_sil.cli", "run"]
RUN_LIMIT_S = 180  # generous bound so a hung process fails the test instead of blocking CI


def _procs_mentioning(text: str) -> list[int]:
    """PIDs (other than ours) whose command line contains ``text``."""
    pids = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit() and int(d.name) != os.getpid():
            try:
                cmd = (d / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
            except OSError:
                continue
            if text in cmd:
                pids.append(int(d.name))
    return pids


def _headless_env() -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET", "RERUN")}
    return env


def _static_entities(path) -> set[str]:
    return {ch.entity_path for ch in rr.chunk.RrdReader(Path(path)).stream() if ch.is_static}


def test_sil_run_rrd_equals_steplog_conversion(tmp_path):
    """``daa-sil run --rrd`` (helper process) writes the same entities and steps as converting the run's
    step log afterwards; headless --spawn-viewer is one warning line, not a failure."""
    out = tmp_path / "run"
    rrd = out / "enc.rrd"  # inside --out, which the run creates
    cp = subprocess.run(RUN + [str(ROOT / "scenarios" / "head_on.yaml"), "--out", str(out), "--rrd", str(rrd),
                               "--spawn-viewer", "--json"], capture_output=True, text=True, timeout=RUN_LIMIT_S,
                        cwd=ROOT, env=_headless_env())
    assert cp.returncode == 0, cp.stderr
    assert "daa-sil: warning: --spawn-viewer needs a display" in cp.stderr and "Traceback" not in cp.stderr
    result = json.loads(cp.stdout)
    assert result["files"]["rrd"] == str(rrd)
    assert result["rrd_timing"]["live"] is None, "lockstep records from the step log, nothing runs next to it"
    if sys.platform.startswith("linux"):
        assert result["rrd_timing"]["helper"] == "fork", "the orchestrator forks its helper before any thread"
    assert [p.name for p in out.iterdir() if p.name.startswith(".")] == [], "no temporary file left"
    reader = rr.chunk.RrdReader(rrd)
    assert len(reader.recordings()) == 1 and reader.recordings()[0].recording_id == "encounter-0"
    assert len(reader.blueprints()) == 1, "the layout is in the file"
    table = steplog.read_steplog(out / "steplog.parquet")
    ref, _ = viz.log_steplog(table, viz.SinkOptions(rrd=tmp_path / "ref.rrd"))
    live, batch = read_rrd(rrd), read_rrd(ref)
    assert sorted(live) == sorted(batch)
    assert {e: t.num_rows for e, t in live.items()} == {e: t.num_rows for e, t in batch.items()}
    assert _static_entities(rrd) == _static_entities(ref)
    assert live["/world/ownship"].num_rows == table.num_rows == result["steps"]
    rng = np.array([v[0] for v in table.column("range_m").to_pylist()])
    assert np.allclose(scalars(live["/plots/range/0"]), rng)
    assert rrd.stat().st_size <= 1_000_000


def test_sil_run_ctrl_c_leaves_a_readable_rrd_or_none(tmp_path):
    out = tmp_path / "run"
    rrd = out / "enc.rrd"
    # real time at 40x: the 180 s scenario takes ~4.5 s, so the interrupt lands mid-encounter
    proc = subprocess.Popen(RUN + [str(ROOT / "scenarios" / "head_on.yaml"), "--out", str(out), "--rrd", str(rrd),
                                   "--clock", "realtime", "--speed", "40"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT, env=_headless_env())
    try:
        wait_for_vehicle_time(out, 20, proc)
        assert len(_procs_mentioning(str(out))) >= 4  # orchestrator, vehicle, shim, gcs (+ the recorder)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 130, err
    assert "Traceback" not in err
    assert _procs_mentioning(str(out)) == [], "the recorder helper is gone too"
    assert [p.name for p in out.iterdir() if p.name.startswith(".")] == [], "no temporary file left"
    table = steplog.read_steplog(out / "steplog.parquet")
    assert 20 <= table.num_rows < 180
    result = json.loads((out / "result.json").read_text())
    assert result["interrupted"] is True
    # the partial step log became a complete recording (a second Ctrl-C would leave none)
    assert result["files"]["rrd"] == str(rrd)
    assert read_rrd(rrd)["/world/ownship"].num_rows == table.num_rows


@pytest.mark.parametrize("argv, code, message", [
    (["--rrd", "{tmp}/no/such/dir/x.rrd"], 1, "directory {tmp}/no/such/dir is missing or not writable"),
    (["--rrd", "{tmp}/x.txt"], 2, "--rrd '{tmp}/x.txt' should end in .rrd"),
    (["--connect", "localhost:9876", "--clock", "realtime"], 2, "not a Rerun gRPC URL"),
])
def test_sil_run_bad_rrd_fails_before_any_process(tmp_path, capsys, argv, code, message):
    from daa_sil.cli import main as cli_main

    argv = [a.format(tmp=tmp_path) for a in argv]
    assert cli_main(["run", str(ROOT / "scenarios" / "head_on.yaml"), "--out", str(tmp_path / "o")] + argv) == code
    err = capsys.readouterr().err
    assert err.startswith("daa-sil: error: ") and message.format(tmp=tmp_path) in err and err.count("\n") == 1
    assert not (tmp_path / "o").exists(), "nothing was started or written"
