"""An encounter played by the vehicle, the delay shim and the GCS in this process, on real loopback
sockets, with a tap socket; the hostile message strategies and the documented acceptance rules (the
oracle). Used by the hostile-message tests (``tests/test_hostile_messages.py`` through sockets,
``tests/test_hostile_cores.py`` on the protocol cores, ``tests/test_message_guard.py``)."""

from __future__ import annotations

import asyncio
import math
import socket
import struct

from hypothesis import HealthCheck, Phase, settings
from hypothesis import strategies as st

from daa_sil.link.codec import MavCodec, mavlink as M
from daa_sil.steplog import cells_equal
from daa_sil.sil.endpoint import format_udp_address
from daa_sil.sil.scenario import delay_models, parse_scenario
from daa_sil.sil.shim import DelayShim
from daa_sil.sil.shim_config import ShimConfig
from gcs.node import GcsNode, GcsOptions
from vehicle.node import VehicleNode, VehicleOptions

HANG_GUARD_S = 300.0  # only to fail instead of hanging
INJECT_STEP = 3
STEPS = 30  #: the scenario's duration_s
REALTIME_SPEED = 5.0
#: 30 s head-on, 2 s each way: no_wait, blend and wait decisions (the wait map), so W_T and DAA_ENABLE matter
SCENARIO = """\
name: head-on-hostile
description: short head-on for the hostile-message property test
seed: 11
duration_s: 30
ownship: {alt_m: 1000, gs_mps: 55, track_deg: 0}
intruders:
  - callsign: HEAD1
    initial: {x_m: 150, y_m: 6900, alt_m: 1000, gs_mps: 60, track_deg: 180}
link: {up: "const:2", down: "const:2"}
pilot: {mode: model, model: {response: deterministic}}
allocation: {group: ID-1}
"""


def msg_class(mtype: str):
    return M.mavlink_map[getattr(M, f"MAVLINK_MSG_ID_{mtype}")]


def pack(mtype: str, fields: dict, sysid: int, compid: int) -> bytes:
    """One packet from its own codec (header seq 0, so a reference run packs the same bytes)."""
    return MavCodec(sysid, compid).encode(msg_class(mtype)(**fields))


async def play(clock: str, inject=None) -> dict:
    """The scenario in ``clock`` with a tap; ``inject(veh, gcs, shim, tap)`` is called after step INJECT_STEP."""
    sc = parse_scenario(SCENARIO, "hostile.yaml")
    up, down = delay_models(sc)
    speed = REALTIME_SPEED if clock == "realtime" else 1.0
    shim = DelayShim(ShimConfig(delay_down=down, delay_up=up, listen_vehicle="udp:127.0.0.1:0",
                                listen_gcs="udp:127.0.0.1:0", epoch_s=sc.link.epoch_s, seed=sc.seed, clock=clock,
                                speed=speed))
    await shim.start()
    tap = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    tap.bind(("127.0.0.1", 0))
    tap.setblocking(False)
    gcs = GcsNode(sc, GcsOptions(vehicle=format_udp_address(shim.gcs_side), listen="udp:127.0.0.1:0", clock=clock,
                                 speed=speed, display=False))
    veh = VehicleNode(sc, VehicleOptions(out=format_udp_address(shim.vehicle_side), clock=clock, speed=speed,
                                         tick_sync="wait", tick_timeout_s=60.0, tap=format_udp_address(tap.getsockname())))
    received = []
    try:
        await gcs.start()
        await veh.start()
        await veh.prepare()  # the simulation ready before the test talks to it

        def on_step(node, _out):
            if inject is not None and node.k == INJECT_STEP:
                inject(veh, gcs, shim, tap)

        gtask = asyncio.create_task(gcs.run())
        await asyncio.wait_for(veh.run(on_step=on_step), HANG_GUARD_S)
        await asyncio.sleep(0.05)  # the last answers to the tap
        gcs.stop.set()
        await asyncio.wait_for(gtask, 30)
        while True:
            try:
                received.append(tap.recv(65535))
            except BlockingIOError:
                break
    finally:
        tap.close()
        veh.close()
        gcs.close()
        await shim.close()
    return {"rows": veh.core.rows, "veh": veh, "gcs": gcs, "shim": shim, "tap_rx": received}


GCS_CANARY = pack("PARAM_SET", {"target_system": 1, "target_component": 1, "param_id": b"DAA_WT",
                                "param_value": 7.5, "param_type": M.MAV_PARAM_TYPE_REAL32}, 255, 190)
TAP_CANARY_US = 424242
TAP_CANARY = pack("PING", {"time_usec": TAP_CANARY_US, "seq": 7, "target_system": 0, "target_component": 0}, 255, 190)
VEHICLE_CANARY = pack("PARAM_VALUE", {"param_id": b"CANARY", "param_value": 42.0, "param_type": 9,
                                      "param_count": 1, "param_index": 0}, 1, 1)


NAN, INF = math.nan, math.inf
FLOATS = (NAN, INF, -INF, 3.0e38, -3.0e38, 0.0, -0.0, -1.0, -1e6, 65535.0, 1e9)
INTS = {"uint8_t": (0, 1, 200, 255), "int8_t": (-128, -1, 0, 127), "uint16_t": (0, 1, 54321, 65535),
        "int16_t": (-32768, -1, 0, 32767), "uint32_t": (0, 1, 2**31, 2**32 - 1),
        "int32_t": (-2**31, -1, 0, 2**31 - 1), "uint64_t": (0, 1, 2**63, 2**64 - 1),
        "int64_t": (-2**63, -1, 0, 2**63 - 1)}
TEXT = {"param_id": (b"DAA_WT", b"DAA_ENABLE", b"DAA_PROJL_S", b"DAA_STALE_S", b"DAA_LINK_TO", b"DAA_WAIT_MODE",
                     b"DAA_PRESET", b"BOGUS", b""),
        "name": (b"DAA_ALERT", b"OTHER"), "text": (b"x", b"DAA-SIL t=1s authority"), "callsign": (b"HEAD1", b"")}
#: the COMMAND_LONG / COMMAND_INT commands the vehicle handles, and two it does not know
COMMANDS = (M.MAV_CMD_REQUEST_MESSAGE, M.MAV_CMD_GET_HOME_POSITION, M.MAV_CMD_SET_MESSAGE_INTERVAL,
            M.MAV_CMD_GET_MESSAGE_INTERVAL, M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, M.MAV_CMD_COMPONENT_ARM_DISARM,
            M.MAV_CMD_DO_SET_MODE, M.MAV_CMD_DO_REPOSITION, 0, 65535)
#: every message type the vehicle handles (docs/sil.md "Commands", vehicle/services.py), besides the commands
VEHICLE_TYPES = ("HEARTBEAT", "SYSTEM_TIME", "PARAM_REQUEST_LIST", "PARAM_REQUEST_READ", "PARAM_SET", "TIMESYNC", "PING",
                 "REQUEST_DATA_STREAM", "MISSION_REQUEST_LIST", "FILE_TRANSFER_PROTOCOL", "SET_MODE", "PILOT_MANEUVER",
                 "SET_POSITION_TARGET_GLOBAL_INT", "SIM_TICK", "SIM_TICK_ACK")
#: every message type the GCS takes in (gcs/view.py; SIM_TICK drives its steps)
GCS_TYPES = ("LOCAL_POSITION_NED", "GLOBAL_POSITION_INT", "ADSB_VEHICLE", "NAMED_VALUE_INT", "ALLOCATION_DECISION",
             "DAA_BANDS", "COMMAND_ACK", "HEARTBEAT", "PARAM_VALUE", "STATUSTEXT")


def _field_strategy(name: str, ctype: str, length: int):
    if ctype == "char":
        return st.sampled_from(TEXT.get(name, (b"x", b"")))
    one = st.sampled_from(FLOATS) if ctype in ("float", "double") else st.sampled_from(INTS[ctype])
    return st.lists(one, min_size=length, max_size=length) if length else one


def message_strategy(mtype: str, command: "int | None" = None):
    """``(mtype, {field: value})`` with every field drawn from the hostile pools (COMMAND_*: ``command`` fixed)."""
    cls = msg_class(mtype)
    lengths = dict(zip(cls.ordered_fieldnames, cls.array_lengths))
    fields = {n: _field_strategy(n, t, lengths[n]) for n, t in zip(cls.fieldnames, cls.fieldtypes)}
    if command is not None:
        fields["command"] = st.just(command)
    return st.fixed_dictionaries(fields).map(lambda f: (mtype, f))


def datagram_strategy(types, commands=()):
    """One message of each type (and one COMMAND_LONG and COMMAND_INT per command), fields drawn."""
    parts = [message_strategy(t) for t in types]
    parts += [message_strategy(kind, c) for c in commands for kind in ("COMMAND_LONG", "COMMAND_INT")]
    return st.tuples(*parts)


# -- the documented acceptance rules (the oracle for the GCS path) -------------------------------------
def f32(x: float) -> float:
    return struct.unpack("<f", struct.pack("<f", x))[0] if math.isfinite(x) else x


WRITABLE = {"DAA_ENABLE": (0.0, 1.0, True), "DAA_WT": (0.0, 120.0, False), "DAA_PROJL_S": (0.0, 120.0, False),
            "DAA_STALE_S": (1.0, 120.0, False), "DAA_LINK_TO": (1.0, 120.0, False)}  # docs/sil.md "Parameters"


def _gate_ok(t_sent: float, trk: float, vs: float, gs: float) -> bool:
    """The command gate (docs/sil.md "Commands"): send time not ahead of the vehicle (handled at
    >= INJECT_STEP s, 2 s allowed), not all NaN, no infinity, track [0, 360], gs (0, 400], |vs| <= 60."""
    vals = (trk, vs, gs)
    return (t_sent <= INJECT_STEP + 2.0 and not all(math.isnan(v) for v in vals) and not any(math.isinf(v) for v in vals)
            and (math.isnan(trk) or 0.0 <= trk <= 360.0) and (math.isnan(gs) or 0.0 < gs <= 400.0)
            and (math.isnan(vs) or abs(vs) <= 60.0))


PILOT_TYPES = ("PILOT_MANEUVER", "SET_POSITION_TARGET_GLOBAL_INT")
#: REQUEST_DATA_STREAM groups and the messages the vehicle streams (docs/sil.md "Telemetry and rates")
STREAM_GROUPS = (M.MAV_DATA_STREAM_ALL, M.MAV_DATA_STREAM_EXTENDED_STATUS, M.MAV_DATA_STREAM_POSITION,
                 M.MAV_DATA_STREAM_EXTRA1, M.MAV_DATA_STREAM_EXTRA2, M.MAV_DATA_STREAM_EXTRA3)
STREAMED = {M.MAVLINK_MSG_ID_HEARTBEAT, M.MAVLINK_MSG_ID_SYSTEM_TIME, M.MAVLINK_MSG_ID_SYS_STATUS,
            M.MAVLINK_MSG_ID_GPS_RAW_INT, M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, M.MAVLINK_MSG_ID_LOCAL_POSITION_NED,
            M.MAVLINK_MSG_ID_ATTITUDE, M.MAVLINK_MSG_ID_VFR_HUD, M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE,
            M.MAVLINK_MSG_ID_POSITION_TARGET_GLOBAL_INT, M.MAVLINK_MSG_ID_HOME_POSITION,
            M.MAVLINK_MSG_ID_ADSB_VEHICLE, M.MAVLINK_MSG_ID_NAMED_VALUE_INT, M.MAVLINK_MSG_ID_DAA_BANDS,
            M.MAVLINK_MSG_ID_ALLOCATION_DECISION}


def is_pilot_command(mtype: str, f: dict) -> bool:
    return mtype in PILOT_TYPES or (mtype in ("COMMAND_LONG", "COMMAND_INT") and f["command"] == M.MAV_CMD_DO_REPOSITION)


def accepted_by_the_rules(mtype: str, f: dict) -> bool:
    """True if the vehicle must act on this message from the GCS link in a way that can change the step
    log: a parameter it may set, a pilot command the gate takes, or a change of the GCS link's own
    telemetry rates (the pilot then sees less, or more)."""
    to_us = f.get("target_system") in (0, 1)
    both = to_us and f.get("target_component") in (0, 1)
    if mtype == "REQUEST_DATA_STREAM":
        return both and f["req_stream_id"] in STREAM_GROUPS
    if mtype == "COMMAND_LONG" and f["command"] == M.MAV_CMD_SET_MESSAGE_INTERVAL:
        mid, iv = f32(f["param1"]), f32(f["param2"])
        ok_iv = math.isfinite(iv) and (iv >= 0 or iv == -1) and iv <= 2**31 - 1
        if mid == M.MAVLINK_MSG_ID_HEARTBEAT:
            ok_iv = ok_iv and iv != -1 and iv <= 1e6 + 1
        return both and mid in STREAMED and ok_iv
    if mtype == "PARAM_SET":
        name = f["param_id"].decode()
        if not (to_us and f["target_component"] in (0, 1) and name in WRITABLE):
            return False
        lo, hi, integer = WRITABLE[name]
        v = f32(f["param_value"])
        return lo <= v <= hi and (not integer or v == round(v))
    if mtype == "PILOT_MANEUVER":
        return to_us and _gate_ok(f["time_boot_ms"] / 1000.0, f32(f["track_deg"]), f32(f["vs"]), f32(f["gs"]))
    if mtype == "SET_POSITION_TARGET_GLOBAL_INT":
        vn, ve, vd = f32(f["vx"]), f32(f["vy"]), f32(f["vz"])
        if not (to_us and f["type_mask"] & 0b111000 == 0 and all(map(math.isfinite, (vn, ve, vd)))):
            return False
        gs = math.hypot(vn, ve)
        trk = math.degrees(math.atan2(ve, vn)) % 360.0 if gs > 0.5 else NAN
        return _gate_ok(f["time_boot_ms"] / 1000.0, trk, -vd, gs if gs > 0.5 else NAN)
    if mtype in ("COMMAND_LONG", "COMMAND_INT") and f["command"] == M.MAV_CMD_DO_REPOSITION:
        lat, lon = (f["x"] / 1e7, f["y"] / 1e7) if mtype == "COMMAND_INT" else (f32(f["param5"]), f32(f["param6"]))
        gs = f32(f["param1"])
        gs = gs if math.isfinite(gs) and gs > 0 else NAN  # the point is >= 100 km from the aircraft: a bearing
        return to_us and -90 <= lat <= 90 and -180 <= lon <= 180 and _gate_ok(0.0, 0.0, NAN, gs)
    return False  # reads, modes, time stamps, heartbeats, ticks: nothing the agent flies by


def same_rows(a: list, b: list) -> "list":
    """(t, column) of every step-log cell that differs (empty = identical)."""
    if len(a) != len(b):
        return [("rows", len(a), len(b))]
    return [(ra["t"], k) for ra, rb in zip(a, b) for k in ra if not cells_equal(ra[k], rb[k])]


def hostile_settings(n: int):
    """Hypothesis settings of the hostile-message tests: ``n`` derandomised examples, no deadline."""
    return settings(max_examples=n, deadline=None, derandomize=True, database=None, phases=[Phase.generate],
                    suppress_health_check=list(HealthCheck))
