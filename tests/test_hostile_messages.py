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

import pytest
from hypothesis import given
from hypothesis import strategies as st

from daa_sil.geometry.kinematics import state_in_bounds
from daa_sil.link.codec import MavCodec
from hostile_helpers import (COMMANDS, GCS_CANARY, GCS_TYPES, STEPS, TAP_CANARY, TAP_CANARY_US, VEHICLE_CANARY,
                             VEHICLE_TYPES, accepted_by_the_rules, datagram_strategy, hostile_settings,
                             is_pilot_command, pack, play, same_rows)

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
    diff = same_rows(run["rows"], ref["rows"])
    assert not diff, f"step log differs from the clean run at {diff[:8]}"
    COMPARED[clock] += 1


VEHICLE_DATAGRAM = datagram_strategy(VEHICLE_TYPES, COMMANDS)
GCS_DATAGRAM = datagram_strategy(GCS_TYPES + ("SIM_TICK",))


@pytest.fixture(scope="module", autouse=True)
def _report():
    yield
    print(f"\nhostile-message runs compared with their reference: {COMPARED}")


@hostile_settings(4)
@given(msgs=VEHICLE_DATAGRAM)
def test_hostile_messages_from_the_tap_lockstep(msgs):
    check_from_tap("lockstep", msgs)


@hostile_settings(4)
@given(msgs=VEHICLE_DATAGRAM)
def test_hostile_messages_from_the_gcs_peer_lockstep(msgs):
    check_from_gcs("lockstep", msgs)


@hostile_settings(2)
@given(msgs=GCS_DATAGRAM)
def test_hostile_messages_from_the_vehicle_peer_lockstep(msgs):
    check_from_vehicle("lockstep", msgs)


@hostile_settings(1)
@given(msgs=VEHICLE_DATAGRAM)
def test_hostile_messages_from_the_tap_and_gcs_realtime(msgs):
    check_from_tap("realtime", msgs)
    check_from_gcs("realtime", msgs)


@pytest.mark.slow
@hostile_settings(40)
@given(msgs=VEHICLE_DATAGRAM, source=st.sampled_from(("tap", "gcs")))
def test_hostile_messages_lockstep_broad(msgs, source):
    (check_from_tap if source == "tap" else check_from_gcs)("lockstep", msgs)


@pytest.mark.slow
@hostile_settings(15)
@given(msgs=GCS_DATAGRAM)
def test_hostile_messages_from_the_vehicle_peer_broad(msgs):
    check_from_vehicle("lockstep", msgs)
    check_from_vehicle("realtime", msgs)


@pytest.mark.slow
@hostile_settings(8)
@given(msgs=VEHICLE_DATAGRAM, source=st.sampled_from(("tap", "gcs")))
def test_hostile_messages_realtime_broad(msgs, source):
    (check_from_tap if source == "tap" else check_from_gcs)("realtime", msgs)
