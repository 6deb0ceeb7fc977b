"""Lockstep pipelining (issue 21, item 5): the vehicle's and the GCS's step of one tick run in parallel.

The shim releases packets only when it processes a tick, so what one side sends during tick ``k``
reaches the other at tick ``k + 1`` at the earliest: the vehicle's step ``k`` never reads the
GCS's step ``k`` and vice versa. The shim holds a new tick until the GCS has
acknowledged the previous one (so the GCS's datagrams of that step are queued, stamped with its
tick, before the next releases), and the vehicle steps on the shim's echo instead of waiting for
the GCS's ack. The step logs of every scenario stay identical (tests/test_sil_run.py and the
references in the benchmark); these tests pin the protocol itself.
"""

from __future__ import annotations

import asyncio

import pytest

from daa_sil.link.codec import MavCodec
from daa_sil.link.codec import mavlink as d
from daa_sil.models.latency import Constant
from daa_sil.sil.endpoint import open_endpoint
from daa_sil.sil.shim import DelayShim
from daa_sil.sil.shim_config import ShimConfig

LOCAL = "udp:127.0.0.1:0"


async def _next(ep, types: tuple, timeout: float = 5.0):
    """The next message of one of ``types`` (others are skipped); fails after ``timeout`` s."""
    loop = asyncio.get_running_loop()
    end = loop.time() + timeout
    while True:
        r = await ep.recv(max(0.0, end - loop.time()))
        if r.msg.get_type() in types:
            return r.msg


async def _nothing(ep, types: tuple, wait: float = 0.3) -> None:
    """No message of ``types`` arrives within ``wait`` s (bounded)."""
    loop = asyncio.get_running_loop()
    end = loop.time() + wait
    while (left := end - loop.time()) > 0:
        try:
            r = await ep.recv(left)
        except asyncio.TimeoutError:
            return
        assert r.msg.get_type() not in types, f"unexpected {r.msg.get_type()} {getattr(r.msg, 'tick', '')}"


@pytest.mark.asyncio
async def test_shim_holds_a_tick_until_the_gcs_acked_the_previous_one():
    shim = DelayShim(ShimConfig(delay_down=Constant(0.5), delay_up=Constant(0.5), listen_vehicle=LOCAL,
                                listen_gcs=LOCAL, seed=3, clock="lockstep"))
    await shim.start()
    try:
        async with await open_endpoint(MavCodec(1, 1), peer=shim.vehicle_side) as veh, \
                await open_endpoint(MavCodec(255, 190), peer=shim.gcs_side) as gcs:
            gcs.send(d.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3))  # the GCS introduces itself
            for _ in range(2000):
                if shim.peers["gcs"] is not None:
                    break
                await asyncio.sleep(0.001)
            veh.send(d.MAVLink_sim_tick_message(0, 0))
            assert (await _next(veh, ("SIM_TICK",))).tick == 0  # echoed at once
            assert (await _next(gcs, ("SIM_TICK",))).tick == 0
            # the vehicle is done with step 0 before the GCS: its telemetry, then tick 1
            veh.send(d.MAVLink_global_position_int_message(0, 1, 1, 0, 0, 0, 0, 0, 0))
            veh.send(d.MAVLink_sim_tick_message(1, 1000))
            await _nothing(veh, ("SIM_TICK",))  # held: no echo ...
            await _nothing(gcs, ("SIM_TICK",))  # ... nor forwarded ...
            assert shim.core.sim_time == 0.0 and shim.counters["ticks_held"] == 1  # ... nor released anything
            # the vehicle's retry (tick 0 again, then tick 1): the repeated tick reaches the GCS again,
            # tick 1 stays held
            veh.send(d.MAVLink_sim_tick_message(0, 0))
            veh.send(d.MAVLink_sim_tick_message(1, 1000))
            assert (await _next(gcs, ("SIM_TICK",))).tick == 0
            assert (await _next(veh, ("SIM_TICK",))).tick == 0  # a repeated tick is echoed again
            await _nothing(gcs, ("SIM_TICK",))
            await _nothing(veh, ("SIM_TICK",))
            assert shim.core.sim_time == 0.0 and shim.counters["ticks_held"] == 2
            # the GCS's step 0: a command stamped t = 0 (due at 0.5 s), then its ack
            gcs.send(d.MAVLink_pilot_maneuver_message(0, 1, 1, 1, 90.0, 0.0, 55.0))
            gcs.send(d.MAVLink_sim_tick_ack_message(0, 0, 1))
            got = []
            while not got or got[-1].get_type() != "SIM_TICK":
                got.append(await _next(veh, ("SIM_TICK_ACK", "PILOT_MANEUVER", "SIM_TICK")))
            # the ack, then tick 1's releases (the command of step 0), then the echo of tick 1
            assert [m.get_type() for m in got] == ["SIM_TICK_ACK", "PILOT_MANEUVER", "SIM_TICK"]
            assert got[0].tick == 0 and got[-1].tick == 1
            assert (await _next(gcs, ("GLOBAL_POSITION_INT", "SIM_TICK"))).get_type() == "GLOBAL_POSITION_INT"
            assert shim.core.sim_time == 1.0
        st = shim.stats()
        assert st["counters"]["released_late"] == 0 and st["counters"]["gcs_lagged"] == 0
        assert st["up"]["released"] == 2 and st["down"]["released"] == 1  # up: the greeting and the command
    finally:
        await shim.close()


SCENARIO = """\
name: pipeline-test
duration_s: 6
ownship: {alt_m: 1000, gs_mps: 55, track_deg: 0}
intruders:
  - cpa: {angle_deg: 180, hmd_m: 300, t_cpa_s: 5, gs_mps: 55}
link: {up: "const:2", down: "const:2"}
pilot: {mode: scripted, commands: [{t_s: 1, until_s: 3, track_deg: 20}]}
allocation: {group: B-2}
"""


@pytest.mark.asyncio
async def test_vehicle_steps_on_the_shims_echo_and_waits_for_the_last_ack(tmp_path):
    """A shim stand-in that echoes every tick but lets the GCS's ack through only for tick 0 and the
    last tick: the vehicle flies every step in between without an ack, and finishes only on the last."""
    from daa_sil.sil.scenario import parse_scenario
    from vehicle.node import VehicleNode, VehicleOptions

    sc = parse_scenario(SCENARIO)
    n = sc.n_steps
    # the stand-in encodes as the vehicle (system 1): a real shim echoes the vehicle's own bytes
    async with await open_endpoint(MavCodec(1, 1), LOCAL) as shim:
        port = shim.local_address[1]
        node = VehicleNode(sc, VehicleOptions(out=f"udp:127.0.0.1:{port}", clock="lockstep", tick_timeout_s=5.0,
                                              tick_retry_s=5.0))
        await node.start()
        run = asyncio.create_task(node.run())
        ticks = []
        try:
            while len(ticks) < n:
                r = await shim.recv(10.0)
                if r.msg.get_type() != "SIM_TICK":
                    continue
                k = int(r.msg.tick)
                ticks.append(k)
                shim.send(d.MAVLink_sim_tick_message(k, r.msg.time_ms), addr=r.addr)  # the echo
                if k == 0:
                    shim.send(d.MAVLink_sim_tick_ack_message(0, 0, 1), addr=r.addr)
            await asyncio.sleep(0.3)
            assert not run.done() and node.stats.steps == n  # every step flown; waiting for the last ack
            shim.send(d.MAVLink_sim_tick_ack_message(n - 1, (n - 1) * 1000, 1), addr=node.ep.local_address)
            await asyncio.wait_for(run, 10.0)
        finally:
            run.cancel()
            node.close()
    assert ticks == list(range(n))  # each tick once: no retry, no timeout
    assert node.stats.sync_partner == "shim" and node.stats.tick_retries == 0


@pytest.mark.asyncio
async def test_vehicle_retry_of_a_held_tick_resends_the_previous_one():
    """A shim stand-in holds tick 2 (the GCS's ack of tick 1 is missing); the vehicle's retry sends
    tick 1 again before tick 2, and the run goes on once the stand-in answers."""
    from daa_sil.sil.scenario import parse_scenario
    from vehicle.node import VehicleNode, VehicleOptions

    sc = parse_scenario(SCENARIO)
    n = sc.n_steps
    async with await open_endpoint(MavCodec(1, 1), LOCAL) as shim:
        node = VehicleNode(sc, VehicleOptions(out=f"udp:127.0.0.1:{shim.local_address[1]}", clock="lockstep",
                                              tick_timeout_s=10.0, tick_retry_s=0.3))
        await node.start()
        run = asyncio.create_task(node.run())
        ticks, held = [], True
        try:
            while True:
                r = await shim.recv(10.0)
                if r.msg.get_type() != "SIM_TICK":
                    continue
                k = int(r.msg.tick)
                ticks.append(k)
                if k == 2 and held:
                    continue  # held: no echo
                if k == 1 and ticks.count(1) == 2:  # the retry: the GCS acks tick 1, tick 2 goes
                    held = False
                    shim.send(d.MAVLink_sim_tick_ack_message(1, 1000, 1), addr=r.addr)
                    shim.send(d.MAVLink_sim_tick_message(2, 2000), addr=r.addr)
                    continue
                shim.send(d.MAVLink_sim_tick_message(k, r.msg.time_ms), addr=r.addr)
                if k in (0, n - 1):
                    shim.send(d.MAVLink_sim_tick_ack_message(k, r.msg.time_ms, 1), addr=r.addr)
                if k == n - 1:
                    break
            await asyncio.wait_for(run, 10.0)
        finally:
            run.cancel()
            node.close()
    assert ticks[:5] == [0, 1, 2, 1, 2] and node.stats.steps == n and node.stats.tick_retries == 1
