"""daa_sil.viz: .rrd content read back with Rerun's own reader, sinks, failure modes."""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import sys
import time
import urllib.request
import warnings
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest

rr = pytest.importorskip("rerun")

from daa_sil import viz  # noqa: E402
from daa_sil.errors import OutputError  # noqa: E402
from daa_sil.geometry.thresholds import get_thresholds  # noqa: E402
from daa_sil.viz.recorder import BackgroundRecorder  # noqa: E402
from viz_encounter import make_steplog, records  # noqa: E402

NS = 1_000_000_000


@pytest.fixture(autouse=True)
def _rerun_env(monkeypatch):
    """Results must not depend on the caller's RERUN setting."""
    monkeypatch.delenv("RERUN", raising=False)


@pytest.fixture(scope="module")
def table() -> pa.Table:
    return make_steplog()


def read_rrd(path) -> dict[str, pa.Table]:
    """Temporal rows per entity (sorted by step) from an .rrd, via rr.chunk.RrdReader."""
    parts: dict[str, list[pa.RecordBatch]] = {}
    for ch in rr.chunk.RrdReader(Path(path)).stream():
        if ch.is_static:
            continue
        parts.setdefault(ch.entity_path, []).append(ch.to_record_batch())
    out = {}
    for ent, batches in parts.items():
        cols = sorted(set.intersection(*(set(b.schema.names) for b in batches)) - {"rerun.controls.RowId"})
        tb = pa.Table.from_batches([b.select(cols) for b in batches])
        out[ent] = tb.sort_by("step") if "step" in cols else tb
    return out


def static_entities(path) -> set[str]:
    return {ch.entity_path for ch in rr.chunk.RrdReader(Path(path)).stream() if ch.is_static}


def scalars(tb: pa.Table) -> np.ndarray:
    return np.array([v[0] for v in tb.column("Scalars:scalars").to_pylist()])


def list_col(table: pa.Table, name: str, j: int = 0) -> np.ndarray:
    return np.array([v[j] for v in table.column(name).to_pylist()], float)


def write(table, path, **kw) -> Path:
    written, logger = viz.log_steplog(table, viz.SinkOptions(rrd=path, deterministic=True, **kw))
    assert written == Path(path)
    return written


def test_entities_steps_timeline_and_values(tmp_path, table):
    path = write(table, tmp_path / "enc.rrd")
    data = read_rrd(path)
    expected = {"/world/ownship", "/world/ownship/body", "/world/ownship/velocity", "/world/ownship/well_clear",
                "/world/ownship/bands", "/world/ownship/cmd/pilot", "/world/ownship/cmd/daa", "/world/ownship/cmd/exec",
                "/world/ownship_trail", "/world/intruders/0", "/world/intruders/0/trail", "/world/intruders/0/velocity",
                "/decisions", "/status/decision", "/status/authority", "/plots/range/0", "/plots/hmd/0", "/plots/dh/0",
                "/plots/tau_mod/0", "/plots/wait/wait_s", "/plots/delay/up", "/plots/delay/down", "/plots/sm/pilot",
                "/plots/sm/exec"}
    assert expected <= set(data)
    assert {"/world", "/world/ownship/well_clear"} <= static_entities(path)
    own = data["/world/ownship"]
    assert own.num_rows == table.num_rows == 240
    assert own.column("sim_time").type == pa.duration("ns")
    t = own.column("sim_time").cast(pa.int64()).to_numpy()
    assert t[0] == 0 and t[-1] == 239 * NS
    assert np.array_equal(own.column("step").to_numpy(), np.arange(240))
    xyz = np.array(own.column("Transform3D:translation").to_pylist()).reshape(240, 3)
    assert np.allclose(xyz[:, 1], table.column("own_y").to_numpy(), atol=1e-3)
    assert np.allclose(xyz[:, 2], table.column("own_z").to_numpy(), atol=1e-3)
    # per-intruder series equal the input
    for ent, col in (("/plots/range/0", "range_m"), ("/plots/hmd/0", "hmd_m"), ("/plots/dh/0", "dh_m")):
        assert np.allclose(scalars(data[ent]), list_col(table, col))
    # tau_mod is nan while diverging: only finite values are logged, at their own times
    tau = list_col(table, "tau_mod_s")
    tau_tb = data["/plots/tau_mod/0"]
    assert tau_tb.num_rows == np.isfinite(tau).sum() < 240
    assert np.allclose(scalars(tau_tb), tau[np.isfinite(tau)])
    assert np.array_equal(tau_tb.column("step").to_numpy(), np.flatnonzero(np.isfinite(tau)))
    # wait time only on the active steps
    wait = table.column("wait_s").to_numpy()
    assert np.allclose(scalars(data["/plots/wait/wait_s"]), wait[np.isfinite(wait)])
    pts = np.array(data["/world/intruders/0"].column("Points3D:positions").to_pylist()).reshape(-1, 3)
    assert np.allclose(pts[:, 1], list_col(table, "intr_y"), atol=1e-2)


def test_decisions_bands_and_well_clear_colour(tmp_path, table):
    data = read_rrd(write(table, tmp_path / "enc.rrd"))
    decisions = table.column("decision").to_pylist()
    n_dec = sum(d != "none" for d in decisions)
    lowc = table.column("lowc").to_numpy(zero_copy_only=False)
    onsets = int(lowc[0]) + int(np.sum(lowc[1:] & ~lowc[:-1]))
    assert onsets >= 1, "the test encounter must lose well clear"
    log = data["/decisions"]
    texts = [v[0] for v in log.column("TextLog:text").to_pylist()]
    levels = [v[0] for v in log.column("TextLog:level").to_pylist()]
    assert len(texts) == n_dec + onsets
    assert sum(x.startswith("wait:") for x in texts) == decisions.count("wait")
    assert sum(x.startswith("no-wait:") for x in texts) == decisions.count("no_wait")
    assert sum(x.startswith("blended:") for x in texts) == decisions.count("blend")
    assert levels.count("CRITICAL") == onsets
    first_wait = texts[[x.startswith("wait:") for x in texts].index(True)]
    assert "w(S) =" in first_wait and "hold the pilot course" in first_wait
    # bands: one arc per band, per step
    bands = data["/world/ownship/bands"]
    n_arcs = [len(v or []) for v in bands.column("LineStrips3D:strips").to_pylist()]
    assert n_arcs == [len(v) for v in table.column("bands_trk_lo_deg").to_pylist()]
    assert max(n_arcs) >= 2
    # well-clear cylinder is red exactly while an intruder violates well clear
    wcv = list_col(table, "wcv").astype(bool)
    colors = np.array([v[0] for v in data["/world/ownship/well_clear"].column("Cylinders3D:colors").to_pylist()],
                      np.uint32)
    red = (colors >> 24) > 150
    assert wcv.any() and np.array_equal(red, wcv)


def test_band_arc_geometry():
    th = get_thresholds("do365")
    arc = viz.track_arc(350.0, 20.0, 1000.0)
    trk = np.degrees(np.arctan2(arc[:, 0], arc[:, 1])) % 360.0
    assert np.isclose(trk[0], 350.0) and np.isclose(trk[-1], 20.0, atol=1e-3)
    assert np.allclose(np.hypot(arc[:, 0], arc[:, 1]), 1000.0, rtol=1e-5)
    full = viz.track_arc(0.0, 360.0, th.dthr)
    assert len(full) > 100 and np.allclose(full[0], full[-1], atol=1e-2)


def test_incremental_log_step_matches_batch(tmp_path, table):
    batch = read_rrd(write(table, tmp_path / "batch.rrd"))
    path = tmp_path / "live.rrd"
    logger = viz.EncounterLogger(viz.SinkOptions(rrd=path, deterministic=True), encounter_id=7, flush_interval_s=0.01)
    for rec in records(table):
        logger.log_step(rec)
    assert logger.close() == path and logger.steps_logged == 240
    live = read_rrd(path)
    assert set(live) == set(batch)
    for ent in ("/plots/range/0", "/plots/tau_mod/0", "/plots/sm/pilot", "/decisions", "/world/ownship_trail",
                "/world/ownship/bands", "/world/intruders/0/trail"):
        for name in batch[ent].column_names:
            assert live[ent].column(name).to_pylist() == batch[ent].column(name).to_pylist(), (ent, name)


def test_step_dicts_with_n1_arrays(tmp_path, table):
    """StepLogBuilder-style step dicts ((1,) scalars, (1, M) intruders, padded bands + count)."""
    path = tmp_path / "n1.rrd"
    with viz.EncounterLogger(viz.SinkOptions(rrd=path)) as logger:
        for rec in records(table.slice(100, 20)):
            d = {k: np.array([v]) for k, v in rec.items() if not isinstance(v, list)}
            for k in viz.PER_INTRUDER:
                d[k] = np.array([rec[k]], dtype=float if k != "wcv" else bool)
            n = len(rec["bands_trk_lo_deg"])
            d["bands_count"] = np.array([n])
            d["bands_trk_lo_deg"] = np.array([rec["bands_trk_lo_deg"] + [np.nan] * 2])
            d["bands_trk_hi_deg"] = np.array([rec["bands_trk_hi_deg"] + [np.nan] * 2])
            d["bands_trk_region"] = np.array([rec["bands_trk_region"] + ["none"] * 2], dtype=object)
            logger.log_step(d)
    data = read_rrd(path)
    assert np.array_equal(data["/world/ownship"].column("step").to_numpy(), np.arange(100, 120))
    assert np.allclose(scalars(data["/plots/range/0"]), list_col(table.slice(100, 20), "range_m"))
    n_arcs = [len(v) for v in data["/world/ownship/bands"].column("LineStrips3D:strips").to_pylist()]
    assert n_arcs == [len(v) for v in table.slice(100, 20).column("bands_trk_lo_deg").to_pylist()]


def test_rrd_size_per_240s_encounter(tmp_path, table):
    path = write(table, tmp_path / "enc.rrd")
    assert path.stat().st_size <= 1_000_000
    rerun_bin = viz.rerun_binary()
    if os.path.exists(rerun_bin):
        res = subprocess.run([rerun_bin, "rrd", "verify", str(path)], capture_output=True, text=True)
        assert res.returncode == 0, res.stderr


def test_deterministic_files(tmp_path, table):
    a, b = write(table, tmp_path / "a.rrd"), write(table, tmp_path / "b.rrd")
    res = subprocess.run([viz.rerun_binary(), "rrd", "compare", "--unordered", str(a), str(b)],
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stderr


def test_select_encounter_and_until(tmp_path, table):
    other = make_steplog(n_steps=30, encounter_id=9)
    both = pa.concat_tables([table, other])
    with pytest.raises(viz.UsageError, match="2 encounters"):
        viz.log_steplog(both, viz.SinkOptions(rrd=tmp_path / "x.rrd"))
    with pytest.raises(viz.UsageError, match="encounter 5 is not"):
        viz.log_steplog(both, viz.SinkOptions(rrd=tmp_path / "x.rrd"), encounter_id=5)
    assert not (tmp_path / "x.rrd").exists() and not list(tmp_path.iterdir())
    path, _ = viz.log_steplog(both, viz.SinkOptions(rrd=tmp_path / "nine.rrd"), encounter_id=9, until_s=19.5)
    own = read_rrd(path)["/world/ownship"]
    assert own.num_rows == 20 and own.column("step").to_numpy()[-1] == 19


# ---- sinks and failure modes ------------------------------------------------------------------


def test_headless_spawn_warns_and_file_still_written(tmp_path, monkeypatch, table):
    for var in ("DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET"):
        monkeypatch.delenv(var, raising=False)
    assert not viz.has_display() or os.name == "nt" or os.sys.platform == "darwin"
    with pytest.warns(viz.VizWarning, match="needs a display"):
        written, logger = viz.log_steplog(table, viz.SinkOptions(rrd=tmp_path / "enc.rrd", spawn=True))
    assert written is not None and read_rrd(written)["/world/ownship"].num_rows == 240
    with pytest.warns(viz.VizWarning, match="needs a display"):
        logger = viz.EncounterLogger(viz.SinkOptions(spawn=True))
    assert not logger.enabled
    logger.log_step(records(table)[0])
    assert logger.close() is None


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_unreachable_viewer_is_a_warning(tmp_path, table):
    url = f"rerun+http://127.0.0.1:{free_port()}/proxy"
    with pytest.warns(viz.VizWarning, match="no Rerun viewer"):
        logger = viz.EncounterLogger(viz.SinkOptions(connect=url))
    assert not logger.enabled and logger.close() is None
    with pytest.raises(viz.UsageError, match="not a Rerun gRPC URL"):
        viz.EncounterLogger(viz.SinkOptions(connect="http//nonsense"))


def test_rerun_off_in_environment(tmp_path, monkeypatch):
    monkeypatch.setenv("RERUN", "off")
    with pytest.warns(viz.VizWarning, match="RERUN=off"):
        logger = viz.EncounterLogger(viz.SinkOptions(rrd=tmp_path / "enc.rrd"))
    assert logger.close() is None
    assert list(tmp_path.iterdir()) == []


def test_disabled_logger_never_touches_rerun(table):
    logger = viz.EncounterLogger(viz.SinkOptions())
    assert logger.rec is None and not logger.enabled
    logger.log_step(records(table)[0])
    logger.log_table(table)
    assert logger.close() is None and logger.steps_logged == 0


def test_interrupt_right_after_the_viewer_url_is_a_clean_stop(monkeypatch):
    """Whoever reads the URL may stop the server at once (CI sent SIGTERM right after the line, before
    the wait began, and the command exited 143): the announcement is inside the Ctrl-C guard, and the
    server is stopped either way."""

    class FakeServer:
        stopped = 0

        def alive(self) -> bool:
            return not self.stopped

        def stop(self) -> None:
            self.stopped += 1

    server = FakeServer()
    monkeypatch.setattr(viz.EncounterLogger, "web", property(lambda self: server))
    logger = viz.EncounterLogger(viz.SinkOptions())

    def announce_then_interrupted() -> None:
        raise KeyboardInterrupt  # the signal lands as the line is written

    logger.wait_serving(announce=announce_then_interrupted)  # returns: no KeyboardInterrupt escapes
    assert server.stopped == 1


def test_overwrite_and_atomic_output(tmp_path, table):
    target = tmp_path / "enc.rrd"
    target.write_bytes(b"old")
    with pytest.raises(OutputError, match="refusing to overwrite"):
        viz.EncounterLogger(viz.SinkOptions(rrd=target))
    logger = viz.EncounterLogger(viz.SinkOptions(rrd=target, overwrite=True))
    logger.log_table(table)
    assert target.read_bytes() == b"old", "the target is replaced only on close"
    assert logger.close() == target and target.read_bytes()[:4] == b"RRF2"
    # abort leaves neither the target nor a temporary file
    fresh = tmp_path / "aborted.rrd"
    logger = viz.EncounterLogger(viz.SinkOptions(rrd=fresh))
    logger.log_table(table)
    logger.abort()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["enc.rrd"]
    with pytest.raises(OutputError, match="not writable|missing"):
        viz.EncounterLogger(viz.SinkOptions(rrd=tmp_path / "no" / "such" / "dir.rrd"))


def test_bad_record_is_a_warning_not_a_crash(tmp_path, table):
    path = tmp_path / "enc.rrd"
    logger = viz.EncounterLogger(viz.SinkOptions(rrd=path), flush_interval_s=0.01)
    good = records(table)
    logger.log_step(good[0])
    logger.log_step({**good[1], "own_x": "not a number"})
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        logger.close()
    assert any(issubclass(w.category, viz.VizWarning) and "stopped after an error" in str(w.message) for w in caught)
    assert not logger.enabled


def test_decision_text_reasons(table):
    cols = viz.StepColumns.from_table(table)
    kinds = {}
    for k in range(cols.n):
        text, level = viz.decision_text(cols, k)
        kinds.setdefault(cols.s("decision")[k], (text, level))
    assert kinds["none"] == ("", "")
    assert kinds["pilot"][0].startswith("pilot: pilot command horizontal/right") and kinds["pilot"][1] == "INFO"
    assert "ProjL yes" in kinds["no_wait"][0] and kinds["no_wait"][1] == "WARN"
    assert "by rule axis" in kinds["blend"][0]


# ---- web viewer ------------------------------------------------------------------------------------


def test_web_viewer_on_loopback(tmp_path, table):
    grpc, web = free_port(), free_port()
    path = write(table, tmp_path / "enc.rrd")
    server = viz.WebServer("127.0.0.1", grpc, web, rrd=str(path))
    try:
        assert server.alive()
        with urllib.request.urlopen(f"http://127.0.0.1:{web}/", timeout=10) as resp:
            assert resp.status == 200 and b"Rerun" in resp.read()
        assert server.url.startswith(f"http://127.0.0.1:{web}/?url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A{grpc}")
    finally:
        server.stop()
    assert not server.alive()
    with pytest.raises(ProcessLookupError):
        os.killpg(server.proc.pid, 0)  # the whole process group is gone


def test_logger_streams_into_web_viewer(tmp_path, table):
    grpc, web = free_port(), free_port()
    opts = viz.SinkOptions(serve_web=True, grpc_port=grpc, web_port=web, rrd=tmp_path / "enc.rrd")
    logger = viz.EncounterLogger(opts)
    assert logger.enabled and logger.web is not None and logger.web.alive()
    logger.log_table(table)
    assert logger.close() == tmp_path / "enc.rrd"
    assert not logger.web.alive()


def _screenshot_unavailable() -> "str | None":
    try:
        import playwright  # noqa: F401
    except ImportError:
        return "playwright is not installed (pip install playwright)"
    if not any(shutil.which(n) for n in ("chromium", "chromium-browser", "google-chrome")):
        return "no chromium on PATH (apt-get install chromium)"
    return None


@pytest.mark.skipif(_screenshot_unavailable() is not None, reason=str(_screenshot_unavailable()))
def test_headless_web_viewer_screenshot(tmp_path, table):
    import importlib.util

    spec = importlib.util.spec_from_file_location("make_screenshot",
                                                  Path(__file__).parents[1] / "docs" / "make_screenshot.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    rrd, _ = viz.log_steplog(table, viz.SinkOptions(rrd=tmp_path / "enc.rrd"), until_s=130.0)
    png = mod.screenshot(rrd, tmp_path / "shot.png", wait_s=12.0, width=1200, height=700,
                         grpc_port=free_port(), web_port=free_port())
    from PIL import Image

    img = np.asarray(Image.open(png).convert("RGB"))
    assert img.shape == (700, 1200, 3)
    assert len(np.unique(img.reshape(-1, 3), axis=0)) > 20, "the viewer rendered more than a blank page"


# --------------------------------------------------------------------------------------------
# BackgroundRecorder: the helper process behind ``daa-sil run --rrd``. This pytest process has imported
# Rerun, so it may not fork: mode="exec" here; the forked helper is tested from a fresh interpreter
# (and by tests/test_viz_cli.py's ``daa-sil run --rrd`` cases).


def _steplog_file(tmp_path, table) -> Path:
    from daa_sil import steplog

    return steplog.write_steplog(table.cast(steplog.STEP_SCHEMA), tmp_path / "steps.parquet")


def _wait_ready(recorder, timeout_s: float = 60.0) -> None:
    assert recorder.ready.wait(timeout_s), "the helper never became ready"


def test_background_recorder_abort_and_owner_gone_leave_nothing(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    a = BackgroundRecorder(viz.SinkOptions(rrd=out / "a.rrd"), prepare_now=True)
    assert a.mode == "exec", "never fork a process that already runs Rerun"
    _wait_ready(a)
    assert a.tmp_path.exists(), "the helper writes into its temporary file"
    a.abort()
    assert a.proc.returncode is not None
    # the owner dies (its end of the pipe closes): the helper removes its file and exits by itself
    b = BackgroundRecorder(viz.SinkOptions(rrd=out / "b.rrd"), prepare_now=True, mode="exec")
    _wait_ready(b)
    b.proc.stdin.close()
    assert b.proc.wait(timeout=60) == 0
    b.abort()
    assert list(out.iterdir()) == []


def test_forked_helper_cleans_up_when_its_owner_dies(tmp_path):
    """A fresh interpreter forks the helper, lets it prepare, then dies without a word."""
    script = (
        "import os, sys\n"
        "from daa_sil.viz import SinkOptions\n"
        "from daa_sil.viz.recorder import BackgroundRecorder\n"
        "r = BackgroundRecorder(SinkOptions(rrd=sys.argv[1]), prepare_now=True)\n"
        "assert r.mode == 'fork', r.mode\n"
        "assert r.ready.wait(60)\n"
        "print(r.proc.pid, flush=True)\n"
        "os._exit(0)\n")
    cp = subprocess.run([sys.executable, "-c", script, str(tmp_path / "f.rrd")], capture_output=True, text=True,
                        timeout=120)
    assert cp.returncode == 0, cp.stderr
    pid = int(cp.stdout.split()[0])
    deadline = time.monotonic() + 30
    while _alive(pid) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not _alive(pid), "the orphaned helper exits on EOF"
    assert list(tmp_path.iterdir()) == [], "and removes its temporary file"


def _alive(pid: int) -> bool:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


def test_background_recorder_killed_helper_is_a_warning(tmp_path, table):
    src = _steplog_file(tmp_path, table)
    out = tmp_path / "out"
    out.mkdir()
    recorder = BackgroundRecorder(viz.SinkOptions(rrd=out / "k.rrd"), prepare_now=True)
    _wait_ready(recorder)
    os.killpg(recorder.proc.pid, 9)
    recorder.proc.wait(timeout=30)
    with pytest.warns(viz.VizWarning, match="stopped without writing the recording"):
        assert recorder.finish(src) is None
    assert list(out.iterdir()) == [], "neither the .rrd nor the temporary file"
    with pytest.raises(OutputError, match="missing or not writable"):
        BackgroundRecorder(viz.SinkOptions(rrd=tmp_path / "no" / "dir" / "x.rrd"))


def test_intruders_are_labelled_by_callsign(tmp_path, table):
    """A SIL step log names its intruders (``intruders`` metadata): the points' labels and the plots' series
    say ``HEAD1 13.8 km``, not ``#0 13.8 km`` (as on main); a step log without names keeps ``#0``."""
    import json

    named = table.replace_schema_metadata({**(table.schema.metadata or {}),
                                           b"intruders": json.dumps([{"icao": 1000, "callsign": "HEAD1"}])})
    labels = read_rrd(write(named, tmp_path / "named.rrd"))["/world/intruders/0"].column("Points3D:labels").to_pylist()
    rng = list_col(table, "range_m")
    assert labels[0] == [f"HEAD1 {rng[0] / 1000.0:.1f} km"], labels[0]
    assert all(lb[0].startswith("HEAD1 ") for lb in labels)
    series = [ch for ch in rr.chunk.RrdReader(tmp_path / "named.rrd").stream()
              if ch.is_static and ch.entity_path == "/plots/range/0"]
    assert "range HEAD1 [m]" in str(series[0].to_record_batch().to_pydict())
    plain = read_rrd(write(table, tmp_path / "plain.rrd"))["/world/intruders/0"].column("Points3D:labels").to_pylist()
    assert plain[0][0].startswith("#0 ")
