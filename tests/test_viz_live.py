"""Live Rerun streaming of a SIL run: the step feed (daa_sil.sil.live), the recorder's live mode, the
vehicle's --live option and ``daa-sil run --clock realtime`` with live logging."""

from __future__ import annotations

import json
import math
import socket
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest

from daa_sil.sil import live
from daa_sil import steplog
from daa_sil.errors import UsageError
from viz_encounter import make_steplog, records, rerun_env  # noqa: F401 (fixture)

ROOT = Path(__file__).resolve().parents[1]
PROC_LIMIT_S = 180  # generous bound so a hung process fails the test instead of blocking CI


pytestmark = pytest.mark.usefixtures("rerun_env")


@pytest.fixture(scope="module")
def table() -> pa.Table:
    return make_steplog(n_steps=60, encounter_id=0)


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _short_scenario(tmp_path: Path, duration_s: int = 40) -> Path:
    """head_on.yaml shortened (CPA at 3/4 of the run) without its expectations."""
    text = (ROOT / "scenarios" / "head_on.yaml").read_text()
    text = text.replace("duration_s: 180", f"duration_s: {duration_s}")
    text = text.replace("t_cpa_s: 120", f"t_cpa_s: {duration_s * 3 // 4}")
    text = "\n".join(line for line in text.splitlines() if not line.startswith("expect:"))
    path = tmp_path / "short.yaml"
    path.write_text(text + "\n")
    return path


# --------------------------------------------------------------------------------------------
# the wire format and the receiver's state (no I/O)


def test_row_round_trip_is_exact(table):
    row = records(table)[30]
    row["delay_up_s"] = math.nan
    row["own_x"] = 0.1 + 0.2  # not representable in short decimal form
    got = live.decode_row(live.encode_row(row))
    assert set(got) == set(row)
    assert math.isnan(got["delay_up_s"]) and got["own_x"] == row["own_x"]
    assert got["range_m"] == row["range_m"] and got["bands_trk_region"] == row["bands_trk_region"]
    assert len(live.encode_row(row)) < live.MAX_DATAGRAM
    # numpy values (StepLogBuilder-style) encode to the same bytes as plain ones
    assert live.encode_row({"step": np.int32(3), "t": np.float64(3.0), "range_m": np.array([1.5])}) == \
        live.encode_row({"step": 3, "t": 3.0, "range_m": [1.5]})


@pytest.mark.parametrize("data", [
    b"", b"garbage", b"DAASIL-STEP1 {not json", b"DAASIL-STEP1 [1, 2]", b"DAASIL-STEP1 {}",
    b'DAASIL-STEP1 {"step": true, "t": 0}', b'DAASIL-STEP1 {"step": -1, "t": 0}',
    b'DAASIL-STEP1 {"step": 1, "t": NaN}', b'DAASIL-STEP1 {"step": 1, "t": 1, "own_x": "x"}',
    b'DAASIL-STEP1 {"step": 1, "t": 1, "decision": 3}', b'DAASIL-STEP1 {"step": 1, "t": 1, "range_m": 5}',
    b'DAASIL-STEP1 {"step": 1, "t": 1, "bands_trk_region": [1]}', b"DAASIL-STEP1 \xff\xfe",
])
def test_garbage_is_rejected(data):
    with pytest.raises(live.LiveRecordError):
        live.decode_row(data)


def test_unknown_columns_are_dropped():
    assert live.decode_row(b'DAASIL-STEP1 {"step": 2, "t": 2.0, "future_column": {"a": 1}}') == {"step": 2, "t": 2.0}


@pytest.mark.parametrize("spec", ["udp:10.0.0.1:5000", "udp:0.0.0.0:5000", "tcp:127.0.0.1:5000",
                                  "udp:127.0.0.1:0", "udp:127.0.0.1:x", "127.0.0.1:5000"])
def test_live_address_is_loopback_only(spec):
    with pytest.raises(UsageError):
        live.parse_live_address(spec)
    assert live.parse_live_address("udp:localhost:5000") == ("127.0.0.1", 5000)


def test_feed_counts_bad_and_stale_and_lists_missing_rows(table):
    rows = records(table)
    feed = live.LiveFeed()
    logged = []
    for data in ([live.encode_row(r) for r in rows[:5]] + [b"junk", live.encode_row(rows[3])]
                 + [live.encode_row(r) for r in rows[7:]]):
        row = feed.feed(data)
        if row is not None:
            logged.append(row["step"])
    assert logged == [r["step"] for r in rows[:5] + rows[7:]]
    assert feed.counters() == {"received": len(rows) - 2 + 2, "logged": len(rows) - 2, "bad": 1, "stale": 1}
    assert feed.missing(table) == [5, 6]
    # a row that arrived different from the step log's is backfilled too
    feed.rows[10] = live.encode_row({**rows[10], "own_x": rows[10]["own_x"] + 1.0})
    assert feed.missing(table) == [5, 6, 10]


def test_sender_never_raises_without_a_receiver():
    sender = live.LiveSender(f"udp:127.0.0.1:{_free_port()}")  # nobody listens there
    try:
        for k in range(50):
            sender.send({"step": k, "t": float(k)})
        assert sender.send({"step": 1, "t": 1.0, "x": object()}) is False  # cannot encode: counted
        sender.send({"step": 2, "t": 2.0, "own_x": [0.0] * 20_000})  # too big for one datagram
    finally:
        sender.close()
    assert sender.stats.sent + sender.stats.errors == 51  # 50 sends (delivered or not) + 1 encoding error
    assert sender.stats.errors >= 1 and sender.stats.too_big == 1


# --------------------------------------------------------------------------------------------
# the recorder's live mode (no SIL: the test plays the vehicle)

rr = pytest.importorskip("rerun")

from daa_sil import viz  # noqa: E402
from daa_sil.viz.recorder import BackgroundRecorder  # noqa: E402
from test_viz import read_rrd, static_entities  # noqa: E402
from test_viz_cli import _procs_mentioning  # noqa: E402


@pytest.fixture
def viewer(tmp_path):
    """A headless Rerun viewer: the rerun binary serving gRPC on 127.0.0.1 and saving what it gets.
    Yields (its URL, the file it saves to)."""
    import os
    import signal

    port = _free_port_tcp()
    saved = tmp_path / "viewer.rrd"
    srv = subprocess.Popen([viz.rerun_binary(), "--serve-grpc", "--bind", "127.0.0.1", "--port", str(port),
                            "--save", str(saved)], stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                           stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        for _ in range(300):
            if viz.port_open("127.0.0.1", port, 0.1) or srv.poll() is not None:
                break
            time.sleep(0.02)
        assert srv.poll() is None, "the headless viewer started"
        yield f"rerun+http://127.0.0.1:{port}/proxy", saved
    finally:
        try:
            os.killpg(srv.pid, signal.SIGTERM)
        except ProcessLookupError:
            pass
        srv.wait(timeout=10)


def _free_port_tcp() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _viewer_rows(saved: Path, n_steps: int) -> dict:
    """What the headless viewer saved (it writes as data comes; wait, bounded, for ``n_steps`` rows)."""
    data: dict = {}
    for _ in range(200):
        if saved.exists():
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # a file still being written has no footer
                try:
                    data = read_rrd(saved)
                except Exception:
                    data = {}
            if "/world/ownship" in data and data["/world/ownship"].num_rows >= n_steps:
                return data
        time.sleep(0.05)
    return data


def _play_live(tmp_path: Path, table: pa.Table, url: str, skip=(), garbage: int = 0, mode: str = "auto"):
    """Send ``table``'s rows (minus ``skip``) and ``garbage`` junk datagrams to a live recorder that
    streams to the viewer at ``url`` and writes an .rrd, then hand it the step log; returns (the
    recorder's DONE result, the .rrd path)."""
    log = tmp_path / "steplog.parquet"
    steplog.write_steplog(table.cast(steplog.STEP_SCHEMA), log)
    rrd = tmp_path / "enc.rrd"
    rec = BackgroundRecorder(viz.SinkOptions(rrd=rrd, connect=url, overwrite=True), preset="do365", encounter_id=0,
                             live=True, prepare_now=True, mode=mode)
    try:
        assert rec.live_address and rec.live_address.startswith("udp:127.0.0.1:")
        assert rec.ready.wait(60), "the helper prepared"
        sender = live.LiveSender(rec.live_address)
        junk = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            for _ in range(garbage):
                junk.sendto(b"\x00garbage\xff", live.parse_live_address(rec.live_address))
            for r in records(table):
                if r["step"] not in skip:
                    assert sender.send(r)
        finally:
            sender.close()
            junk.close()
        path = rec.finish(log)
    finally:
        rec.abort()
    assert path == rrd
    return rec.result, rrd


def _deferred(tmp_path: Path, table: pa.Table) -> Path:
    ref, _ = viz.log_steplog(table, viz.SinkOptions(rrd=tmp_path / "ref.rrd"), preset="do365")
    return ref


def _assert_same(got: dict, want: dict, values: bool = True) -> None:
    assert sorted(got) == sorted(want)
    for ent in want:
        assert got[ent].num_rows == want[ent].num_rows, ent
        if values:
            for name in want[ent].column_names:
                assert got[ent].column(name).to_pylist() == want[ent].column(name).to_pylist(), (ent, name)


def _assert_rrd_is_deferred(rrd: Path, ref: Path) -> None:
    _assert_same(read_rrd(rrd), read_rrd(ref))
    assert static_entities(rrd) == static_entities(ref)
    assert len(rr.chunk.RrdReader(rrd).blueprints()) == 1
    assert rrd.stat().st_size <= 1_000_000


def test_live_recorder_streams_rows_to_the_viewer(tmp_path, table, viewer):
    url, saved = viewer
    result, rrd = _play_live(tmp_path, table, url, garbage=2)
    info = result["live"]
    assert info["bad"] == 2 and info["logged"] == table.num_rows and info["backfilled"] == 0 and info["viewer"]
    assert result["steps"] == table.num_rows
    ref = _deferred(tmp_path, table)
    _assert_same(_viewer_rows(saved, table.num_rows), read_rrd(ref))  # the viewer saw exactly the encounter
    _assert_rrd_is_deferred(rrd, ref)


def test_lost_rows_are_backfilled(tmp_path, table, viewer):
    url, saved = viewer
    result, rrd = _play_live(tmp_path, table, url, skip={0, 17, 18, 59}, mode="exec")
    info = result["live"]
    assert info["logged"] == table.num_rows - 4 and info["backfilled"] == 4
    ref = _deferred(tmp_path, table)
    # every step reached the viewer (the backfilled ones last, so their trails differ: rows only)
    _assert_same(_viewer_rows(saved, table.num_rows), read_rrd(ref), values=False)
    _assert_rrd_is_deferred(rrd, ref)
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == [], "no temporary file left"


def test_no_viewer_is_a_warning_and_the_rrd_is_still_written(tmp_path, table, capfd):
    url = f"rerun+http://127.0.0.1:{_free_port_tcp()}/proxy"  # nobody listens there
    result, rrd = _play_live(tmp_path, table, url)
    assert f"daa-sil: warning: no Rerun viewer at {url}" in capfd.readouterr().err
    assert result["live"]["viewer"] is False and result["live"]["logged"] == table.num_rows
    _assert_rrd_is_deferred(rrd, _deferred(tmp_path, table))


def test_predicted_focus_is_the_straight_line_closest_approach():
    """Ownship north at 50 m/s, intruder 10 km north flying south at 50 m/s, 200 m east: CPA at t = 100 s
    with the ownship at (0, 5000); the camera looks halfway to the intruder. The farther intruder is ignored."""
    row = {"step": 0, "t": 0.0, "own_x": 0.0, "own_y": 0.0, "own_z": 1000.0, "own_gs": 50.0, "own_trk_deg": 0.0,
           "own_vs": 0.0, "intr_x": [200.0, 30000.0], "intr_y": [10000.0, 0.0], "intr_z": [1000.0, 1000.0],
           "intr_gs": [50.0, 10.0], "intr_trk_deg": [180.0, 90.0], "intr_vs": [0.0, 0.0]}
    center, extent = viz.predicted_focus(row)
    assert np.allclose(center, [100.0, 5000.0, 1000.0], atol=1e-6) and extent == 6000.0
    assert viz.predicted_focus({"step": 0, "t": 0.0}) == ([0.0, 0.0, 0.0], 8000.0)


# --------------------------------------------------------------------------------------------
# processes


def test_vehicle_keeps_running_without_a_recorder(tmp_path):
    scenario = _short_scenario(tmp_path, duration_s=20)
    log = tmp_path / "steps.parquet"
    cp = subprocess.run([sys.executable, "-m", "vehicle", str(scenario), "--out", f"udp:127.0.0.1:{_free_port()}",
                         "--speed", "50", "--live", f"udp:127.0.0.1:{_free_port()}", "--steplog", str(log), "--quiet",
                         "--exit-at-end"],
                        capture_output=True, text=True, timeout=PROC_LIMIT_S, cwd=ROOT)
    assert cp.returncode == 0, cp.stderr
    assert "done, 20 steps" in cp.stdout and "live rows sent" in cp.stdout
    table = steplog.read_steplog(log)
    assert table.num_rows == 20
    sent = json.loads(steplog.steplog_metadata(log)["live"])
    assert sent["sent"] + sent["errors"] == 20


def test_vehicle_rejects_a_non_loopback_live_address(tmp_path):
    cp = subprocess.run([sys.executable, "-m", "vehicle", str(_short_scenario(tmp_path)),
                         "--live", "udp:192.0.2.1:9000"], capture_output=True, text=True, timeout=PROC_LIMIT_S,
                        cwd=ROOT)
    assert cp.returncode == 2 and "loopback only" in cp.stderr and "Traceback" not in cp.stderr


def test_realtime_run_streams_steps_while_it_plays(tmp_path, viewer):
    """``--clock realtime --connect URL --rrd FILE`` (auto live mode): steps reach the viewer before the
    vehicle exits, the viewer gets every step, and the .rrd equals the deferred conversion."""
    url, saved = viewer
    out = tmp_path / "run"
    rrd = out / "enc.rrd"
    env = {k: v for k, v in __import__("os").environ.items() if k != "RERUN"}
    cp = subprocess.run([sys.executable, "-m", "daa_sil.cli", "run", str(_short_scenario(tmp_path)), "--out",
                         str(out), "--rrd", str(rrd), "--clock", "realtime", "--speed", "20", "--connect", url,
                         "--json"], capture_output=True, text=True, timeout=PROC_LIMIT_S, cwd=ROOT, env=env)
    assert cp.returncode == 0, cp.stderr
    assert _procs_mentioning(str(out)) == [], "no SIL process or recorder helper left"
    assert "warning" not in cp.stderr and "Traceback" not in cp.stderr
    result = json.loads(cp.stdout)
    info = result["rrd_timing"]["live"]
    assert result["steps"] == 40 and result["files"]["rrd"] == str(rrd)
    assert info["viewer"] and info["bad"] == 0 and info["logged"] + info["backfilled"] == 40
    # logged during the run, not after it: at least the first steps were in Rerun before the vehicle exited
    assert info["before_exit"] >= 1 and info["first_logged_before_exit_s"] > 0, info
    table = steplog.read_steplog(out / "steplog.parquet")
    ref = _deferred(tmp_path, table)
    _assert_same(_viewer_rows(saved, 40), read_rrd(ref), values=info["backfilled"] == 0)
    _assert_rrd_is_deferred(rrd, ref)
    assert "live rows sent 40, failed 0" in (out / "logs" / "vehicle.log").read_text()
