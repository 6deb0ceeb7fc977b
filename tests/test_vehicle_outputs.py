"""Issue 20 §12: more than one ground station, as SITL's repeatable ``--out``.

* ``daa-vehicle --out A --out B --out C,rw --out udpin:...``: the first is the pilot's link; each
  further one gets the telemetry with its **own** stream rates, may read, is **read-only** unless
  marked ``,rw`` (then its parameter writes apply, and the other observers hear of them), and never
  flies pilot commands;
* a ``udpin:`` output answers every ground station that spoke to it lately, each with its own stream
  and reply budget (as the vehicle's ``--out udpin:``, tests/test_interop_mavutil.py);
* ``daa-sil run --vehicle-out`` forwards outputs to the vehicle it starts;
* the syntax errors are one line.
"""

from __future__ import annotations

import asyncio
import json
import re
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from daa_sil.errors import UsageError
from daa_sil.link.codec import MavCodec, mavlink as M
from daa_sil.sil.outputs import output_specs
from daa_sil.sil.scenario import parse_scenario
from daa_sil.sil.supervise import free_udp_ports
from hostile_helpers import SCENARIO
from vehicle.node import VehicleNode, VehicleOptions

ROOT = Path(__file__).resolve().parents[1]
HANG_GUARD_S = 120.0


class Station:
    """A test ground station: a non-blocking UDP socket and what it received (decoded)."""

    def __init__(self, port: int = 0, sysid: int = 255, compid: int = 190):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", port))
        self.sock.setblocking(False)
        self.codec = MavCodec(sysid, compid)
        self.rx = MavCodec(sysid, compid)
        self.msgs: list = []
        self.addr = f"udp:127.0.0.1:{self.sock.getsockname()[1]}"

    def send(self, msg, to) -> None:
        self.sock.sendto(self.codec.encode(msg), to)

    def poll(self) -> None:
        while True:
            try:
                data = self.sock.recv(65535)
            except BlockingIOError:
                return
            self.msgs += self.rx.decode(data)

    def of(self, mtype: str) -> list:
        return [m for m in self.msgs if m.get_type() == mtype]


async def _until(cond, stations, what: str, timeout: float = HANG_GUARD_S) -> None:
    loop = asyncio.get_running_loop()
    end = loop.time() + timeout
    while loop.time() < end:
        for s in stations:
            s.poll()
        if cond():
            return
        await asyncio.sleep(0.02)
    raise AssertionError(f"timed out waiting for {what}")


def test_each_output_has_its_own_rates_and_is_read_only_unless_marked(capfd):
    sc = parse_scenario(SCENARIO.replace("duration_s: 30", "duration_s: 600"), "outputs.yaml")
    gcs, ro, rw, first, second = Station(), Station(), Station(), Station(compid=191), Station(compid=192)
    (din,) = free_udp_ports(1)

    async def go():
        veh = VehicleNode(sc, VehicleOptions(out=gcs.addr, also_out=(ro.addr, rw.addr + ",rw", f"udpin:127.0.0.1:{din}"),
                                             clock="realtime", speed=5.0))
        await veh.start()
        await veh.prepare()  # the simulation ready before the test talks to it
        task = asyncio.create_task(veh.run())
        try:
            assert [o.name for o in veh.outputs] == ["gcs", "out2", "out3", "out4"]
            everyone = (gcs, ro, rw)
            await _until(lambda: all(s.of("VFR_HUD") for s in everyone), everyone, "telemetry on every output")
            # the read-only observer stops its VFR_HUD: its own stream only
            ro.send(M.MAVLink_command_long_message(1, 1, M.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                                                   M.MAVLINK_MSG_ID_VFR_HUD, -1, 0, 0, 0, 0, 0), veh.ep.local_address)
            await _until(lambda: ro.of("COMMAND_ACK"), everyone, "the ack")
            assert ro.of("COMMAND_ACK")[-1].result == M.MAV_RESULT_ACCEPTED
            await asyncio.sleep(0.2)  # a step for the change to hold
            for s in everyone:
                s.poll()
                s.msgs.clear()
            await _until(lambda: len(gcs.of("GLOBAL_POSITION_INT")) >= 4, everyone, "four steps")
            assert not ro.of("VFR_HUD") and ro.of("GLOBAL_POSITION_INT")  # its VFR_HUD stopped, nothing else
            assert len(gcs.of("VFR_HUD")) >= 3 and len(rw.of("VFR_HUD")) >= 3  # the others' streams unchanged
            # writes: refused from the read-only one, applied from the ,rw one (and announced to the others)
            ro.send(M.MAVLink_param_set_message(1, 1, b"DAA_WT", 9.0, M.MAV_PARAM_TYPE_REAL32), veh.ep.local_address)
            await _until(lambda: ro.of("PARAM_VALUE"), everyone, "the read-only answer")
            assert ro.of("PARAM_VALUE")[-1].param_value == 4.0
            rw.send(M.MAVLink_param_set_message(1, 1, b"DAA_WT", 9.0, M.MAV_PARAM_TYPE_REAL32), veh.ep.local_address)
            await _until(lambda: rw.of("PARAM_VALUE"), everyone, "the writable answer")
            assert rw.of("PARAM_VALUE")[-1].param_value == 9.0 and veh.core.core.policy.wait_threshold_s == 9.0
            await _until(lambda: any(t.text == "DAA_WT 4 -> 9" for t in ro.of("STATUSTEXT")), everyone,
                         "the other observer told")
            # a pilot command from a writable observer is still not flown: commands cross the delayed link
            rw.send(M.MAVLink_pilot_maneuver_message(int(veh.t * 1000), 1, 1, 1, 90.0, 0.0, 55.0), veh.ep.local_address)
            await _until(lambda: veh.stats.commands_from_observers_ignored == 1, everyone, "the command ignored")
            assert veh.gate.counters.accepted == 0
            # udpin output: every sender is a ground station of its own; a second one is answered too
            first.send(M.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3), ("127.0.0.1", din))
            await _until(lambda: first.of("GLOBAL_POSITION_INT"), (first,), "the udpin output streaming")
            second.send(M.MAVLink_param_request_list_message(1, 1), ("127.0.0.1", din))
            await _until(lambda: len(second.of("PARAM_VALUE")) == 8, (first, second), "the second sender answered")
            await _until(lambda: second.of("GLOBAL_POSITION_INT"), (first, second), "the second one's stream")
            assert not first.of("PARAM_VALUE")  # the list went to who asked for it
            assert veh.outputs[3].intake.counters.datagrams_rejected_peer == 0
            return veh, [(e.link, e.name, e.status) for e in veh.services.events]
        finally:
            veh.request_stop()
            task.cancel()
            try:
                await task
            except asyncio.CancelledError:
                pass
            veh.close()

    try:
        veh, events = asyncio.run(go())
    finally:
        for s in (gcs, ro, rw, first, second):
            s.sock.close()
    assert events == [("out2", "DAA_WT", "denied_readonly"), ("out3", "DAA_WT", "accepted")]
    err = capfd.readouterr().err
    assert "dropping datagrams from" not in err


@pytest.mark.parametrize("outs,tap,needle", [
    (["udp:127.0.0.1:14550,rw"], None, "the first --out is the pilot's link"),
    (["udp:127.0.0.1:14550", "udp:127.0.0.1:14560,write"], None, "only ',rw' (writable) or ',ro'"),
    (["udp:127.0.0.1:14550", "udp:127.0.0.1:14550"], None, "are the same address"),
    (["udp:127.0.0.1:14550", "udp:127.0.0.1:14560"], "udp:127.0.0.1:14560", "are the same address"),
    (["udp:127.0.0.1:14550", "tcp:127.0.0.1:5760"], None, "would connect out as a TCP client"),
    (["udp:127.0.0.1:14550", "tcpin:127.0.0.1:5760,rw"], "tcpin:127.0.0.1:5761", "is a TCP server"),
])
def test_output_syntax_errors_are_one_line(outs, tap, needle):
    with pytest.raises(UsageError, match=re.escape(needle)):
        output_specs(outs, tap)


def test_output_marks():
    specs = output_specs(["udpin:127.0.0.1:14550", "udp:127.0.0.1:14560,rw", "udpout:127.0.0.1:14570,ro"],
                         "udp:127.0.0.1:14580", tap_writable=False)
    assert [(s.name, s.listens, s.writable) for s in specs] == [
        ("gcs", True, False), ("out2", False, True), ("out3", False, False), ("tap", False, False)]


def test_daa_sil_run_forwards_vehicle_outputs(tmp_path):
    """``daa-sil run --vehicle-out`` gives the vehicle another output: a ground station there gets the
    (undelayed) telemetry of the whole run while the SIL plays as usual."""
    path = tmp_path / "short.yaml"
    path.write_text(SCENARIO)
    station = Station()
    try:
        cp = subprocess.run([sys.executable, "-m", "daa_sil.cli", "run", str(path), "--out", str(tmp_path / "run"),
                             "--json", "--vehicle-out", station.addr], capture_output=True, text=True,
                            timeout=600, cwd=ROOT)
        assert cp.returncode == 0, cp.stderr[-3000:]
        station.poll()
    finally:
        station.sock.close()
    hb = station.of("HEARTBEAT")
    times = sorted({m.time_boot_ms for m in station.of("GLOBAL_POSITION_INT")})
    assert hb and hb[0].autopilot == M.MAV_AUTOPILOT_ARDUPILOTMEGA
    assert times == [k * 1000 for k in range(30)]  # every step of the run
    log = (tmp_path / "run" / "logs" / "vehicle.log").read_text()
    assert f"out2=udpout:{station.addr.split(':', 1)[1]}" in log  # the READY line lists it
    res = json.loads(cp.stdout)
    assert res["interrupted"] is False and res["failure"] is None


@pytest.mark.parametrize("kind", ["udpin", "tcpin"])
def test_a_taken_listening_port_is_one_line_before_any_work(tmp_path, kind):
    """``daa-sil run --vehicle-out udpin:`` (or ``tcpin:``) on a taken port: one line, exit 2, before any process
    or directory (on main the run started, built the vehicle's simulation, and then failed as a dead vehicle,
    exit 1); ``daa-vehicle --out`` the same: it binds before it prepares anything."""
    busy = socket.socket(socket.AF_INET, socket.SOCK_DGRAM if kind == "udpin" else socket.SOCK_STREAM)
    busy.bind(("127.0.0.1", 0))
    if kind == "tcpin":
        busy.listen(1)
    port = busy.getsockname()[1]
    try:
        cp = subprocess.run([sys.executable, "-m", "daa_sil.cli", "run", str(ROOT / "scenarios" / "head_on.yaml"),
                             "--out", str(tmp_path / "run"), "--vehicle-out", f"{kind}:127.0.0.1:{port}"],
                            capture_output=True, text=True, timeout=120, cwd=ROOT)
        assert cp.returncode == 2 and cp.stderr.count("\n") == 1, cp.stderr
        assert f"--vehicle-out {kind}:127.0.0.1:{port}: cannot listen there" in cp.stderr
        assert not (tmp_path / "run").exists()
        cp = subprocess.run([sys.executable, "-m", "vehicle", str(ROOT / "scenarios" / "head_on.yaml"), "--out",
                             f"{kind}:127.0.0.1:{port}"], capture_output=True, text=True, timeout=120, cwd=ROOT)
        assert cp.returncode == 2 and cp.stderr.count("\n") == 1 and "in use" in cp.stderr, cp.stderr
        assert "READY" not in cp.stdout and "boot" not in cp.stderr  # nothing prepared
    finally:
        busy.close()
