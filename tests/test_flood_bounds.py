"""Bounded resources under floods: no flood from the network may take the vehicle, the shim or the run.

Each test sends a bounded flood (a fixed number of datagrams, a few seconds at most) over loopback only,
uses only public interfaces (so it runs against an older checkout as well, to show it failed there),
and cleans up every socket and process; the ones that start a process run it under its own memory
limit (``RLIMIT_AS``):

* a PARAM_REQUEST_LIST flood from the pilot link (4,679 requests in each 64 KB datagram) gets far
  fewer bytes back than it sent, and the pilot's commands sent between the flood's datagrams are
  all taken (they have their own queue);
* a realtime run with a spoofed read flood (sent from the shim's own socket, so the vehicle takes it
  for the pilot link) stays lockstep-equivalent and flies the lockstep run's step log;
* a settings flood is cut at the settings queue's byte budget: counted, warned once;
* the shim's delay lines and its start-up hold are bounded in bytes (a process under a memory limit,
  flooded with 60 KB datagrams, stays small and counts ``dropped_queue``);
* the per-address bookkeeping of dropped datagrams stays bounded whatever the number of spoofed
  addresses;
* a stalled shim (no datagram read, as under SIGSTOP) is named as the shim, not as the GCS.
"""

from __future__ import annotations

import asyncio
import json
import os
import re
import resource
import signal
import socket
import subprocess
import sys
import time
import tracemalloc

import pytest

from daa_sil.link.codec import MavCodec
from daa_sil.link.codec import mavlink as M
from daa_sil.sil.scenario import parse_scenario
from daa_sil.sil.shim_config import HELD_BYTES, LINE_BYTES
from hostile_helpers import SCENARIO, STEPS, play, same_rows

GCS = MavCodec(255, 190)
LIST_REQUEST = GCS.encode(M.MAVLink_param_request_list_message(1, 1))
#: the issue's flood datagram: as many PARAM_REQUEST_LIST as fit in one UDP datagram
LIST_FLOOD = LIST_REQUEST * (65507 // len(LIST_REQUEST))
SET_ONE = GCS.encode(M.MAVLink_param_set_message(1, 1, b"DAA_WT", 5.0, M.MAV_PARAM_TYPE_REAL32))
SET_FLOOD = SET_ONE * (65507 // len(SET_ONE))
CHILD_AS_BYTES = 3 * 1024**3  #: address-space limit of a process a test floods


def _station() -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    s.setblocking(False)
    return s


async def _vehicle_behind(station: socket.socket, steps: int = 40, speed: float = 10.0):
    """A realtime vehicle whose pilot link is ``station`` (free-running: the station answers no tick)."""
    from vehicle.node import VehicleNode, VehicleOptions

    sc = parse_scenario(SCENARIO.replace("duration_s: 30", f"duration_s: {steps}"), "flood.yaml")
    host, port = station.getsockname()
    veh = VehicleNode(sc, VehicleOptions(out=f"udp:{host}:{port}", clock="realtime", speed=speed))
    await veh.start()
    await veh.prepare()  # the simulation ready before the test talks to it
    return veh, asyncio.create_task(veh.run())


async def _stop(veh, task) -> None:
    veh.request_stop()
    task.cancel()
    try:
        await task
    except (asyncio.CancelledError, Exception):
        pass
    veh.close()


def test_a_parameter_list_flood_gets_less_back_than_it_sent_and_commands_still_fly():
    """Before: each request of the flood was answered with the whole list, 21x the bytes in, and the
    commands behind the flood were lost in the overflowing inbox."""
    station = _station()

    async def go():
        veh, task = await _vehicle_behind(station)
        try:
            await asyncio.sleep(0.5)  # a few steps first
            out0 = veh.codec.counters.bytes_out
            sent = 0
            for i in range(5):
                station.sendto(LIST_FLOOD, veh.ep.local_address)
                cmd = GCS.encode(M.MAVLink_pilot_maneuver_message(int(veh.t * 1000), i + 1, 1, 1, 10.0 * i, 0.0, 55.0))
                station.sendto(cmd, veh.ep.local_address)
                sent += len(LIST_FLOOD) + len(cmd)
                await asyncio.sleep(0.1)
            await asyncio.sleep(0.5)
            return veh.codec.counters.bytes_out - out0, sent, veh.gate.counters.accepted
        finally:
            await _stop(veh, task)

    try:
        out, sent, accepted = asyncio.run(go())
    finally:
        station.close()
    print(f"flood: {sent} B in, {out} B out (telemetry included): amplification {out / sent:.3f}")
    assert out < sent, f"{out} bytes out for {sent} bytes in"
    assert accepted == 5  # every command between the flood's datagrams was taken


def test_a_settings_flood_is_cut_at_its_queue_budget_counted_and_warned_once(capfd):
    station = _station()

    async def go():
        veh, task = await _vehicle_behind(station)
        try:
            await asyncio.sleep(0.3)
            for _ in range(3):
                station.sendto(SET_FLOOD, veh.ep.local_address)
                await asyncio.sleep(0.15)
            await asyncio.sleep(0.3)
            return veh.ep.stats(), len(veh.services.events)
        finally:
            await _stop(veh, task)

    try:
        stats, events = asyncio.run(go())
    finally:
        station.close()
    n = len(SET_FLOOD) // len(SET_ONE)
    err = capfd.readouterr().err
    warned = [x for x in err.splitlines() if "queue is full" in x]
    assert stats.get("dropped_queue", 0) > 0 and events < 3 * n
    assert len(warned) == 1 and "dropping settings from gcs" in warned[0], err[-2000:]


def test_a_realtime_run_under_a_spoofed_read_flood_stays_lockstep_equivalent():
    """Before: the vehicle answered every request of the flood; its steps ran late, the run lost lockstep
    timing and flew another encounter."""
    lockstep = asyncio.run(play("lockstep"))
    flood = {"sent": 0}

    def inject(veh, gcs, shim, tap):
        sock, dest = shim.sides["vehicle"].sock, veh.ep.local_address  # the address the vehicle calls its GCS

        async def flooding():
            for _ in range(40):  # 5 datagrams a wall second while the run lasts (30 steps at 5x: 6 s)
                try:
                    sock.sendto(LIST_FLOOD, dest)
                    flood["sent"] += 1
                except OSError:
                    return
                await asyncio.sleep(0.2)

        flood["task"] = asyncio.get_running_loop().create_task(flooding())

    run = asyncio.run(play("realtime", inject))
    veh = run["veh"]
    print(f"flood datagrams {flood['sent']}, steps unconfirmed {veh.stats.steps_unconfirmed}, "
          f"late max {veh.stats.late_max_ms} ms, released late {run['shim'].counters['released_late']}")
    assert flood["sent"] >= 10 and veh.stats.steps == STEPS
    assert veh.stats.steps_unconfirmed == 0 and run["shim"].counters["released_late"] == 0
    assert len(run["gcs"].sent) == len(lockstep["gcs"].sent)
    assert not same_rows(run["rows"], lockstep["rows"])


def _limited() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (CHILD_AS_BYTES, CHILD_AS_BYTES))
    os.setsid()


def _rss_kib(pid: int) -> int:
    with open(f"/proc/{pid}/status") as f:
        return int(re.search(r"VmRSS:\s+(\d+)", f.read()).group(1))


@pytest.mark.parametrize("clock", ["lockstep", "realtime"])
def test_the_shim_holds_a_flood_within_its_byte_budget(clock):
    """Lockstep: a GCS side flooded with 60 KB datagrams before any tick filled the up delay line
    (unbounded: 2.3 GB in 10.8 s); realtime: the start-up hold (10,000 datagrams, 617 MB). Now both are
    byte budgets: the shim stays small and counts what it drops."""
    proc = subprocess.Popen([sys.executable, "-m", "daa_sil.cli", "shim", "--clock", clock, "--delay", "const:1",
                             "--listen-vehicle", "udp:127.0.0.1:0", "--listen-gcs", "udp:127.0.0.1:0"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=_limited)
    gcs = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        line = proc.stderr.readline()
        m = re.search(r"gcs side udp:([\d.]+):(\d+)", line)
        assert m, line
        side = (m.group(1), int(m.group(2)))
        gcs.sendto(GCS.encode(M.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3)), side)  # claims the GCS side
        time.sleep(0.2)
        rss0 = _rss_kib(proc.pid)
        blob = GCS.encode(M.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3)) * (60_000 // 21)
        for i in range(2000):  # 120 MB, paced so that the shim reads most of it even on a loaded machine
            gcs.sendto(blob, side)
            if i % 4 == 3:
                time.sleep(0.004)
        time.sleep(0.5)
        grown_mib = (_rss_kib(proc.pid) - rss0) / 1024
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=30)
    finally:
        gcs.close()
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    stats = json.loads(out)
    dropped = stats["counters"].get("dropped_queue", 0)
    read_mib = stats["counters"]["datagrams_from_gcs"] * len(blob) / 2**20
    print(f"shim ({clock}) read {read_mib:.0f} MiB, grew {grown_mib:.0f} MiB under the flood; dropped_queue {dropped}")
    assert grown_mib < 30, f"the shim grew by {grown_mib:.0f} MiB"
    # the flood must exceed the budget to test it (the kernel drops what a starved shim does not read)
    assert read_mib > 2 * max(LINE_BYTES, HELD_BYTES) / 2**20, f"the shim read only {read_mib:.0f} MiB of the flood"
    assert dropped > 0 and err.count("queue") >= 1


def test_the_bookkeeping_of_dropped_senders_stays_bounded():
    """Before: about 190 B kept per spoofed source address (a million addresses: 280 -> 467 MB)."""
    from daa_sil.sil.endpoint import MavEndpoint

    ep = MavEndpoint(MavCodec(1, 1), peer=("127.0.0.1", 14550), learn_peer=False, allow_peers=[("127.0.0.1", 14550)],
                     warn=lambda text: None)
    junk = GCS.encode(M.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3))
    for i in range(2000):  # warm-up
        ep.datagram_received(junk, ("10.0.0.1", 1000 + i))
    tracemalloc.start()
    base = tracemalloc.get_traced_memory()[0]
    for i in range(60_000):
        ep.datagram_received(junk, (f"10.{i // 60000}.{(i // 250) % 250}.{i % 250}", 20000 + i % 7))
    grown = tracemalloc.get_traced_memory()[0] - base
    tracemalloc.stop()
    print(f"60,000 spoofed addresses: {grown / 1e6:.2f} MB kept")
    assert grown < 2e6, f"{grown / 1e6:.1f} MB kept for 60,000 dropped senders"
    assert ep.counters.datagrams_rejected_peer == 62_000
    assert "62000 datagrams" in ep.drops.summary()


def test_a_stalled_shim_is_named_as_the_shim():
    """A shim that reads nothing (SIGSTOP, Ctrl-Z) after step 5: before, the vehicle's last line blamed the
    GCS ("is daa-gcs still running?")."""
    from daa_sil.errors import DaaSilError
    from daa_sil.sil.endpoint import format_udp_address
    from daa_sil.sil.scenario import delay_models
    from daa_sil.sil.shim import DelayShim
    from daa_sil.sil.shim_config import ShimConfig
    from gcs.node import GcsNode, GcsOptions
    from vehicle.node import VehicleNode, VehicleOptions

    sc = parse_scenario(SCENARIO, "stall.yaml")

    async def go():
        up, down = delay_models(sc)
        shim = DelayShim(ShimConfig(delay_down=down, delay_up=up, listen_vehicle="udp:127.0.0.1:0",
                                    listen_gcs="udp:127.0.0.1:0", epoch_s=sc.link.epoch_s, seed=sc.seed,
                                    clock="lockstep"))
        await shim.start()
        gcs = GcsNode(sc, GcsOptions(vehicle=format_udp_address(shim.gcs_side), listen="udp:127.0.0.1:0",
                                     clock="lockstep", display=False))
        veh = VehicleNode(sc, VehicleOptions(out=format_udp_address(shim.vehicle_side), clock="lockstep",
                                             tick_timeout_s=3.0, tick_retry_s=0.5))
        await gcs.start()
        await veh.start()
        await veh.prepare()  # the simulation ready before the test talks to it
        loop = asyncio.get_running_loop()

        def stall(node, _out):
            if node.k == 5:
                for side in shim.sides.values():  # as SIGSTOP: datagrams wait in the kernel, nothing is read
                    loop.remove_reader(side.sock.fileno())

        gtask = asyncio.create_task(gcs.run())
        try:
            await asyncio.wait_for(veh.run(on_step=stall), 60)
        except DaaSilError as exc:
            return str(exc)
        finally:
            gcs.stop.set()
            await asyncio.wait_for(gtask, 10)
            veh.close()
            gcs.close()
            await shim.close()
        return "the run went on"

    text = asyncio.run(go())
    print(text)
    assert "shim" in text and "daa-gcs" not in text and "is the shim still running" in text, text
