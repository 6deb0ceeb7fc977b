"""The vehicle boots like an autopilot: it is on the link before its simulation is ready.

* the core with a :class:`vehicle.boot.BootPlant`: HEARTBEAT in MAV_STATE_BOOT, parameters answered and
  set (the simulation starts with what was set), pilot commands and traffic refused while booting;
* a real ``daa-vehicle`` on a **cold cache** (empty ``NUMBA_CACHE_DIR`` and ``DAA_SIL_CACHE``): a stock
  client (pymavlink) gets the BOOT heartbeat and the whole parameter list *before* the STATUSTEXT that
  says the kernels are ready -- the order is checked, not a time (slow: it compiles the kernels, 17-40 s
  on two cores; ``.ci/run`` runs it). On main the vehicle sent nothing until the kernels and maps were
  ready: the first heartbeat a client saw was ACTIVE;
* ``--wait-gcs``: the clock starts at the first message from a ground station: the first position it
  gets is stamped t = 0 (on main the option did not exist, and a GCS 5 s late missed 5 s).
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
from pathlib import Path

import pytest

from core_helpers import decoded
from daa_sil.link.codec import MavCodec
from daa_sil.link.codec import mavlink as M
from daa_sil.sil.outputs import output_specs
from daa_sil.sil.scenario import parse_scenario
from interop_helpers import ROOT, free_ports, recv_until, stop
from test_vehicle_protocol import SCENARIO
from vehicle.boot import BOOT_TEXT_EVERY, BootPlant
from vehicle.protocol import VehicleProtocol
from vehicle.tick_rules import TickOptions

SC = parse_scenario(SCENARIO, "boot.yaml")
GCS_ADDR = ("127.0.0.1", 50010)
SMALL_GRID = "paper,dx=6,dy=6,dh=3,vi=3,vh=3,theta=4"  # a map that builds in seconds
HANG_GUARD_S = 600.0
#: address space of the vehicle under test (it compiles the kernels: numba and LLVM want room)
VEHICLE_AS_BYTES = 8 * 1024**3


def booting(clock: str = "realtime") -> VehicleProtocol:
    return VehicleProtocol(BootPlant(SC), output_specs(["udpin:127.0.0.1:14550"]), ("127.0.0.1", 0), MavCodec(1, 1),
                           TickOptions(clock=clock))


def test_a_booting_core_beats_answers_and_carries_settings_over():
    p = booting()
    gcs = MavCodec(255, 190)
    p.receive(0, gcs.encode(M.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3)), GCS_ADDR, 0.0)
    p.receive(0, gcs.encode(M.MAVLink_param_request_list_message(1, 1)), GCS_ADDR, 0.1)
    values = [m for m in decoded(p.take_sends(), GCS_ADDR) if m.get_type() == "PARAM_VALUE"]
    assert [v.param_id for v in values][:2] == ["DAA_ENABLE", "DAA_WT"] and len(values) == 8
    p.receive(0, gcs.encode_many([
        M.MAVLink_param_set_message(1, 1, b"DAA_WT", 7.0, M.MAV_PARAM_TYPE_REAL32),
        M.MAVLink_command_long_message(1, 1, M.MAV_CMD_DO_REPOSITION, 0, -1, 0, 0, 0, 37.5, -122.0, 1000),
        M.MAVLink_adsb_vehicle_message(77, 375000000, -1220000000, 1, 1000000, 0, 5000, 0, b"T77", 14, 0, 223, 0)]),
        GCS_ADDR, 0.2)
    for beat in range(BOOT_TEXT_EVERY):
        p.publish_boot(1.0 + beat)
        if beat == 0:
            p.boot_progress("compiling the DAA kernels")
    got = decoded(p.take_sends(), GCS_ADDR)
    beats = [m for m in got if m.get_type() == "HEARTBEAT"]
    assert beats and {b.system_status for b in beats} == {M.MAV_STATE_BOOT} and beats[0].custom_mode == 15
    acks = [(a.command, a.result) for a in got if a.get_type() == "COMMAND_ACK"]
    assert acks == [(M.MAV_CMD_DO_REPOSITION, M.MAV_RESULT_TEMPORARILY_REJECTED)]
    texts = [t.text for t in got if t.get_type() == "STATUSTEXT"]
    assert "DAA_WT 4 -> 7" in texts and "traffic 77: the vehicle is booting" in texts
    assert texts.count("boot: compiling the DAA kernels") == 2  # said, and said again for latecomers
    assert [(e.kind, e.status) for e in p.events] == [("param", "accepted"), ("traffic", "temporarily_rejected")]
    from vehicle.core import VehicleCore

    core = VehicleCore(SC)
    p.set_plant(core)
    assert core.policy.wait_threshold_s == 7.0 and not p.booting  # the simulation starts with what was set


def test_a_booting_core_stays_off_the_pilot_link_when_a_shim_may_be_there():
    """Lockstep (and --tick-sync wait): the pilot's link may be a shim, which must see SIM_TICK first."""
    p = VehicleProtocol(BootPlant(SC), output_specs(["udp:127.0.0.1:14601"], "udp:127.0.0.1:14560"),
                        ("127.0.0.1", 0), MavCodec(1, 1), TickOptions(clock="lockstep"))
    p.publish_boot(0.0, to_pilot=False)
    sends = p.take_sends()
    assert [s.addr for s in sends] == [("127.0.0.1", 14560)]  # the tap only


def _limited() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (VEHICLE_AS_BYTES, VEHICLE_AS_BYTES))


def _vehicle(args: list, log: Path, env: "dict | None" = None) -> subprocess.Popen:
    fh = open(log, "w")
    return subprocess.Popen([sys.executable, "-m", "vehicle", *map(str, args)], stdout=fh, stderr=subprocess.STDOUT,
                            text=True, cwd=ROOT, start_new_session=True, env=env, preexec_fn=_limited)


@pytest.mark.slow
def test_cold_start_heartbeat_and_parameters_come_before_the_kernels_and_maps(tmp_path):
    from pymavlink import mavutil

    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba"), DAA_SIL_CACHE=str(tmp_path / "maps"))
    (port,) = free_ports(1)
    proc = _vehicle([ROOT / "scenarios" / "head_on.yaml", "--out", f"udpin:127.0.0.1:{port}", "--waitmap", SMALL_GRID,
                     "--quiet"], tmp_path / "vehicle.log", env)
    conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=255, source_component=190,
                                      dialect="common")
    events: list = []  # what the client got, in order
    try:
        asked = False
        while not any(e == ("HEARTBEAT", M.MAV_STATE_ACTIVE) for e in events):
            assert proc.poll() is None, (tmp_path / "vehicle.log").read_text()
            assert len(events) < 100_000, "no end to the boot"
            conn.mav.heartbeat_send(6, 8, 0, 0, 4)
            for m in recv_until(conn, lambda x: False, 0.5):
                t = m.get_type()
                if t == "HEARTBEAT":
                    events.append((t, m.system_status))
                    if not asked:
                        conn.mav.param_request_list_send(1, 1)
                        asked = True
                elif t == "PARAM_VALUE":
                    events.append((t, m.param_id))
                elif t == "STATUSTEXT":
                    events.append((t, m.text))
            if len(events) > 20_000:
                break
    finally:
        code = stop(proc)
        conn.close()
    log = (tmp_path / "vehicle.log").read_text()
    assert code == 130, log[-3000:]
    first_boot = events.index(("HEARTBEAT", M.MAV_STATE_BOOT))
    params = [i for i, e in enumerate(events) if e[0] == "PARAM_VALUE"]
    kernels_ready = next(i for i, e in enumerate(events) if e[0] == "STATUSTEXT" and "DAA kernels ready" in e[1])
    maps_ready = next(i for i, e in enumerate(events) if e[0] == "STATUSTEXT" and "wait maps ready" in e[1])
    active = events.index(("HEARTBEAT", M.MAV_STATE_ACTIVE))
    assert first_boot < params[0] and len(params) == 8, events[:40]
    assert params[-1] < kernels_ready < maps_ready < active, events
    # the caches were cold: this vehicle compiled and built them (and says so)
    assert "compiling the DAA kernels" in log and (tmp_path / "numba").is_dir() and (tmp_path / "maps").is_dir()
    assert log.index("boot: DAA kernels ready") < log.index("READY listen=")


def test_wait_gcs_starts_the_clock_at_the_first_ground_station(tmp_path):
    from pymavlink import mavutil

    (port,) = free_ports(1)
    conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=255, source_component=190,
                                      dialect="common")
    proc = _vehicle([ROOT / "scenarios" / "head_on.yaml", "--out", f"udp:127.0.0.1:{port}", "--wait-gcs", "--speed", "4",
                     "--quiet"], tmp_path / "vehicle.log")
    try:
        standby = recv_until(conn, lambda m: m.get_type() == "HEARTBEAT" and m.system_status == M.MAV_STATE_STANDBY,
                             HANG_GUARD_S)
        assert standby and standby[-1].system_status == M.MAV_STATE_STANDBY, (tmp_path / "vehicle.log").read_text()
        more = recv_until(conn, lambda m: False, 2.0)  # it keeps waiting while nobody speaks
        assert [m.system_status for m in more if m.get_type() == "HEARTBEAT"] and not [
            m for m in standby + more if m.get_type() == "GLOBAL_POSITION_INT"]
        conn.mav.heartbeat_send(6, 8, 0, 0, 4)
        pos = recv_until(conn, lambda m: m.get_type() == "GLOBAL_POSITION_INT", 30.0)
        assert pos and pos[-1].get_type() == "GLOBAL_POSITION_INT" and pos[-1].time_boot_ms == 0  # step 0, not later
    finally:
        code = stop(proc)
        conn.close()
    log = (tmp_path / "vehicle.log").read_text()
    assert code == 130 and "waiting for a ground station" in log and log.index("a ground station spoke") < log.index(
        "CLOCK t0_monotonic"), log
