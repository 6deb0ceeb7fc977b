"""Hostile *well-formed* messages (issue 20 §1): every message type each process handles, with every
numeric field drawn from NaN, +-inf, +-huge, 0, -0.0, negative and out-of-enum values (hypothesis),
sent through real loopback sockets while an encounter runs, in lockstep and in realtime.

One unsigned COMMAND_LONG (ARM_DISARM, param2 NaN) from the read-only tap used to kill the vehicle
in lockstep (``int(NaN)`` in vehicle/services.py) and, in realtime, to lose every later message of
its datagram. The vehicle, the shim and the GCS run in this process on one asyncio loop, on real
UDP sockets (as ``tests/test_fuzz.py``); each example sends one datagram holding one message of
every type (each COMMAND_LONG / COMMAND_INT command the vehicle knows, and unknown ones), followed
by a *canary* message that must still be handled:

* **from the tap** (an observer socket of the test, straight to the vehicle): the vehicle may
  answer reads but must refuse every write and command, so the step log must be **identical** to
  the clean run's; the canary is a PING that must be answered;
* **from the GCS peer** (the GCS node's own socket, so through the delay shim like the pilot's
  traffic; SIM_TICK_ACK alone in its datagram, as the protocol has it): values the GCS may set are
  applied, so the step log must equal a clean run that received only the messages the documented
  rules accept (docs/sil.md "Parameters" and "Commands": the parameter ranges, the command gate),
  sent the same way at the same step; the canary is ``PARAM_SET DAA_WT 7.5``, which must be applied;
* **from the vehicle peer** (the vehicle's socket, through the shim to the GCS; SIM_TICK alone):
  the run must complete, the canary (a PARAM_VALUE) must reach the GCS's view, and nothing
  unphysical may enter what the pilot sees.

Everywhere: the run completes and no handler raised (the guard's malformed count stays 0: every
conversion of a wire field is checked before use; the guard is the net for what a check misses,
``tests/test_message_guard.py``). Realtime compares step logs only when the run reports lockstep
timing (no step before its tick's echo, nothing released late: docs/sil.md "Realtime and
lockstep"); how many did is printed. Examples are bounded and derandomised: a fast subset by
default, more under ``-m slow``.
"""

from __future__ import annotations

import asyncio
import math
import struct

import pytest
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from daa_sil.geometry.kinematics import state_in_bounds
from daa_sil.link.codec import MavCodec, mavlink as M
from daa_sil.steplog import cells_equal
from hostile_helpers import (GCS_CANARY, INJECT_STEP, STEPS, TAP_CANARY, TAP_CANARY_US, VEHICLE_CANARY, msg_class, pack,
                             play)

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


_REFERENCES: dict = {}


def reference(clock: str, gcs_packets: "tuple | None" = None) -> dict:
    """The clean run (None), or one whose GCS sent only ``gcs_packets`` and the canary, at the same step."""
    key = (clock, gcs_packets)
    if key not in _REFERENCES:
        inject = None
        if gcs_packets is not None:
            def inject(veh, gcs, shim, tap):
                gcs.ep.transport.sendto(b"".join(gcs_packets) + GCS_CANARY, shim.gcs_side)
        _REFERENCES[key] = asyncio.run(play(clock, inject))
    return _REFERENCES[key]


def _same_rows(a: list, b: list) -> "list":
    """(t, column) of every step-log cell that differs (empty = identical)."""
    if len(a) != len(b):
        return [("rows", len(a), len(b))]
    return [(ra["t"], k) for ra, rb in zip(a, b) for k in ra if not cells_equal(ra[k], rb[k])]


def _lockstep_timing(run: dict) -> bool:
    """The run saw what lockstep sees: every step after its tick's echo, nothing released late."""
    return run["veh"].stats.steps_unconfirmed == 0 and run["shim"].counters["released_late"] == 0


def _no_handler_raised(run: dict) -> None:
    for who, guard in (("vehicle", run["veh"].guard), ("gcs", run["gcs"].ep.guard), ("shim", run["shim"].guard)):
        assert guard.total == 0, f"{who}: a handler raised on {dict(guard.by_type)}"


COMPARED = {"lockstep": 0, "realtime": 0, "realtime_timing_off": 0}


def check_from_tap(clock: str, msgs: tuple) -> None:
    packets = [pack(t, f, 255, 190) for t, f in msgs]
    run = asyncio.run(play(clock, lambda veh, gcs, shim, tap: tap.sendto(b"".join(packets) + TAP_CANARY,
                                                                         veh.ep.local_address)))
    assert run["veh"].stats.steps == STEPS  # the run completed
    _no_handler_raised(run)
    pings = [m for d in run["tap_rx"] for m in MavCodec(255, 190).decode(d) if m.get_type() == "PING"]
    assert any(p.time_usec == TAP_CANARY_US for p in pings), "the canary behind the hostile messages was not answered"
    assert not [e for e in run["veh"].services.events if e.status == "accepted"]  # the tap is read-only
    _compare(clock, run, reference(clock, None))


def check_from_gcs(clock: str, msgs: tuple) -> None:
    packets, ack = [], b""
    for i, (t, f) in enumerate(msgs):
        p = pack(t, f, 255, 191 + i)  # one source per message: the gate orders commands per source
        if t == "SIM_TICK_ACK":
            ack = p  # alone in its datagram, as the protocol has it
        else:
            packets.append((t, f, p))

    def inject(veh, gcs, shim, tap):
        if ack:
            gcs.ep.transport.sendto(ack, shim.gcs_side)
        gcs.ep.transport.sendto(b"".join(p for _, _, p in packets) + GCS_CANARY, shim.gcs_side)

    run = asyncio.run(play(clock, inject))
    assert run["veh"].stats.steps == STEPS
    _no_handler_raised(run)
    canary = [e for e in run["veh"].services.events if e.name == "DAA_WT" and e.new == 7.5 and e.status == "accepted"]
    assert canary, "the canary PARAM_SET behind the hostile messages was not applied"
    accepted = [(t, f, p) for t, f, p in packets if accepted_by_the_rules(t, f)]
    # what the rules accept is what the vehicle took: each pilot command (its own source) through the gate ...
    gate = run["veh"].gate
    for i, (t, f) in enumerate(msgs):
        if is_pilot_command(t, f):
            took = gate.last_accepted((255, 191 + i)) is not None
            assert took == accepted_by_the_rules(t, f), (t, f, took)
    # ... and the parameters
    taken = {e.name for e in run["veh"].services.events if e.status in ("accepted", "unchanged") and e.kind == "param"}
    assert {f["param_id"].decode() for t, f, _ in accepted if t == "PARAM_SET"} <= taken
    _compare(clock, run, reference(clock, tuple(p for _, _, p in accepted)))


def check_from_vehicle(clock: str, msgs: tuple) -> None:
    packets, tick = [], b""
    for t, f in msgs:
        p = pack(t, f, 1, 1)
        if t == "SIM_TICK":
            tick = p
        else:
            packets.append(p)

    def inject(veh, gcs, shim, tap):
        veh.ep.transport.sendto(b"".join(packets) + VEHICLE_CANARY, shim.vehicle_side)
        if tick:
            veh.ep.transport.sendto(tick, shim.vehicle_side)  # alone: the shim takes it as the clock

    run = asyncio.run(play(clock, inject))
    assert run["veh"].stats.steps == STEPS
    _no_handler_raised(run)
    view = run["gcs"].view
    assert view.params.get("CANARY") == 42.0, "the canary behind the hostile telemetry did not reach the GCS"
    # nothing unphysical in what the pilot sees (ENU m, m/s; compass track)
    own = view.own
    assert own is None or state_in_bounds(own[1], own[2], own[3], own[4] * math.sin(own[5]),
                                          own[4] * math.cos(own[5]), own[6])
    for x, y, z, gs, trk, vs in view.intruders.values():
        assert state_in_bounds(x, y, z, gs * math.sin(trk), gs * math.cos(trk), vs)
    assert view.alert[1] in range(4)


def _compare(clock: str, run: dict, ref: dict) -> None:
    if clock == "realtime" and not (_lockstep_timing(run) and _lockstep_timing(ref)):
        COMPARED["realtime_timing_off"] += 1
        return
    diff = _same_rows(run["rows"], ref["rows"])
    assert not diff, f"step log differs from the clean run at {diff[:8]}"
    COMPARED[clock] += 1


VEHICLE_DATAGRAM = datagram_strategy(VEHICLE_TYPES, COMMANDS)
GCS_DATAGRAM = datagram_strategy(GCS_TYPES + ("SIM_TICK",))


def _settings(n: int):
    return settings(max_examples=n, deadline=None, derandomize=True, database=None, phases=[Phase.generate],
                    suppress_health_check=list(HealthCheck))


@pytest.fixture(scope="module", autouse=True)
def _report():
    yield
    print(f"\nhostile-message runs compared with their reference: {COMPARED}")


@_settings(4)
@given(msgs=VEHICLE_DATAGRAM)
def test_hostile_messages_from_the_tap_lockstep(msgs):
    check_from_tap("lockstep", msgs)


@_settings(4)
@given(msgs=VEHICLE_DATAGRAM)
def test_hostile_messages_from_the_gcs_peer_lockstep(msgs):
    check_from_gcs("lockstep", msgs)


@_settings(2)
@given(msgs=GCS_DATAGRAM)
def test_hostile_messages_from_the_vehicle_peer_lockstep(msgs):
    check_from_vehicle("lockstep", msgs)


@_settings(1)
@given(msgs=VEHICLE_DATAGRAM)
def test_hostile_messages_from_the_tap_and_gcs_realtime(msgs):
    check_from_tap("realtime", msgs)
    check_from_gcs("realtime", msgs)


@pytest.mark.slow
@_settings(40)
@given(msgs=VEHICLE_DATAGRAM, source=st.sampled_from(("tap", "gcs")))
def test_hostile_messages_lockstep_broad(msgs, source):
    (check_from_tap if source == "tap" else check_from_gcs)("lockstep", msgs)


@pytest.mark.slow
@_settings(15)
@given(msgs=GCS_DATAGRAM)
def test_hostile_messages_from_the_vehicle_peer_broad(msgs):
    check_from_vehicle("lockstep", msgs)
    check_from_vehicle("realtime", msgs)


@pytest.mark.slow
@_settings(8)
@given(msgs=VEHICLE_DATAGRAM, source=st.sampled_from(("tap", "gcs")))
def test_hostile_messages_realtime_broad(msgs, source):
    (check_from_tap if source == "tap" else check_from_gcs)("realtime", msgs)
