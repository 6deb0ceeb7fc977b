"""The shim's sans-IO core without sockets: bytes in, sends out, deterministic."""

from __future__ import annotations

from daa_sil.link.codec import CONTROL_LINK_ID, MavCodec, mavlink as d
from daa_sil.link.messages import sim_tick, sim_tick_ack
from daa_sil.models.latency import Constant
from daa_sil.sil.shim_config import ShimConfig
from daa_sil.sil.shim_core import MAX_HELD, Send, ShimCore

VEH, GCS = MavCodec(1, 1), MavCodec(255, 190)


def _core(**kw) -> ShimCore:
    base = dict(delay_down=Constant(2.0), delay_up=Constant(1.0), seed=5, clock="lockstep", gcs="udp:127.0.0.1:9")
    base.update(kw)
    return ShimCore(ShimConfig(**base))


def _tick(k: int, t: float) -> bytes:
    return VEH.encode(sim_tick(k, t), link_id=CONTROL_LINK_ID)


def _ack(k: int, t: float) -> bytes:
    return GCS.encode(sim_tick_ack(k, t), link_id=CONTROL_LINK_ID)


def _hb(codec: MavCodec) -> bytes:
    return codec.encode(d.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3))


def test_lockstep_walk_releases_at_ticks_and_forwards_control_at_once():
    core = _core()
    telem = _hb(VEH)
    assert core.receive("vehicle", telem) == []  # stamped 0 s, due at 2 s on the down line
    tick0 = _tick(0, 0.0)
    assert core.receive("vehicle", tick0) == [Send("gcs", tick0), Send("vehicle", tick0)]
    cmd = _hb(GCS)
    assert core.receive("gcs", cmd) == []  # the GCS's step 0: stamped 0 s, due at 1 s on the up line
    ack0 = _ack(0, 0.0)
    assert core.receive("gcs", ack0) == [Send("vehicle", ack0)]
    tick1 = _tick(1, 1.0)
    assert core.receive("vehicle", tick1) == [Send("vehicle", cmd), Send("gcs", tick1), Send("vehicle", tick1)]
    assert core.receive("gcs", _ack(1, 1.0))[0].dest == "vehicle"
    tick2 = _tick(2, 2.0)
    assert core.receive("vehicle", tick2) == [Send("gcs", telem), Send("gcs", tick2), Send("vehicle", tick2)]
    assert core.sim_time == 2.0 and core.last_tick == 2
    assert core.processed == [(2, 2.0, 1)]
    c = core.counters
    assert (c["ticks"], c["acks"], c["tick_echoes"], c["ticks_held"], c["bad_control"]) == (3, 2, 3, 0, 0)
    assert core.next_release() is None  # ticks drive the releases, never a timer


def test_a_tick_before_the_gcs_acked_the_last_one_is_held_until_that_ack():
    core = _core()
    tick0, tick1 = _tick(0, 0.0), _tick(1, 1.0)
    core.receive("vehicle", tick0)
    assert core.receive("vehicle", tick1) == [] and core.counters["ticks_held"] == 1
    assert core.sim_time == 0.0 and core.last_tick == 0
    ack0 = _ack(0, 0.0)
    assert core.receive("gcs", ack0) == [Send("vehicle", ack0), Send("gcs", tick1), Send("vehicle", tick1)]
    assert core.last_tick == 1 and core.sim_time == 1.0


def test_a_corrupt_tick_is_data_and_does_not_move_the_clock():
    core = _core()
    bad = bytearray(_tick(3, 3.0))
    bad[-3] ^= 0xFF  # breaks the CRC
    assert core.receive("vehicle", bytes(bad)) == []
    assert core.counters["bad_control"] == 1 and core.last_tick is None and core.sim_time == 0.0
    assert len(core.lines["down"]) == 1  # delayed like any other datagram


def test_only_a_good_packet_claims_a_side():
    core = _core(gcs=None)
    assert not core.claim("gcs", b"\x00garbage") and core.counters["rejected_claim"] == 1
    assert not core.known["gcs"]
    assert core.claim("gcs", _hb(GCS)) and core.known["gcs"]
    signed = _core(key=b"k" * 32)
    assert not signed.claim("vehicle", _hb(VEH))  # unsigned, while the link is signed


def test_a_gcs_that_never_got_a_tick_is_not_waited_for():
    core = _core(gcs=None)  # nobody has claimed the GCS side: the tick goes nowhere, nothing awaits its ack
    tick0 = _tick(0, 0.0)
    assert core.receive("vehicle", tick0) == [Send("gcs", tick0), Send("vehicle", tick0)]
    tick1 = _tick(1, 1.0)
    assert core.receive("vehicle", tick1)[-1] == Send("vehicle", tick1)
    assert core.counters["ticks_held"] == 0 and core.last_tick == 1


def test_free_running_holds_the_gcs_until_the_vehicle_decides_then_releases_on_time():
    core = _core(clock="realtime")
    g = _hb(GCS)
    assert core.receive("gcs", g, 0.5) == [] and core.counters["held_for_vehicle"] == 1
    assert core.tick_mode is None and core.next_release() is None
    v = _hb(VEH)  # not a tick: the free-running clock
    assert core.receive("vehicle", v, 0.7) == []
    assert core.tick_mode is False
    assert core.next_release() == 1.5  # the held GCS datagram: 0.5 s + 1 s up; the vehicle's: 0.7 + 2
    assert core.release(1.49) == []
    assert core.release(1.5) == [Send("vehicle", g)]
    assert core.next_release() == 2.7
    assert core.release(10.0) == [Send("gcs", v)] and core.next_release() is None


def test_the_held_queue_is_bounded():
    core = _core(clock="realtime")
    g = _hb(GCS)
    for _ in range(MAX_HELD + 3):
        core.receive("gcs", g, 0.0)
    assert core.counters["held_for_vehicle"] == MAX_HELD and core.counters["held_dropped"] == 3


def _faulty_run(greetings: int) -> list:
    """Lockstep with loss, duplication and reordering; ``greetings`` GCS datagrams before the first tick."""
    core = _core(loss=0.3, dup=0.3, reorder=0.3, delay_down=Constant(0.5), delay_up=Constant(0.5))
    veh, gcs = MavCodec(1, 1), MavCodec(255, 190)
    greeter = MavCodec(255, 190)  # its own sequence numbers: the step datagrams' bytes stay the same
    for _ in range(greetings):
        core.receive("gcs", _hb(greeter))
    out = []
    for k in range(40):
        t = float(k)
        out.append([s for s in core.receive("vehicle", veh.encode(sim_tick(k, t), link_id=CONTROL_LINK_ID))
                    if s.data[7] != d.MAVLINK_MSG_ID_HEARTBEAT])  # set start-up traffic aside
        out.append(core.receive("vehicle", veh.encode(d.MAVLink_system_time_message(k, k * 1000))))
        core.receive("gcs", gcs.encode(d.MAVLink_system_time_message(k, k * 1000)))
        core.receive("gcs", gcs.encode(sim_tick_ack(k, t), link_id=CONTROL_LINK_ID))
    return out


def test_faults_are_keyed_on_the_step_not_on_wall_clock_traffic():
    a, b, c = _faulty_run(0), _faulty_run(0), _faulty_run(7)
    assert a == b  # deterministic
    assert a == c  # greetings before the first tick move no fault of the simulation's datagrams
    released = [s for row in a for s in row if s.data[7] == d.MAVLINK_MSG_ID_SYSTEM_TIME]
    assert 0 < len(released) < 2 * 40 * 1.3  # some were lost, some duplicated: the faults ran


def test_realtime_ticks_stamp_a_late_gcs_with_the_tick_it_works_on():
    core = _core(clock="realtime")  # delays: 2 s down, 1 s up
    tick0 = _tick(0, 0.0)
    assert core.receive("vehicle", tick0, 0.0) == [Send("gcs", tick0), Send("vehicle", tick0)]
    assert core.tick_mode is True  # the vehicle's first datagram was a tick
    core.receive("gcs", _ack(0, 0.0))
    core.receive("vehicle", _tick(1, 1.0))
    assert core.counters["ticks_held"] == 0  # realtime: the vehicle's wall clock paces ticks, nothing is held
    core.receive("vehicle", _tick(2, 2.0))
    cmd = _hb(GCS)  # the GCS's step-1 command, read after tick 2: stamped t_1 = 1 s, due at 2 s
    assert core.receive("gcs", cmd) == []
    assert core.counters["gcs_lagged"] == 1 and core.counters["released_late"] == 1
    core.receive("gcs", _ack(2, 2.0))
    sends = core.receive("vehicle", _tick(3, 3.0))
    assert sends[0] == Send("vehicle", cmd)  # released at the next tick processed


def _up_keys(retry: bool) -> list:
    """Fault-draw keys of two GCS datagrams of step 0, with or without a retried tick 0 between them."""
    core = _core()
    keys = []
    push = core.lines["up"].push
    core.lines["up"].push = lambda t, data, key=None: keys.append(key) or push(t, data, key=key)
    tick0 = _tick(0, 0.0)
    core.receive("vehicle", tick0)
    core.receive("gcs", _hb(GCS))
    if retry:  # the vehicle re-sends tick 0 (its ack is late): forwarded and echoed again
        assert core.receive("vehicle", tick0) == [Send("gcs", tick0), Send("vehicle", tick0)]
    core.receive("gcs", _hb(GCS))
    core.receive("gcs", _ack(0, 0.0))
    return keys


def test_a_retried_tick_does_not_change_the_fault_keys_of_the_gcs_step():
    plain, retried = _up_keys(False), _up_keys(True)
    assert len(plain) == 2 and len(set(plain)) == 2  # two datagrams, two independent draws
    assert retried == plain  # before: the retry flushed the first alone, and both got the same key


def test_a_gcs_flooding_one_step_is_capped_and_counted():
    core = _core()
    core.receive("vehicle", _tick(0, 0.0))
    hb = _hb(GCS)
    for _ in range(MAX_HELD + 5):
        core.receive("gcs", hb)
    assert core.counters["batch_dropped"] == 5
    core.receive("gcs", _ack(0, 0.0))
    assert len(core.lines["up"]) == MAX_HELD


def test_tick_0_before_the_gcs_spoke_reaches_it_with_its_first_datagram():
    """The GCS usually finishes starting after the vehicle: tick 0 found no GCS (its forward is dropped
    as no_peer by the socket side), so the GCS's first datagram brings it tick 0 at once -- what the
    vehicle's next retry of tick 0 would do then. From there the walk is the usual one: the GCS's
    step-0 datagrams wait for its ack, tick 1 releases them at 1 s (up delay 1 s)."""
    core = _core(gcs=None)
    tick0, hello = _tick(0, 0.0), _hb(GCS)
    assert core.receive("vehicle", tick0) == [Send("gcs", tick0), Send("vehicle", tick0)]
    assert core.claim("gcs", hello)
    assert core.receive("gcs", hello) == [Send("gcs", tick0)]  # the vehicle had its echo already
    assert core.counters["start_tick_forwarded"] == 1 and core.last_tick == 0 and core.sim_time == 0.0
    assert core.counters["tick_echoes"] == 1
    cmd, ack0, tick1 = _hb(GCS), _ack(0, 0.0), _tick(1, 1.0)
    assert core.receive("gcs", cmd) == []  # held: the GCS now owes the ack of tick 0
    assert core.receive("vehicle", tick1) == [] and core.counters["ticks_held"] == 1
    assert core.receive("gcs", ack0) == [Send("vehicle", ack0), Send("vehicle", hello), Send("vehicle", cmd),
                                         Send("gcs", tick1), Send("vehicle", tick1)]
    assert core.receive("gcs", _hb(GCS)) == [] and core.counters["start_tick_forwarded"] == 1  # only once


def test_a_known_gcs_gets_tick_0_once():
    core = _core()  # the GCS address given: tick 0 reached it
    tick0 = _tick(0, 0.0)
    core.receive("vehicle", tick0)
    assert core.receive("gcs", _hb(GCS)) == [] and core.counters["start_tick_forwarded"] == 0


def test_a_late_gcs_with_signing_costs_the_vehicle_no_replayed_packet():
    """Signed link, GCS late: tick 0 reaches the GCS with its first datagram, and every datagram the shim sends
    the vehicle decodes there (the deferred tick 0 was echoed a second time, the same signed bytes, which the
    vehicle's codec dropped as a replay: one genuine packet lost and counted as an attack in a clean run)."""
    key = bytes(range(32))
    veh, gcs = MavCodec(1, 1, key=key), MavCodec(255, 190, key=key)
    vehicle_side = MavCodec(1, 1, key=key)  # the vehicle's receiving codec (its own echoes come back to it)
    core = _core(gcs=None, key=key)
    tick0 = veh.encode(sim_tick(0, 0.0), link_id=CONTROL_LINK_ID)
    sends = core.receive("vehicle", tick0)
    hello = gcs.encode(d.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3))
    assert core.claim("gcs", hello)
    sends += core.receive("gcs", hello)
    ack0 = gcs.encode(sim_tick_ack(0, 0.0), link_id=CONTROL_LINK_ID)
    sends += core.receive("gcs", ack0)
    sends += core.receive("vehicle", veh.encode(sim_tick(1, 1.0), link_id=CONTROL_LINK_ID))  # releases the hello
    to_vehicle = [s.data for s in sends if s.dest == "vehicle"]
    got = [m.get_type() for dg in to_vehicle for m in vehicle_side.decode(dg)]
    assert got == ["SIM_TICK", "SIM_TICK_ACK", "HEARTBEAT", "SIM_TICK"]
    st = vehicle_side.counters
    assert st.replayed == 0 and st.dropped == 0
    assert [s.dest for s in sends].count("gcs") == 3  # tick 0 (the forward that found no GCS, then the real one), tick 1
