"""Vehicle: command gate rules, and a stock pymavlink (mavutil) client attached to a real vehicle process."""

from __future__ import annotations

import math
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from vehicle.commands import CommandGate, PilotCommand

ROOT = Path(__file__).resolve().parents[1]


def _cmd(t, seq, trk=90.0, src=(255, 190)):
    return PilotCommand(t, seq, trk, math.nan, math.nan, src)


def test_gate_applies_each_command_once_and_never_an_older_one():
    g = CommandGate()
    assert g.offer(_cmd(10.0, 5), t_now=14.0)
    assert not g.offer(_cmd(10.0, 5), t_now=15.0)  # duplicate (link dup / replay)
    assert g.offer(_cmd(11.0, 6), t_now=15.0)
    assert not g.offer(_cmd(10.5, 7), t_now=16.0)  # sent earlier than the applied one: reordered, dropped
    assert not g.offer(_cmd(11.0, 4), t_now=16.0)  # same send time, older sequence number
    assert g.offer(_cmd(9.0, 1, src=(255, 230)), t_now=16.0)  # another source has its own order
    c = g.counters
    assert (c.accepted, c.duplicate, c.older) == (3, 1, 2)


def test_gate_drops_future_and_invalid_commands():
    g = CommandGate(max_future_s=2.0)
    assert not g.offer(_cmd(20.5, 1), t_now=18.0)  # stamped 2.5 s in the future: forged / unsynchronised
    assert not g.offer(PilotCommand(5.0, 1, math.nan, math.nan, math.nan), t_now=6.0)  # says nothing
    assert not g.offer(_cmd(5.0, 2, trk=400.0), t_now=6.0)
    assert not g.offer(PilotCommand(5.0, 3, math.inf, 0.0, 50.0), t_now=6.0)
    assert g.counters.future == 1 and g.counters.invalid == 3 and g.counters.accepted == 0


def _free_port() -> int:
    from daa_sil.sil.supervise import free_udp_ports

    return free_udp_ports(1)[0]


@pytest.fixture()
def vehicle_and_client():
    """A vehicle process streaming (realtime, 5x) to a mavutil ``udpin`` connection."""
    os.environ["MAVLINK20"] = "1"
    from pymavlink import mavutil

    port = _free_port()
    conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=255, source_component=190,
                                      dialect="common")
    proc = subprocess.Popen([sys.executable, "-m", "vehicle", str(ROOT / "scenarios" / "two_intruders.yaml"),
                             "--out", f"udp:127.0.0.1:{port}", "--speed", "5", "--quiet"],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=ROOT)
    try:
        yield conn, proc
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        conn.close()


def _collect(conn, seconds: float, want=None) -> list:
    out, end = [], time.monotonic() + seconds
    while time.monotonic() < end:
        m = conn.recv_match(blocking=True, timeout=0.2)
        if m is None:
            continue
        out.append(m)
        if want is not None and want(m):
            break
    return out


def test_stock_mavutil_client_sees_ownship_and_intruders_and_can_command(vehicle_and_client):
    from daa_sil.link.dialect import daa_sil as dialect
    from daa_sil.sil.scenario import load_scenario

    conn, proc = vehicle_and_client
    sc = load_scenario(ROOT / "scenarios" / "two_intruders.yaml")
    msgs = _collect(conn, 15.0, want=lambda m: m.get_type() == "ADSB_VEHICLE" and m.ICAO_address == sc.intruders[-1].id)
    types = {m.get_type() for m in msgs}
    assert {"HEARTBEAT", "GLOBAL_POSITION_INT", "ATTITUDE", "ADSB_VEHICLE", "SYSTEM_TIME"} <= types
    hb = next(m for m in msgs if m.get_type() == "HEARTBEAT")
    assert (hb.get_srcSystem(), hb.get_srcComponent(), hb.type) == (1, 1, mavutil_const("MAV_TYPE_FIXED_WING"))
    pos = [m for m in msgs if m.get_type() == "GLOBAL_POSITION_INT"][-1]
    assert pos.lat != 0 and pos.lon != 0
    assert abs(pos.lat / 1e7 - sc.origin.lat_deg) < 0.1  # near the scenario origin
    adsb = [m for m in msgs if m.get_type() == "ADSB_VEHICLE"]
    assert {m.ICAO_address for m in adsb} == {i.id for i in sc.intruders}
    assert all(m.get_srcSystem() == 1 and m.flags & 1 and m.tslc <= 15 for m in adsb)  # QGC's conditions
    t_now = max(m.time_boot_ms for m in msgs if m.get_type() == "GLOBAL_POSITION_INT") / 1000.0

    # 1) the standard setpoint: SET_POSITION_TARGET_GLOBAL_INT velocity (east at 55 m/s). As ArduPilot, the
    #    vehicle answers no COMMAND_ACK (it is not a command); POSITION_TARGET_GLOBAL_INT shows the target flown.
    before = [m for m in msgs if m.get_type() == "POSITION_TARGET_GLOBAL_INT"][-1]
    assert before.vx > 50 and abs(before.vy) < 1  # flying north (track 0) before
    conn.mav.set_position_target_global_int_send(int(t_now * 1000), 1, 1, 6, 0x0DC7, 0, 0, 0, 0.0, 55.0, 0.0,
                                                 0, 0, 0, 0, 0)
    got = _collect(conn, 5.0, want=lambda m: m.get_type() == "POSITION_TARGET_GLOBAL_INT" and m.vy > 50)
    assert not [m for m in got if m.get_type() == "COMMAND_ACK"]
    tgt = [m for m in got if m.get_type() == "POSITION_TARGET_GLOBAL_INT"][-1]
    assert abs(tgt.vx) < 1 and abs(tgt.vy - 55.0) < 0.01 and tgt.type_mask == 0x0DC7

    # 2) the pilot maneuver message of our dialect, packed with the client's own MAVLink object
    pm = dialect.MAVLink_pilot_maneuver_message(int(t_now * 1000) + 1, 7, 1, 1, 45.0, 0.0, 55.0)
    conn.mav.send(pm)
    conn.mav.send(pm)  # a duplicate must not be applied (or acknowledged) twice
    got = _collect(conn, 5.0)
    acks = [m for m in got if m.get_type() == "COMMAND_ACK" and m.command == dialect.MAVLINK_MSG_ID_PILOT_MANEUVER]
    assert len(acks) == 1 and acks[0].result_param2 == 7
    assert proc.poll() is None


def test_hostile_datagrams_do_not_crash_the_vehicle(vehicle_and_client):
    import socket

    conn, proc = vehicle_and_client
    msgs = _collect(conn, 10.0, want=lambda m: m.get_type() == "HEARTBEAT")
    assert msgs
    ready = proc.stdout.readline()  # (the boot line, on stderr, comes first) READY listen=udp:127.0.0.1:PORT ...
    while ready and not ready.startswith("READY"):
        ready = proc.stdout.readline()
    assert ready.startswith("READY listen=udp:127.0.0.1:")
    vaddr = ("127.0.0.1", int(ready.split()[1].rsplit(":", 1)[1]))
    sk = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        for junk in (b"", b"\xfd", b"\xfd\x09\x00\x00\x00\xff\xbe\x4c\x00\x00" + b"\x00" * 5, os.urandom(300),
                     b"\xfe" * 1000):
            sk.sendto(junk, vaddr)
    finally:
        sk.close()
    after = _collect(conn, 3.0)
    assert any(m.get_type() == "GLOBAL_POSITION_INT" for m in after)  # still streaming
    assert proc.poll() is None


def mavutil_const(name: str) -> int:
    from pymavlink.dialects.v20 import common

    return getattr(common, name)


def test_vehicle_cli_bad_input_is_one_line(tmp_path):
    cp = subprocess.run([sys.executable, "-m", "vehicle", str(tmp_path / "missing.yaml")], capture_output=True,
                        text=True, timeout=60, cwd=ROOT)
    assert cp.returncode == 2
    assert cp.stderr.strip() == f"daa-vehicle: error: {tmp_path / 'missing.yaml'}: scenario file not found"
    cp = subprocess.run([sys.executable, "-m", "vehicle", str(ROOT / "scenarios" / "head_on.yaml"), "--out", "tcp:x:1"],
                        capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert cp.returncode == 2 and cp.stderr.count("\n") == 1 and "tcpin:HOST:PORT" in cp.stderr
