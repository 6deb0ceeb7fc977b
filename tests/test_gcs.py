"""GCS node: lockstep tick handling and scripted commands, against a fake vehicle on loopback."""

from __future__ import annotations

import asyncio
import json
import math
import signal
from pathlib import Path

import pytest

from daa_sil.link.codec import MavCodec
from daa_sil.link.codec import mavlink as M
from daa_sil.sil.endpoint import open_endpoint
from daa_sil.sil.scenario import parse_scenario
from gcs.node import GcsNode, GcsOptions

SCENARIO = """\
name: gcs-test
duration_s: 60
ownship: {alt_m: 1000, gs_mps: 55, track_deg: 0}
intruders:
  - cpa: {angle_deg: 180, hmd_m: 100, t_cpa_s: 50, gs_mps: 55}
pilot:
  mode: scripted
  commands:
    - {t_s: 2, until_s: 4, track_deg: 30}
"""


async def _recv_until(ep, pred, timeout=5.0) -> list:
    got = []
    loop = asyncio.get_running_loop()
    end = loop.time() + timeout
    while loop.time() < end:
        r = await ep.recv(end - loop.time())
        got.append(r.msg)
        if pred(r.msg):
            return got
    raise AssertionError(f"timed out; got {[m.get_type() for m in got]}")


@pytest.mark.asyncio
async def test_lockstep_tick_commands_then_ack_and_repeated_tick(tmp_path):
    sc = parse_scenario(SCENARIO)
    veh = await open_endpoint(MavCodec(1, 1), "udp:127.0.0.1:0")
    node = GcsNode(sc, GcsOptions(vehicle=f"udp:127.0.0.1:{veh.local_address[1]}", listen="udp:127.0.0.1:0",
                                  clock="lockstep", log=tmp_path / "cmds.jsonl", display=False))
    await node.start()
    task = asyncio.create_task(node.run())
    try:
        hello = await veh.recv(5.0)
        assert hello.msg.get_type() == "HEARTBEAT" and hello.msg.get_srcSystem() == 255
        gcs_addr = node.ep.local_address
        for k in range(5):
            veh.send(M.MAVLink_sim_tick_message(k, k * 1000), gcs_addr)
            got = await _recv_until(veh, lambda m: m.get_type() == "SIM_TICK_ACK")
            cmds = [m for m in got if m.get_type() == "PILOT_MANEUVER"]
            assert got[-1].tick == k
            # scripted command streamed once per step over [2, 4): steps 2 and 3 only, sent before the ack
            assert len(cmds) == (1 if k in (2, 3) else 0)
            for c in cmds:
                assert c.time_boot_ms == k * 1000 and c.track_deg == pytest.approx(30.0) and math.isnan(c.vs)
        # a repeated tick is acknowledged again without stepping again
        veh.send(M.MAVLink_sim_tick_message(3, 3000), gcs_addr)
        got = await _recv_until(veh, lambda m: m.get_type() == "SIM_TICK_ACK")
        assert got[-1].tick == 3 and not [m for m in got if m.get_type() == "PILOT_MANEUVER"]
        assert node.steps == 5 and [c.seq for c in node.sent] == [1, 2]
    finally:
        node.stop.set()
        await asyncio.wait_for(task, 5.0)
        node.write_log()
        node.close()
        veh.close()
    rows = [json.loads(x) for x in (tmp_path / "cmds.jsonl").read_text().splitlines()]
    assert [(r["t"], r["seq"], r["kind"]) for r in rows] == [(2.0, 1, "scripted"), (3.0, 2, "scripted")]


VEHICLE = ("127.0.0.1", 14601)


def _gcs_core():
    """A lockstep GCS protocol core (no socket) taking the vehicle side at VEHICLE, and the vehicle's codec."""
    from daa_sil.sil.intake import Intake
    from gcs.pilot import make_pilot
    from gcs.protocol import READ_IDS, GcsProtocol

    sc = parse_scenario(SCENARIO)
    codec = MavCodec(255, 190, read_ids=READ_IDS)
    intake = Intake(codec, peer=VEHICLE, learn_peer=False, allow_peers=[VEHICLE], allow_sysids=[1])
    core = GcsProtocol(sc, GcsOptions(clock="lockstep", display=False), codec, intake, make_pilot(sc, "scripted", None))
    return sc, core, MavCodec(1, 1)


def test_gcs_builds_what_the_pilot_sees_from_telemetry():
    from gcs.pilot import observed
    from vehicle import telemetry as T

    sc, core, veh = _gcs_core()
    own = T.Kin(100.0, 2000.0, 1000.0, 55.0, math.radians(10.0), 1.5)
    intr = T.Kin(-300.0, 6000.0, 1100.0, 60.0, math.radians(190.0), -2.0)
    core.receive(veh.encode_many([T.local_position(7.0, own), T.adsb_vehicle(1000, "X", intr, sc.origin),
                                  T.alert_level(7.0, 2)]), VEHICLE, 0.0)
    o, i = observed(core.view, core.order)
    assert (o.x[0], o.y[0], o.z[0]) == pytest.approx((100.0, 2000.0, 1000.0), abs=1e-3)
    assert (o.gs[0], math.degrees(o.trk[0]), o.vs[0]) == pytest.approx((55.0, 10.0, 1.5), abs=1e-4)
    # ADS-B is quantised (degE7 ~ 1 cm, cm/s, centidegrees)
    assert (i.x[0, 0], i.y[0, 0], i.z[0, 0]) == pytest.approx((-300.0, 6000.0, 1100.0), abs=0.05)
    assert (i.gs[0, 0], math.degrees(i.trk[0, 0]), i.vs[0, 0]) == pytest.approx((60.0, 190.0, -2.0), abs=0.01)
    assert core.view.alert == (7.0, 2)


def test_gcs_ignores_non_finite_and_older_telemetry():
    """A valid-CRC position with NaN fields, or an older datagram overtaking a newer one, must not
    replace what the pilot sees (nor the ADS-B and alert that ride with it); each is counted."""
    from gcs.pilot import observed
    from vehicle import telemetry as T

    sc, core, veh = _gcs_core()
    own = T.Kin(100.0, 2000.0, 1000.0, 55.0, math.radians(10.0), 1.5)
    intr = T.Kin(-300.0, 6000.0, 1100.0, 60.0, math.radians(190.0), -2.0)
    old_own = T.Kin(0.0, 0.0, 900.0, 55.0, 0.0, 0.0)
    old_intr = T.Kin(5000.0, 9000.0, 700.0, 60.0, 0.0, 0.0)
    nan_pos = M.MAVLink_local_position_ned_message(9000, math.nan, 0.0, -1000.0, 55.0, 0.0, 0.0)
    batches = [[T.local_position(7.0, own), T.adsb_vehicle(1000, "X", intr, sc.origin), T.alert_level(7.0, 2)],
               [T.local_position(5.0, old_own), T.adsb_vehicle(1000, "X", old_intr, sc.origin),
                T.alert_level(5.0, 0)],  # overtaken: older than t = 7 s
               [nan_pos]]
    for b in batches:
        core.receive(veh.encode_many(b), VEHICLE, 0.0)
    o, i = observed(core.view, core.order)
    assert (o.x[0], o.y[0], o.z[0]) == pytest.approx((100.0, 2000.0, 1000.0), abs=1e-3)
    assert (i.x[0, 0], i.y[0, 0]) == pytest.approx((-300.0, 6000.0), abs=0.05)
    assert core.view.alert == (7.0, 2) and core.view.last_t == 7.0
    assert core.view.rejected == 4  # old position, its ADS-B, its alert, the NaN position


def test_view_takes_only_physical_telemetry():
    """Issue 20 §1 (the GCS side): hostile telemetry with finite but absurd values (a position of 3e38 m,
    latitude 214 deg, alert level 7, a stamp ahead of the newest tick) used to reach the pilot's view;
    it is counted in ``rejected`` and the view keeps what it had."""
    from gcs.view import View

    def enu(lat_e7, lon_e7, alt_mm):  # a flat frame: 1e-7 deg = 0.011 m, enough for the bounds
        return lat_e7 * 0.0111, lon_e7 * 0.0111, alt_mm / 1000.0

    v = View()
    good = M.MAVLink_local_position_ned_message(5000, 100.0, 0.0, -1000.0, 55.0, 0.0, 0.0)
    v.take(good, enu, newest_tick=5.0)
    assert v.own[0] == 5.0 and v.rejected == 0
    for bad in (M.MAVLink_local_position_ned_message(6000, 3e38, 0.0, -1000.0, 55.0, 0.0, 0.0),  # 3e38 m north
                M.MAVLink_local_position_ned_message(6000, 0.0, 0.0, -1000.0, 2000.0, 0.0, 0.0),  # 2,000 m/s
                M.MAVLink_local_position_ned_message(6000, 0.0, 0.0, -2e5, 55.0, 0.0, 0.0),  # 200 km up
                M.MAVLink_local_position_ned_message(7500, 0.0, 0.0, -1000.0, 55.0, 0.0, 0.0)):  # after tick 5 + 1 s
        v.take(bad, enu, newest_tick=5.0)
    assert v.own[0] == 5.0 and v.rejected == 4
    v.take(M.MAVLink_local_position_ned_message(6000, 160.0, 0.0, -1000.0, 55.0, 0.0, 0.0), enu, newest_tick=5.0)
    assert v.own[0] == 6.0 and v.rejected == 4  # one step after the tick is fine (the vehicle's publish)
    for level, ok in ((7, False), (-1, False), (2**31 - 1, False), (2, True)):
        v.take(M.MAVLink_named_value_int_message(6000, b"DAA_ALERT", level), enu, newest_tick=5.0)
        assert (v.alert == (6.0, level)) == ok
    assert v.rejected == 7

    def adsb(lat_e7, heading_cdeg):
        return M.MAVLink_adsb_vehicle_message(1001, lat_e7, 0, 0, 1_000_000, heading_cdeg, 6000, 0, b"HEAD1", 0, 0,
                                              M.ADSB_FLAGS_VALID_COORDS, 0)

    v.take(adsb(2_140_000_000, 18000), enu)  # latitude 214 deg
    v.take(adsb(100_000, 40_000), enu)  # heading 400 deg
    assert v.intruders == {} and v.rejected == 9
    v.take(adsb(100_000, 18000), enu)
    assert list(v.intruders) == [1001]
    bands = M.MAVLink_daa_bands_message(6000, 0, 255, 0, 1, [0.0] * 16, [1.0] * 16, [3] + [0] * 15)
    v.take(bands, enu)  # count 255 > 16 slots: read as the 16 there are
    assert v.alert_regions == 3


@pytest.mark.asyncio
async def test_gcs_udpin_takes_the_first_vehicle_and_warns_about_a_second(capfd):
    """Issue 20 §12: ``daa-gcs --vehicle udpin:`` answered whoever sent first and took every later sender's
    telemetry too (silently); now a second sender is dropped with one warning, as in ``udp:`` mode."""
    from daa_sil.sil.supervise import free_udp_ports

    (port,) = free_udp_ports(1)
    sc = parse_scenario(SCENARIO)
    node = GcsNode(sc, GcsOptions(vehicle=f"udpin:127.0.0.1:{port}", clock="lockstep", display=False))
    await node.start()
    task = asyncio.create_task(node.run())
    first = await open_endpoint(MavCodec(1, 1), "udp:127.0.0.1:0", peer=("127.0.0.1", port))
    second = await open_endpoint(MavCodec(1, 1), "udp:127.0.0.1:0", peer=("127.0.0.1", port))
    try:
        first.send(M.MAVLink_local_position_ned_message(1000, 10.0, 0.0, -1000.0, 55.0, 0.0, 0.0))
        for _ in range(200):
            if node.view.own is not None:
                break
            await asyncio.sleep(0.01)
        second.send(M.MAVLink_local_position_ned_message(2000, 9e6, 0.0, -1000.0, 55.0, 0.0, 0.0))
        for _ in range(200):
            if node.ep.counters.datagrams_rejected_peer:
                break
            await asyncio.sleep(0.01)
    finally:
        node.stop.set()
        await asyncio.wait_for(task, 5.0)
        node.close()
        first.close()
        second.close()
    assert node.peer == first.local_address and node.view.own[0] == 1.0  # the second sender's position: not taken
    assert node.ep.counters.datagrams_rejected_peer == 1
    err = capfd.readouterr().err
    warned = [x for x in err.splitlines() if "dropping datagrams from" in x]
    assert len(warned) == 1 and f"udp:127.0.0.1:{second.local_address[1]} (LOCAL_POSITION_NED from system 1)" in warned[0]


@pytest.mark.asyncio
@pytest.mark.parametrize("clock", ["lockstep", "realtime"])
async def test_request_stop_wakes_the_loop_waiting_for_a_datagram(tmp_path, monkeypatch, clock):
    """SIGINT / SIGTERM call ``request_stop``: a loop waiting for a datagram ends at once instead of
    after its wait timed out (0.1 s in lockstep, up to 0.5 s in realtime), which the end of every
    ``daa-sil run`` waited for."""
    real_wait_for, timed_out = asyncio.wait_for, []

    async def counting_wait_for(aw, timeout):
        try:
            return await real_wait_for(aw, timeout)
        except asyncio.TimeoutError:
            timed_out.append(timeout)
            raise

    sc = parse_scenario(SCENARIO)
    veh = await open_endpoint(MavCodec(1, 1), "udp:127.0.0.1:0")
    node = GcsNode(sc, GcsOptions(vehicle=f"udp:127.0.0.1:{veh.local_address[1]}", listen="udp:127.0.0.1:0",
                                  clock=clock, log=tmp_path / "cmds.jsonl", display=False))
    await node.start()
    monkeypatch.setattr(asyncio, "wait_for", counting_wait_for)
    task = asyncio.create_task(node.run())
    try:
        await asyncio.sleep(0)  # the loop is now waiting for a datagram
        before = len(timed_out)
        node.request_stop()
        await real_wait_for(task, 5.0)
        assert node.stop.is_set()
        assert len(timed_out) == before, "the loop ended only after its wait timed out"
    finally:
        node.stop.set()
        if not task.done():
            task.cancel()
        node.close()
        veh.close()


def test_status_lines_are_flushed_in_batches_and_never_behind_a_warning(monkeypatch):
    """Off a TTY (a run's log, through a pipe) the per-step status lines are flushed at most every
    FLUSH_EVERY_S, not one write per line; a warning on stderr first flushes the lines printed before it,
    so the log keeps their order."""
    import sys

    from gcs import display
    from daa_sil.sil.msgguard import stderr_line

    events: list = []

    class Stream:
        def __init__(self, name):
            self.name = name

        def write(self, text):
            events.append((self.name, "write", text))
            return len(text)

        def flush(self):
            events.append((self.name, "flush", None))

        def isatty(self):
            return False

    monkeypatch.setattr(sys, "stdout", Stream("out"))
    monkeypatch.setattr(sys, "stderr", Stream("err"))
    monkeypatch.setattr(display, "format_line", lambda node, t, n: f"line {t:g}")
    monkeypatch.setattr(display, "_last_flush", -math.inf)
    monkeypatch.setattr(display, "FLUSH_EVERY_S", 3600.0)
    for t in range(5):
        display.render_line(None, float(t), 0)
    assert [e for e in events if e[1] == "flush"] == [("out", "flush", None)]  # the first line only
    assert events.index(("out", "flush", None)) < events.index(("out", "write", "line 1"))
    stderr_line("daa-gcs: warning: something")
    last_line = max(i for i, e in enumerate(events) if e[:2] == ("out", "write"))
    out_flush = max(i for i, e in enumerate(events) if e == ("out", "flush", None))
    err_write = next(i for i, e in enumerate(events) if e[0] == "err" and e[1] == "write")
    assert last_line < out_flush < err_write


def test_status_lines_are_batched_under_pythonunbuffered():
    """``daa-sil run`` starts the GCS with PYTHONUNBUFFERED=1 (every print a write): the status lines still
    reach the pipe in batches, and a warning on stderr first writes the ones held back."""
    import os
    import subprocess
    import sys

    code = r'''
import os, sys
from gcs import display
from daa_sil.sil.msgguard import stderr_line
r, w = os.pipe()
os.dup2(w, 1)  # stdout is now a pipe this process reads itself
os.set_blocking(r, False)
def written():
    try:
        return os.read(r, 65536).decode()
    except BlockingIOError:
        return ""
display.format_line = lambda node, t, n: f"line {t:g}"
display.FLUSH_EVERY_S = 3600.0
for t in range(5):
    display.render_line(None, float(t), 0)
first = written()
stderr_line("daa-gcs: warning: test")
rest = written()
print(repr((first, rest)), file=sys.stderr)
'''
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    res = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stderr[-2000:]
    import ast

    first, rest = ast.literal_eval(res.stderr.strip().splitlines()[-1])
    assert first == "line 0\n"
    assert rest == "line 1\nline 2\nline 3\nline 4\n"


@pytest.mark.parametrize("sig,code", [(signal.SIGINT, 130), (signal.SIGTERM, 143), (None, 0)])
def test_daa_gcs_exits_as_daa_vehicle_does(tmp_path, sig, code):
    """Ctrl-C 130 and SIGTERM 143 (exit 0 on main, where daa-vehicle gave 130), ``--duration`` 0; the
    command log is written either way."""
    import subprocess
    import sys
    import time

    from daa_sil.sil.supervise import free_udp_ports

    root = Path(__file__).resolve().parents[1]
    (port,) = free_udp_ports(1)
    argv = [sys.executable, "-m", "gcs", "--scenario", str(root / "scenarios" / "head_on.yaml"), "--listen",
            "udp:127.0.0.1:0", "--vehicle", f"udp:127.0.0.1:{port}", "--no-display", "--log", str(tmp_path / "c.jsonl")]
    proc = subprocess.Popen(argv + (["--duration", "1"] if sig is None else []), stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, cwd=root)
    try:
        ready = proc.stdout.readline()
        assert ready.startswith("READY"), ready
        if sig is not None:
            time.sleep(0.2)
            proc.send_signal(sig)
        out, _ = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == code, out
    assert (tmp_path / "c.jsonl").exists() and "Traceback" not in out
