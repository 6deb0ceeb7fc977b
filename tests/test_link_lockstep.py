"""Lockstep helpers: a full run through the shim, and tick re-sends without a shim."""

from __future__ import annotations

import asyncio
import hashlib

import pytest

from daa_sil.models.latency import Constant
from daa_sil.link.codec import MavCodec, mavlink as d
from daa_sil.sil.endpoint import open_endpoint
from daa_sil.sil.lockstep import LockstepGcs, LockstepTimeout, LockstepVehicle
from daa_sil.link.messages import pilot_command_from, pilot_maneuver
from daa_sil.sil.shim import DelayShim
from daa_sil.sil.shim_config import ShimConfig


@pytest.mark.asyncio
@pytest.mark.parametrize("signed", [False, True])
async def test_helpers_through_shim(signed):
    key = hashlib.sha256(b"k").digest() if signed else None
    shim = DelayShim(ShimConfig(delay_down=Constant(1.0), delay_up=Constant(2.0), listen_vehicle="udp:127.0.0.1:0",
                                listen_gcs="udp:127.0.0.1:0", clock="lockstep", key=key))
    await shim.start()
    arrivals: dict[int, list[float]] = {}
    try:
        async with await open_endpoint(MavCodec(1, 1, key=key), peer=shim.vehicle_side) as v_ep, \
                await open_endpoint(MavCodec(255, 190, key=key), peer=shim.gcs_side) as g_ep:
            g_ep.send(d.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3))
            for _ in range(2000):  # bounded: at most ~2 s
                if shim.peers["gcs"] is not None:
                    break
                await asyncio.sleep(0.001)
            veh, gcs = LockstepVehicle(v_ep, timeout=5), LockstepGcs(g_ep)

            async def gcs_loop():
                for _ in range(6):
                    k, t, _msgs = await gcs.next_tick(timeout=10)
                    g_ep.send(pilot_maneuver(t, k + 1, track_deg=10.0 * k))
                    gcs.ack(k, t, 1)

            task = asyncio.create_task(gcs_loop())
            for k in range(6):
                got = await veh.step(k, float(k))
                arrivals[k] = [pilot_command_from(r.msg).t_sent_s for r in got if r.msg.get_type() == "PILOT_MANEUVER"]
            await asyncio.wait_for(task, 10)
    finally:
        await shim.close()
    # a command sent at step s (delay 2 s) reaches the vehicle in the handshake of step s + 2
    assert arrivals == {0: [], 1: [], 2: [0.0], 3: [1.0], 4: [2.0], 5: [3.0]}


@pytest.mark.asyncio
async def test_tick_is_resent_and_reacked_without_rerunning_the_step():
    async with await open_endpoint(MavCodec(1, 1)) as v_ep, \
            await open_endpoint(MavCodec(255, 190), peer=v_ep.local_address) as g_ep:
        v_ep.peer = g_ep.local_address
        veh, gcs = LockstepVehicle(v_ep, timeout=0.2, retries=3), LockstepGcs(g_ep)
        steps_run = []

        async def gcs_loop():
            k, t, _ = await gcs.next_tick(timeout=5)
            await g_ep.recv(timeout=5)  # swallow the re-sent tick: we are "slow" (> timeout) ...
            steps_run.append(k)
            gcs.ack(k, t)  # ... the late ack still completes step 0
            k, t, _ = await gcs.next_tick(timeout=5)
            steps_run.append(k)
            gcs.ack(k, t)

        task = asyncio.create_task(gcs_loop())
        await veh.step(0, 0.0)
        await veh.step(1, 1.0)
        await asyncio.wait_for(task, 5)
        assert steps_run == [0, 1] and veh.resent >= 1
        with pytest.raises(LockstepTimeout, match="tick 2"):
            await LockstepVehicle(v_ep, timeout=0.05, retries=1).step(2, 2.0)


@pytest.mark.asyncio
async def test_gcs_reacks_a_repeated_tick():
    from daa_sil.link.messages import sim_tick

    async with await open_endpoint(MavCodec(1, 1)) as v_ep, \
            await open_endpoint(MavCodec(255, 190), peer=v_ep.local_address) as g_ep:
        v_ep.peer = g_ep.local_address
        gcs = LockstepGcs(g_ep)
        v_ep.send(sim_tick(0, 0.0))
        k, t, _ = await gcs.next_tick(timeout=5)
        gcs.ack(k, t)
        v_ep.send(sim_tick(0, 0.0))  # the vehicle did not see the ack in time and re-sent
        v_ep.send(sim_tick(1, 1.0))
        k, _, _ = await gcs.next_tick(timeout=5)
        assert k == 1 and gcs.reacked == 1
        acks = [(await v_ep.recv(timeout=5)).msg for _ in range(2)]
        assert [(a.get_type(), a.tick) for a in acks] == [("SIM_TICK_ACK", 0)] * 2
