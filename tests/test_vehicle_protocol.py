"""The vehicle's and the GCS's protocol cores with bytes alone: parameters, the command gate and its acks,
mode requests, stream rates and the tick protocol (``vehicle/protocol.py``, ``vehicle/tick_rules.py``,
``gcs/protocol.py``). No socket, no process, no wall clock: times are given."""

from __future__ import annotations

import math

import pytest

from core_helpers import PILOT, TAP, VEHICLE, decoded, gcs_protocol, vehicle_protocol
from daa_sil.link.codec import MavCodec
from daa_sil.link.codec import mavlink as M
from daa_sil.sil.scenario import parse_scenario
from vehicle.tick_rules import TickTimeout

SCENARIO = """\
name: core-test
seed: 3
duration_s: 20
ownship: {alt_m: 1000, gs_mps: 55, track_deg: 0}
intruders:
  - callsign: HEAD1
    initial: {x_m: 150, y_m: 6900, alt_m: 1000, gs_mps: 60, track_deg: 180}
link: {up: "const:1", down: "const:1"}
pilot:
  mode: scripted
  commands:
    - {t_s: 2, until_s: 4, track_deg: 30}
allocation: {group: ID-1}
"""
SC = parse_scenario(SCENARIO, "core.yaml")
GCS = MavCodec(255, 190)


@pytest.fixture()
def plant():
    from vehicle.core import VehicleCore

    return VehicleCore(SC)


def _step(p, k: int) -> None:
    p.begin_step(k)
    p.process()
    p.publish(p.t, p.plant.step(p.t), float(k))


def test_parameters_list_read_and_set_from_bytes(plant):
    p = vehicle_protocol(SC, plant=plant)
    _step(p, 0)
    p.take_sends()
    p.receive(0, GCS.encode_many([M.MAVLink_param_request_list_message(1, 1),
                                  M.MAVLink_param_request_read_message(1, 1, b"DAA_WT", -1),
                                  M.MAVLink_param_set_message(1, 1, b"DAA_WT", 6.0, M.MAV_PARAM_TYPE_REAL32)]),
              PILOT, 0.5)
    assert not p.take_sends()  # lockstep: handled at the step boundary, not on arrival
    p.begin_step(1)
    p.process()
    got = decoded(p.take_sends(), PILOT)
    values = [(m.param_id, m.param_value, m.param_index) for m in got if m.get_type() == "PARAM_VALUE"]
    # the step boundary applies settings first (the set's answer), then answers the reads in order
    assert values[0] == ("DAA_WT", 6.0, 1) and [v[2] for v in values[1:9]] == list(range(8))
    assert values[2] == ("DAA_WT", 6.0, 1) and values[9] == ("DAA_WT", 6.0, 1) and len(values) == 10
    assert plant.policy.wait_threshold_s == 6.0
    ev = p.events[-1]
    assert (ev.name, ev.status, ev.link, ev.t_applied) == ("DAA_WT", "accepted", "gcs", 1.0)
    assert [n.text for n in p.take_notices() if n.stream == "stdout"][0].startswith("t=    1s param DAA_WT accepted")


def test_the_tap_reads_but_may_not_write(plant):
    p = vehicle_protocol(SC, plant=plant)
    p.receive(0, GCS.encode(M.MAVLink_param_set_message(1, 1, b"DAA_WT", 9.0, M.MAV_PARAM_TYPE_REAL32)), TAP, 0.1)
    p.process()
    got = decoded(p.take_sends(), TAP)
    assert [m.param_value for m in got if m.get_type() == "PARAM_VALUE"] == [plant.policy.wait_threshold_s]
    assert p.events[-1].status == "denied_readonly"


def test_pilot_commands_through_the_gate_with_acks(plant):
    p = vehicle_protocol(SC, plant=plant)
    p.begin_step(5)
    cmd = M.MAVLink_pilot_maneuver_message(4000, 7, 1, 1, 90.0, 0.0, 55.0)
    p.receive(0, GCS.encode(cmd), PILOT, 5.1)
    p.receive(0, GCS.encode(cmd), PILOT, 5.2)  # the same command again (a duplicate)
    p.receive(0, GCS.encode(M.MAVLink_pilot_maneuver_message(9000, 8, 1, 1, 90.0, 0.0, 55.0)), PILOT, 5.3)  # future
    p.process()
    acks = [m for m in decoded(p.take_sends(), PILOT) if m.get_type() == "COMMAND_ACK"]
    assert [(a.command, a.result) for a in acks] == [(M.MAVLINK_MSG_ID_PILOT_MANEUVER, M.MAV_RESULT_ACCEPTED)]
    c = p.gate.counters
    assert (c.accepted, c.duplicate, c.future) == (1, 1, 1)
    # from the (writable or not) observer a command is never flown
    p.receive(0, GCS.encode(M.MAVLink_command_long_message(1, 1, M.MAV_CMD_DO_REPOSITION, 0, -1, 0, 0, 0, 50.0, 8.0,
                                                           0)), TAP, 5.4)
    p.process()
    acks = [m for m in decoded(p.take_sends(), TAP) if m.get_type() == "COMMAND_ACK"]
    assert [a.result for a in acks] == [M.MAV_RESULT_DENIED] and p.stats.commands_from_observers_ignored == 1


def test_mode_requests_and_rates(plant):
    p = vehicle_protocol(SC, plant=plant)
    _step(p, 0)
    p.take_sends()
    p.receive(0, GCS.encode_many([
        M.MAVLink_command_long_message(1, 1, M.MAV_CMD_DO_SET_MODE, 0, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 10, 0, 0,
                                       0, 0, 0),  # AUTO: not available
        M.MAVLink_command_long_message(1, 1, M.MAV_CMD_SET_MESSAGE_INTERVAL, 0, M.MAVLINK_MSG_ID_VFR_HUD, -1, 0, 0, 0,
                                       0, 0)]), TAP, 0.5)
    p.process()
    acks = {(a.command, a.result) for a in decoded(p.take_sends(), TAP) if a.get_type() == "COMMAND_ACK"}
    assert acks == {(M.MAV_CMD_DO_SET_MODE, M.MAV_RESULT_DENIED), (M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAV_RESULT_ACCEPTED)}
    _step(p, 1)
    sends = p.take_sends()
    assert not [m for m in decoded(sends, TAP) if m.get_type() == "VFR_HUD"]  # the tap's own stream only
    assert [m for m in decoded(sends, PILOT) if m.get_type() == "VFR_HUD"]


def test_tick_protocol_echo_ack_and_the_rules(plant):
    p = vehicle_protocol(SC, plant=plant)
    rules = p.ticks
    w = rules.wait(0, 0.0, now=100.0)
    p.send_tick(0, 0.0)
    (tick,) = p.take_sends()
    assert tick.addr == PILOT and not tick.counted and decoded([tick])[0].get_type() == "SIM_TICK"
    assert not w.ready() and w.next_timer() == pytest.approx(100.2)  # tick 0 is repeated soon: the GCS may start
    assert w.on_timer(100.2) == [(0, 0.0)] and p.stats.tick_retries == 1
    ack = MavCodec(255, 190).encode(M.MAVLink_sim_tick_ack_message(0, 0, 1))
    p.receive(0, ack, PILOT, 100.3)  # taken on arrival, not at the step boundary
    assert w.ready() and not p.pending() and rules.peer.partner == "gcs"
    # behind a shim: an echo of tick 1 lets step 1 run, and a silent partner gets a clear line
    p.send_tick(1, 1.0)
    echo = p.take_sends()[0].data
    w1 = rules.wait(1, 1.0, now=101.0)
    p.receive(0, echo, PILOT, 101.1)
    assert w1.ready() and rules.peer.partner == "shim"
    w2 = rules.wait(2, 2.0, now=102.0)
    with pytest.raises(TickTimeout, match=r"no echo for tick 2 .* within 10 s: .*"):
        w2.on_timer(112.0)


def test_gcs_core_steps_on_a_tick_and_acks():
    core = gcs_protocol(SC, "lockstep", mode="scripted")
    veh = MavCodec(1, 1)
    for k in range(5):
        core.receive(veh.encode(M.MAVLink_sim_tick_message(k, k * 1000)), VEHICLE, float(k))
        sends = core.take_sends()
        msgs = [m for s in sends for m in MavCodec(1, 1).decode(s.data)]
        assert msgs[-1].get_type() == "SIM_TICK_ACK" and msgs[-1].tick == k and not sends[-1].counted
        cmds = [m for m in msgs if m.get_type() == "PILOT_MANEUVER"]
        assert len(cmds) == (1 if k in (2, 3) else 0)
        assert all(c.time_boot_ms == k * 1000 and math.isnan(c.vs) for c in cmds)
    core.receive(veh.encode(M.MAVLink_sim_tick_message(3, 3000)), VEHICLE, 5.0)  # repeated: acked, no step
    msgs = [m for s in core.take_sends() for m in MavCodec(1, 1).decode(s.data)]
    assert [m.get_type() for m in msgs] == ["SIM_TICK_ACK"] and core.steps == 5
    assert [(c.t, c.seq, c.order.kind) for c in core.sent] == [(2.0, 1, "scripted"), (3.0, 2, "scripted")]
    assert core.sent[0].as_dict()["track_deg"] == 30.0 and "axis" not in core.sent[0].as_dict()


def test_reads_are_paced_per_step_and_one_parameter_list_per_peer(plant):
    """A datagram full of PARAM_REQUEST_LIST and PARAM_REQUEST_READ: one list answered, the other lists
    dropped (most before decoding), the reads answered within the reply budget a step, in order."""
    from vehicle.peers import REPLY_BYTES_PER_STEP, REQUEST_QUEUE_BYTES

    p = vehicle_protocol(SC, plant=plant)
    lst = GCS.encode(M.MAVLink_param_request_list_message(1, 1))
    read = GCS.encode(M.MAVLink_param_request_read_message(1, 1, b"DAA_WT", -1))
    p.receive(0, lst * 1000 + read * 400, PILOT, 0.1)
    peer = p.outputs[0].peer
    assert peer.counters.coalesced == 999 and p.codec.counters.shed == 999 - 7  # 8 decoded: one list, 7 dropped
    assert peer.request_bytes <= REQUEST_QUEUE_BYTES and peer.counters.dropped_queue == 0  # 400 reads fit
    budgets = []
    for k in range(8):
        p.begin_step(k)
        p.process()
        sends = p.take_sends()
        budgets.append(sum(len(s.data) for s in sends))
        got = decoded(sends, PILOT)
        if k == 0:  # the list first, in one datagram, then the reads
            assert [m.param_index for m in got[:8]] == list(range(8))
    assert all(b <= REPLY_BYTES_PER_STEP + 64 for b in budgets)  # one reply may overshoot: at most its size
    answered = peer.counters.answered
    assert answered == 401 and not peer.requests, (answered, budgets)  # every read answered, over several steps
    assert peer.counters.deferred_steps >= 3


def test_queues_have_byte_budgets_and_commands_their_own(plant):
    from vehicle.peers import SETTING_QUEUE_BYTES

    p = vehicle_protocol(SC, plant=plant)
    setting = GCS.encode(M.MAVLink_param_set_message(1, 1, b"DAA_WT", 5.0, M.MAV_PARAM_TYPE_REAL32))
    p.receive(0, setting * 1800, PILOT, 0.1)
    p.receive(0, GCS.encode(M.MAVLink_pilot_maneuver_message(0, 1, 1, 1, 90.0, 0.0, 55.0)), PILOT, 0.2)
    n = SETTING_QUEUE_BYTES // len(setting)
    assert p.stats.dropped_queue == 1800 - n and p.ports[0].intake.stats()["dropped_queue"] == 1800 - n
    warned = [x.text for x in p.take_notices() if "queue is full" in x.text]
    assert len(warned) == 1 and "settings from gcs" in warned[0]
    p.process()
    assert p.gate.counters.accepted == 1  # the command behind the flood
    assert sum(1 for e in p.events if e.name == "DAA_WT") == n
    assert "dropped" in p.queue_summary()
