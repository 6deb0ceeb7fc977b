"""The delay shim end to end on loopback: lockstep (deterministic ticks) and realtime."""

from __future__ import annotations

import asyncio
import hashlib
import json
import math
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from daa_sil.errors import UsageError
from daa_sil.models.latency import Constant, TruncatedGaussian
from daa_sil.models.delay_process import DelayProcess
from daa_sil.link.codec import CONTROL_LINK_ID, MavCodec, mavlink as d
from daa_sil.models.streams import STREAM_DOWN, STREAM_UP, encounter_streams
from daa_sil.link.delayline import fifo_release
from daa_sil.sil.endpoint import open_endpoint
from daa_sil.sil.shim import DelayShim, run_shim
from daa_sil.sil.shim_config import ShimConfig, control_ids

LOCAL = "udp:127.0.0.1:0"


def _cfg(**kw) -> ShimConfig:
    base = dict(delay_down=Constant(2.0), delay_up=Constant(3.0), listen_vehicle=LOCAL, listen_gcs=LOCAL, seed=5)
    base.update(kw)
    return ShimConfig(**base)


async def _lockstep_run(shim: DelayShim, steps: int, key: "bytes | None" = None, stats: "dict | None" = None):
    """Play the architecture's step order; returns what each side had received at each step.

    GCS at tick k: records the telemetry steps it has seen, sends PILOT_MANEUVER stamped t_k, acks.
    Vehicle: sends SIM_TICK(k), collects commands until ACK(k), then publishes telemetry for t_k.
    """
    seen_by_gcs: dict[int, list[int]] = {}
    seen_by_veh: dict[int, list[int]] = {}
    ctl = CONTROL_LINK_ID if key else None
    async with await open_endpoint(MavCodec(1, 1, key=key), peer=shim.vehicle_side) as veh, \
            await open_endpoint(MavCodec(255, 190, key=key), peer=shim.gcs_side) as gcs:
        gcs.send(d.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3))  # announce the GCS to the shim
        for _ in range(2000):  # bounded: at most ~2 s
            if shim.peers["gcs"] is not None:
                break
            await asyncio.sleep(0.001)

        async def gcs_node():
            telem: list[int] = []
            while True:
                r = await gcs.recv(timeout=10)
                m = r.msg
                if m.get_type() == "GLOBAL_POSITION_INT":
                    telem.append(m.time_boot_ms // 1000)
                elif m.get_type() == "SIM_TICK":
                    k = m.tick
                    seen_by_gcs[k] = list(telem)
                    gcs.send(d.MAVLink_pilot_maneuver_message(m.time_ms, k + 1, 1, 1, float(k), 0.0, 55.0))
                    gcs.send(d.MAVLink_sim_tick_ack_message(k, m.time_ms, 1), link_id=ctl)
                    if k == steps - 1:
                        return

        task = asyncio.create_task(gcs_node())
        cmds: list[int] = []
        for k in range(steps):
            veh.send(d.MAVLink_sim_tick_message(k, k * 1000), link_id=ctl)
            while True:
                m = (await veh.recv(timeout=10)).msg
                if m.get_type() == "PILOT_MANEUVER":
                    cmds.append(m.time_boot_ms // 1000)
                elif m.get_type() == "SIM_TICK_ACK":
                    assert m.tick == k
                    break
            seen_by_veh[k] = list(cmds)
            veh.send(d.MAVLink_global_position_int_message(k * 1000, 1, 1, 0, 0, 0, 0, 0, 0))
        await asyncio.wait_for(task, 10)
        if stats is not None:
            stats["veh"], stats["gcs"] = veh.stats(), gcs.stats()
    return seen_by_gcs, seen_by_veh


def _expected_arrival_ticks(model, seed_ss, epoch_s, steps):
    """Tick at which a packet sent at step s (t = s) is released: first k with k >= FIFO release."""
    proc = DelayProcess(model, seed_ss, epoch_s=epoch_s)
    t = np.arange(steps, dtype=float)
    rel = fifo_release(t, np.array([proc.delay(x, i) for i, x in enumerate(t)]))
    return np.ceil(rel - 1e-9).astype(int)


@pytest.mark.asyncio
async def test_lockstep_constant_delays_deliver_on_exact_ticks():
    shim = DelayShim(_cfg(clock="lockstep"))
    await shim.start()
    try:
        seen_by_gcs, seen_by_veh = await asyncio.wait_for(_lockstep_run(shim, 12), 30)
    finally:
        await shim.close()
    for k in range(12):
        assert seen_by_gcs[k] == list(range(0, max(0, k - 1)))  # telemetry of step s arrives at tick s + 2
        assert seen_by_veh[k] == list(range(0, max(0, k - 2)))  # command of step s arrives at tick s + 3
    s = shim.stats()
    assert s["counters"]["ticks"] == 12 and s["counters"]["acks"] == 12 and s["counters"]["bad_control"] == 0


@pytest.mark.asyncio
async def test_lockstep_signed_link_no_replay_rejections():
    """Ticks overtake delayed data; on their own signing stream nothing is rejected as a replay."""
    key = hashlib.sha256(b"lockstep").digest()
    shim = DelayShim(_cfg(clock="lockstep", key=key))
    await shim.start()
    st: dict = {}
    try:
        seen_by_gcs, seen_by_veh = await asyncio.wait_for(_lockstep_run(shim, 8, key, st), 30)
    finally:
        await shim.close()
    assert seen_by_gcs[7] == list(range(6)) and seen_by_veh[7] == list(range(5))
    for side in ("veh", "gcs"):
        assert st[side]["dropped"] == 0 and st[side]["received"] > 8
    assert shim.core.codec.counters.messages_in == 16  # 8 ticks + 8 acks verified by the shim


@pytest.mark.asyncio
async def test_lockstep_gaussian_matches_sans_io_delay_line():
    """Parity: the shim's delivery ticks equal those computed from the same seeded delay process."""
    g = TruncatedGaussian(5, 3)
    steps = 40
    shim = DelayShim(_cfg(clock="lockstep", delay_down=g, delay_up=g, seed=11, epoch_s=10.0))
    await shim.start()
    try:
        seen_by_gcs, seen_by_veh = await asyncio.wait_for(_lockstep_run(shim, steps), 60)
    finally:
        await shim.close()
    streams = encounter_streams(11)  # the fast-time delay streams of encounter seed 11
    down = _expected_arrival_ticks(g, streams[STREAM_DOWN], 10.0, steps)
    up = _expected_arrival_ticks(g, streams[STREAM_UP], 10.0, steps)
    assert len(set(down - np.arange(steps))) >= 2  # the delays really vary (not a constant in disguise)
    for k in range(steps):
        assert seen_by_gcs[k] == [s for s in range(steps) if down[s] <= k]
        assert seen_by_veh[k] == [s for s in range(steps) if up[s] <= k]
    assert len(seen_by_gcs[steps - 1]) > 20  # something actually flowed


@pytest.mark.asyncio
async def test_lockstep_forged_tick_does_not_move_the_clock():
    shim = DelayShim(_cfg(clock="lockstep"))
    await shim.start()
    try:
        async with await open_endpoint(MavCodec(1, 1), peer=shim.vehicle_side) as veh:
            tick = bytearray(MavCodec(1, 1).encode(d.MAVLink_sim_tick_message(99, 99_000)))
            tick[-1] ^= 0xFF  # bad CRC
            veh.transport.sendto(bytes(tick), shim.vehicle_side)  # garbage cannot claim the vehicle side
            veh.send(d.MAVLink_heartbeat_message(1, 0, 0, 0, 4, 3))  # a good packet does
            veh.transport.sendto(bytes(tick), shim.vehicle_side)
            veh.send(d.MAVLink_sim_tick_message(1, 1000))
            await shim.wait_tick(1, timeout=5)
        assert shim.core.sim_time == 1.0 and shim.counters["bad_control"] == 1 and shim.counters["rejected_claim"] == 1
        assert len(shim.core.lines["down"]) == 2  # heartbeat + the corrupt datagram (just data: delayed, not dropped)
    finally:
        await shim.close()


@pytest.mark.asyncio
async def test_realtime_constant_delay_and_bytes_untouched():
    shim = DelayShim(_cfg(delay_down=Constant(0.2), delay_up=Constant(0.3)))
    await shim.start()
    try:
        async with await open_endpoint(MavCodec(1, 1), peer=shim.vehicle_side) as veh, \
                await open_endpoint(MavCodec(255, 190), peer=shim.gcs_side) as gcs:
            veh.send(d.MAVLink_heartbeat_message(1, 0, 0, 0, 4, 3))  # both introduce themselves
            gcs.send(d.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3))
            assert (await veh.recv(timeout=5)).msg.get_srcSystem() == 255  # up direction works
            assert (await gcs.recv(timeout=5)).msg.get_srcSystem() == 1
            sent = {}
            for i in range(20):
                sent[i] = time.monotonic()
                veh.send(d.MAVLink_sim_tick_ack_message(i, i, 0))  # any message; not lockstep here
                await asyncio.sleep(0.02)
            lat = []
            for _ in range(20):
                r = await gcs.recv(timeout=5)
                lat.append(r.t - sent[r.msg.tick])
        lat = np.array(lat)
        # generous bounds: machines are noisy; the benchmark measures the real accuracy
        assert lat.min() >= 0.2 - 0.005 and np.median(lat) < 0.2 + 0.1
        st = shim.stats()
        assert st["down"]["released"] == 21 and st["counters"]["forwarded_to_gcs"] == 21
        assert "release_lateness_ms" in st
    finally:
        await shim.close()


@pytest.mark.asyncio
async def test_realtime_forwards_bytes_unchanged_and_rejects_strangers():
    shim = DelayShim(_cfg(delay_down=Constant(0.2), delay_up=Constant(0.2), speed=2.0))
    await shim.start()
    try:
        loop = asyncio.get_running_loop()
        got: asyncio.Queue = asyncio.Queue()

        class Sink(asyncio.DatagramProtocol):
            def datagram_received(self, data, addr):
                got.put_nowait((loop.time(), data))

        g_tr, _ = await loop.create_datagram_endpoint(Sink, local_addr=("127.0.0.1", 0))
        v_tr, _ = await loop.create_datagram_endpoint(asyncio.DatagramProtocol, local_addr=("127.0.0.1", 0))
        s_tr, _ = await loop.create_datagram_endpoint(asyncio.DatagramProtocol, local_addr=("127.0.0.1", 0))
        try:
            hello = MavCodec(255, 190).encode(d.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3))
            g_tr.sendto(b"hello", shim.gcs_side)  # not MAVLink: cannot claim the GCS side
            g_tr.sendto(hello, shim.gcs_side)
            v_tr.sendto(MavCodec(1, 1).encode(d.MAVLink_heartbeat_message(1, 0, 0, 0, 4, 3)), shim.vehicle_side)
            await asyncio.wait_for(got.get(), 5)  # the vehicle's heartbeat
            assert shim.counters["rejected_claim"] == 1 and shim.peers["gcs"] == g_tr.get_extra_info("sockname")
            payload = bytes(range(256)) * 4  # once the vehicle is known, any bytes are relayed verbatim
            t0 = loop.time()
            v_tr.sendto(payload, shim.vehicle_side)
            await asyncio.sleep(0.01)
            s_tr.sendto(b"stranger", shim.vehicle_side)  # not the learned vehicle: dropped
            t1, data = await asyncio.wait_for(got.get(), 5)
            assert data == payload
            assert 0.1 - 0.005 <= t1 - t0 < 0.5  # 0.2 sim s at speed 2 = 0.1 wall s
            await asyncio.sleep(0.2)
            assert got.empty() and shim.counters["rejected_peer"] == 1
        finally:
            for tr in (g_tr, v_tr, s_tr):
                tr.close()
    finally:
        await shim.close()


@pytest.mark.asyncio
async def test_run_shim_writes_stats(tmp_path):
    stop = asyncio.Event()
    addrs = {}

    def ready(shim):
        addrs["v"] = shim.vehicle_side
        stop.set()

    stats = await asyncio.wait_for(run_shim(_cfg(stats_json=str(tmp_path / "s.json")), stop=stop, on_ready=ready), 10)
    assert addrs["v"][1] > 0
    on_disk = json.loads((tmp_path / "s.json").read_text())
    assert on_disk["seed"] == 5 and on_disk["counters"] == stats["counters"]


def test_control_ids_header_walk():
    c = MavCodec(1, 1)
    tick = c.encode(d.MAVLink_sim_tick_message(1, 1000))
    hbm = c.encode(d.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3))
    assert control_ids(tick) == {d.MAVLINK_MSG_ID_SIM_TICK}
    assert control_ids(hbm + tick) == {-1, d.MAVLINK_MSG_ID_SIM_TICK}
    assert control_ids(b"junk") == {-1} and control_ids(b"") == set()


def test_config_validation():
    with pytest.raises(UsageError, match="clock"):
        DelayShim(_cfg(clock="wall"))
    with pytest.raises(UsageError, match="--vehicle"):
        DelayShim(_cfg(vehicle="udp:127.0.0.1"))
    with pytest.raises(UsageError, match="speed"):
        DelayShim(_cfg(speed=math.inf))


def test_cli_runs_until_sigterm_and_reports(tmp_path):
    out = tmp_path / "stats.json"
    p = subprocess.Popen([sys.executable, "-m", "daa_sil.cli", "shim", "--delay", "gauss:5,3", "--seed", "3",
                          "--listen-vehicle", LOCAL, "--listen-gcs", LOCAL, "--stats-json", str(out)],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        ready = p.stderr.readline()
        assert "vehicle side udp:127.0.0.1:" in ready
        p.send_signal(signal.SIGTERM)
        stdout, stderr = p.communicate(timeout=30)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    assert p.returncode == 0, stderr
    assert json.loads(stdout)["seed"] == 3 and json.loads(out.read_text())["clock"] == "realtime"
    bad = subprocess.run([sys.executable, "-m", "daa_sil.cli", "shim", "--delay", "gauss:5"],
                         capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1 and "bad delay spec" in bad.stderr


def test_rt_priority_range_is_checked():
    from daa_sil.commands.shim import set_rt_priority

    with pytest.raises(UsageError, match="rt-priority"):
        set_rt_priority(100)
