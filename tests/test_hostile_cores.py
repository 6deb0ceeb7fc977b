"""The hostile-message property test on the protocol cores directly: bytes in, no sockets.

The same datagrams as ``tests/test_hostile_messages.py`` (one message of every type each process
handles, every numeric field drawn from NaN, +-inf, +-huge, 0, -0.0, negative and out-of-enum
values, then a canary) go straight into :class:`vehicle.protocol.VehicleProtocol` and
:class:`gcs.protocol.GcsProtocol` (``tests/core_helpers.py``), in lockstep and in realtime. With no
socket and no wall clock in the way every example is compared (the socket version compares
realtime runs only when they kept lockstep timing), so many more examples run in the same time:

* **from the tap** (the read-only observer): the canary PING is answered, nothing is accepted, and
  the step log is identical to the clean flight's;
* **from the pilot link**: the canary ``PARAM_SET DAA_WT 7.5`` is applied, each pilot command is
  taken iff the documented rules accept it, and the step log equals a flight that received only what
  the rules accept (the oracle: ``hostile_helpers.accepted_by_the_rules``);
* **to the GCS** (from the vehicle side): the canary PARAM_VALUE reaches the view and nothing
  unphysical enters what the pilot sees.

Everywhere no handler raises (the guard's count stays 0).
"""

from __future__ import annotations

import math

import pytest
from hypothesis import given

from core_helpers import PILOT, TAP, VEHICLE, decoded, fly, gcs_protocol, vehicle_protocol
from daa_sil.geometry.kinematics import state_in_bounds
from daa_sil.sil.scenario import parse_scenario
from hostile_helpers import (COMMANDS, GCS_CANARY, GCS_TYPES, INJECT_STEP, SCENARIO, TAP_CANARY, TAP_CANARY_US,
                             VEHICLE_CANARY, VEHICLE_TYPES, accepted_by_the_rules, datagram_strategy,
                             hostile_settings, is_pilot_command, pack, same_rows)

SC = parse_scenario(SCENARIO, "hostile.yaml")
_FLIGHTS: dict = {}


def flight(clock: str, packets: "tuple | None" = None, source=PILOT) -> dict:
    """A flight whose ``source`` sent ``packets`` (bytes, one datagram) after step INJECT_STEP's publish."""
    key = (clock, packets, source)
    if key in _FLIGHTS:
        return _FLIGHTS[key]
    proto = vehicle_protocol(SC, clock)
    replies = []

    def inject(p, k, wall):
        if packets is not None and k == INJECT_STEP:
            p.receive(0, b"".join(packets), source, wall)
            replies.extend(p.take_sends())  # realtime reads: answered on arrival

    sent = fly(proto, after_step=inject)
    res = {"rows": proto.plant.rows, "proto": proto, "sent": [s for step in sent for s in step] + replies}
    if packets is None or source == PILOT and len(_FLIGHTS) < 64:
        _FLIGHTS[key] = res
    return res


def no_handler_raised(proto) -> None:
    assert proto.guard.total == 0, f"a handler raised on {dict(proto.guard.by_type)}"


def check_from_tap(clock: str, msgs: tuple) -> None:
    packets = tuple(pack(t, f, 255, 190) for t, f in msgs) + (TAP_CANARY,)
    run = flight(clock, packets, TAP)
    no_handler_raised(run["proto"])
    pings = [m for m in decoded(run["sent"], TAP) if m.get_type() == "PING"]
    assert any(p.time_usec == TAP_CANARY_US for p in pings), "the canary behind the hostile messages was not answered"
    assert not [e for e in run["proto"].events if e.status == "accepted"]  # the tap is read-only
    diff = same_rows(run["rows"], flight(clock)["rows"])
    assert not diff, f"step log differs from the clean flight at {diff[:8]}"


def check_from_pilot_link(clock: str, msgs: tuple) -> None:
    packets = []
    for i, (t, f) in enumerate(msgs):
        packets.append((t, f, pack(t, f, 255, 191 + i)))  # one source per message: the gate orders per source
    run = flight(clock, tuple(p for _, _, p in packets) + (GCS_CANARY,))
    proto = run["proto"]
    no_handler_raised(proto)
    assert [e for e in proto.events if e.name == "DAA_WT" and e.new == 7.5 and e.status == "accepted"], \
        "the canary PARAM_SET behind the hostile messages was not applied"
    for i, (t, f) in enumerate(msgs):
        if is_pilot_command(t, f):
            took = proto.gate.last_accepted((255, 191 + i)) is not None
            assert took == accepted_by_the_rules(t, f), (t, f, took)
    accepted = tuple(p for t, f, p in packets if accepted_by_the_rules(t, f))
    taken = {e.name for e in proto.events if e.status in ("accepted", "unchanged") and e.kind == "param"}
    assert {f["param_id"].decode() for t, f, _ in packets if t == "PARAM_SET" and accepted_by_the_rules(t, f)} <= taken
    diff = same_rows(run["rows"], flight(clock, accepted + (GCS_CANARY,))["rows"])
    assert not diff, f"step log differs from the flight that got only what the rules accept, at {diff[:8]}"


def check_to_gcs(clock: str, msgs: tuple) -> None:
    core = gcs_protocol(SC, clock)
    tick = b""
    packets = []
    for t, f in msgs:
        p = pack(t, f, 1, 1)
        if t == "SIM_TICK":
            tick = p
        else:
            packets.append(p)
    core.receive(b"".join(packets) + VEHICLE_CANARY, VEHICLE, 1.0)
    if tick:
        core.receive(tick, VEHICLE, 1.1)  # alone: the GCS steps on it
    assert core.intake.guard.total == 0, dict(core.intake.guard.by_type)
    view = core.view
    assert view.params.get("CANARY") == 42.0, "the canary behind the hostile telemetry did not reach the view"
    own = view.own
    assert own is None or state_in_bounds(own[1], own[2], own[3], own[4] * math.sin(own[5]),
                                          own[4] * math.cos(own[5]), own[6])
    for x, y, z, gs, trk, vs in view.intruders.values():
        assert state_in_bounds(x, y, z, gs * math.sin(trk), gs * math.cos(trk), vs)
    assert view.alert[1] in range(4)


VEHICLE_DATAGRAM = datagram_strategy(VEHICLE_TYPES, COMMANDS)
GCS_DATAGRAM = datagram_strategy(GCS_TYPES + ("SIM_TICK",))


@pytest.mark.parametrize("clock", ["lockstep", "realtime"])
def test_the_canaries_alone(clock):
    """The oracle can fail: without the hostile messages the canaries are handled as the checks expect."""
    check_from_tap(clock, ())
    check_from_pilot_link(clock, ())


@hostile_settings(6)
@given(msgs=VEHICLE_DATAGRAM)
def test_hostile_messages_from_the_tap_on_the_core(msgs):
    check_from_tap("lockstep", msgs)
    check_from_tap("realtime", msgs)


@hostile_settings(6)
@given(msgs=VEHICLE_DATAGRAM)
def test_hostile_messages_from_the_pilot_link_on_the_core(msgs):
    check_from_pilot_link("lockstep", msgs)
    check_from_pilot_link("realtime", msgs)


@hostile_settings(20)
@given(msgs=GCS_DATAGRAM)
def test_hostile_messages_to_the_gcs_core(msgs):
    check_to_gcs("lockstep", msgs)
    check_to_gcs("realtime", msgs)


@pytest.mark.slow
@hostile_settings(60)
@given(msgs=VEHICLE_DATAGRAM)
def test_hostile_messages_on_the_vehicle_core_broad(msgs):
    for clock in ("lockstep", "realtime"):
        check_from_tap(clock, msgs)
        check_from_pilot_link(clock, msgs)
