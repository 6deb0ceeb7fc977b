"""The delay shim: a UDP relay between the vehicle and the GCS with one seeded DelayLine per direction.

::

    vehicle  --datagrams-->  [vehicle side socket]  --down line-->  [gcs side socket]  -->  GCS
    vehicle  <------------   [vehicle side socket]  <--up line----  [gcs side socket]  <--  GCS

*down* = vehicle -> GCS (telemetry the pilot sees), *up* = GCS -> vehicle (pilot commands).
The unit of delay is the datagram; forwarded bytes are never modified (signatures stay valid).
Peers are the configured ``vehicle`` / ``gcs`` addresses or learned from the first datagram on
each side that holds a good MAVLink packet (with ``key``: a validly signed one; checked without
changing any signing state) -- garbage and forged packets cannot claim a side (``rejected_claim``);
datagrams from other addresses are counted (``rejected_peer``) and dropped. A
datagram that is due while its destination is still unknown is counted as ``no_peer`` and dropped.

Seeds (:func:`shim_seeds`): the *delays* of a shim seeded ``seed`` are the encounter's fast-time
delay streams, ``DelayProcess(model, encounter_streams(seed)[STREAM_UP], epoch_s)`` for the up line
and ``[STREAM_DOWN]`` for the down line (:func:`daa_sil.models.streams.encounter_streams`), so a SIL run
of a scenario sees draw for draw the delays fast-time gives the same encounter. The *impairment*
draws (loss, duplication, reordering) come from ``child_seed(SeedSequence(seed), 0)`` (down) /
``1`` (up) (:func:`direction_seeds`), keyed on each datagram's simulation step when ticks drive the
clock (:mod:`daa_sil.sil.shim_ticks`), so wall-clock traffic (greetings) does not shift them;
fast-time has no impairments.

Parity with fast-time: a packet sent at sim time ``t`` on direction ``dir`` is released at
``fifo_release(t, d)`` with ``d = DelayProcess(model, encounter_streams(seed)[STREAM_<DIR>],
epoch_s).delay(t)`` -- what :func:`daa_sil.study.fasttime.simulate` computes with
``BatchedDelay(model, [streams[STREAM_<DIR>]], epoch_s, duration_s)``; in lockstep it is delivered
at the first tick ``t_k >= release`` (fast-time: the first step with ``release <= t_k``). This
needs ``epoch_s > 0``: with per-datagram draws the index counts every datagram (heartbeats too),
which fast-time does not model.

Clocks
------
``lockstep`` (``docs/architecture.md``, "The step order"): the shim's clock only moves on ticks.

1. A datagram from the vehicle containing a valid ``SIM_TICK(k, t_k)`` sets the clock to ``t_k``
   (never backwards), releases every packet due at or before ``t_k`` in both directions (each line
   in release order), then forwards the tick datagram to the GCS at once (not delayed) and echoes
   it back to the vehicle (``tick_echoes``): the echo tells the vehicle that the shim is alive and
   that every uplink packet due at ``t_k`` has been sent to it.
2. Other datagrams from the vehicle enter their line stamped with the current clock (the time of
   the last tick). Datagrams from the GCS are stamped with the time of the **oldest tick forwarded
   to the GCS that it has not acknowledged yet** (the tick it is working on; the last tick if it
   never acknowledges ticks, or after it ignored ``MAX_GCS_LAG_TICKS`` (:mod:`daa_sil.sil.shim_ticks`) of them:
   ``gcs_unresponsive``). In lockstep that is always the last tick; in realtime it keeps a GCS that
   answers late from stamping its step-k commands with a later step (``gcs_lagged`` counts them).
3. A datagram from the GCS containing a valid ``SIM_TICK_ACK(k)`` (cumulative: every tick <= k)
   is forwarded to the vehicle at once.
4. A new tick that arrives while the GCS has not acknowledged the last tick forwarded to it is
   held and processed (rule 1) as soon as that ack arrives (``ticks_held``). The vehicle runs its
   step on the echo, in parallel with the GCS's step of the same tick; the hold keeps the GCS's
   datagrams of that step ahead of the next tick's releases (:mod:`daa_sil.sil.shim_ticks`).

``realtime`` with a vehicle that sends ticks (what ``daa-vehicle`` does): **the same tick-driven
rules as lockstep**, only the ticks are paced by the vehicle's wall clock instead of by the GCS's
acks. So a realtime run releases every packet at the same step as the lockstep run of the same
scenario and seed: delays are quantised to the step exactly as lockstep does (a packet released at
sim ``r`` is delivered at the first tick ``t_k >= r``), never by racing a wall-clock release
against a step deadline. Packets that could not keep to that (stamped with an older tick but due at
a tick already processed: a GCS more than the link delay late) are counted as ``released_late``.
``release_lateness_ms`` is then measured against the tick schedule: how long after its ideal wall
instant (the earliest-arriving tick defines the schedule's origin) each packet was released.

The mode is decided by the first datagram from the vehicle side: a ``SIM_TICK`` selects ticks,
anything else the free-running timer mode below. Until then datagrams from the GCS are held
(``held_for_vehicle``, bounded) and then stamped as the mode says, so nothing is lost because the
GCS started first.

``realtime`` with a vehicle that sends no ticks (free-running): sim time = (loop monotonic time -
start) x ``speed``. A datagram enters its line at its *kernel arrival time* (``SO_TIMESTAMPNS``),
not when the loop got round to reading it; each line keeps a heap and one timer (a Linux
``timerfd``, nanosecond absolute expiry, no polling) armed for its earliest pending release
(:mod:`daa_sil.sil.rtclock`; ``timing="poll"`` or non-Linux: the ``call_at`` + poll fallback).
Sockets are read with ``recvmsg`` in bursts from a loop reader.

Send ticks and acks *alone* in their datagram (a mixed datagram is treated as control and its
other messages skip the delay; counted as ``mixed_control``). Control messages are recognised by
a header walk and then fully decoded (CRC and, with ``key``, signature checked), so a forged or
corrupt tick cannot move the clock (``bad_control``). With signing, send control messages on
their own signing stream (``MavCodec.encode(msg, link_id=CONTROL_LINK_ID)``) because they
overtake delayed data. In lockstep the GCS must be known before the first tick: give ``gcs`` or
let the GCS send any datagram (e.g. a HEARTBEAT) to the shim first.

Hostile input: each datagram's handling (control messages included) runs under a
:class:`daa_sil.sil.msgguard.MessageGuard`: one that raises is counted (``malformed_content``) and
reported, and the next datagram is handled; the shim never stops on content.

Never silent: datagrams from an address that is not the learned peer are dropped with a warning
(first one per address at once, then with counts at most every 10 s), datagrams due for a side
nobody has claimed yet likewise, and a side that has talked and then falls silent for
``SILENCE_WARN_S`` is reported (stderr, ``daa-sil shim: warning: ...``).
"""

from __future__ import annotations

import asyncio
import inspect
import sys
from collections import deque
from typing import Callable

import numpy as np

from daa_sil.errors import UsageError
from daa_sil.files import atomic_write_json, to_jsonable
from daa_sil.models.delay_process import as_seed_sequence
from daa_sil.link.codec import MavCodec
from daa_sil.link.delayline import DelayLine
from .endpoint import Address, DropReporter, format_udp_address, parse_udp_address
from .msgguard import MessageGuard
from .rtclock import (PreciseTimer, request_short_slice, set_timer_slack)
from .shim_config import TICK_ID, ShimConfig, control_ids, direction_seeds, shim_delay_processes
from daa_sil.sil.shim_socket import ShimSocket, bind_udp
from daa_sil.sil.shim_ticks import ShimTicks

#: realtime: datagrams from the GCS held until the vehicle side's first datagram decides the mode
MAX_HELD = 10_000
#: wall seconds of silence from a side that has talked before it is reported
SILENCE_WARN_S = 5.0


class DelayShim(ShimTicks):
    """The relay. ``await start()``, then ``vehicle_side`` / ``gcs_side`` addresses; ``await close()``."""

    def __init__(self, config: ShimConfig):
        config.validate()
        self.config = config
        root = as_seed_sequence(config.seed)  # resolved once: seed None = fresh entropy shared by both
        seeds = direction_seeds(root)
        procs = shim_delay_processes(config, root)
        common = dict(fifo=config.fifo, loss=config.loss, dup=config.dup,
                      reorder=config.reorder, outages=config.outages, max_log=config.max_log)
        self.lines = {"down": DelayLine(procs["down"], seed=seeds["down"], **common),
                      "up": DelayLine(procs["up"], seed=seeds["up"], **common)}
        self.peers: dict[str, "Address | None"] = {
            "vehicle": parse_udp_address(config.vehicle, "--vehicle") if config.vehicle else None,
            "gcs": parse_udp_address(config.gcs, "--gcs") if config.gcs else None}
        self.sides: dict[str, ShimSocket] = {}
        self.counters = {k: 0 for k in (
            "datagrams_from_vehicle", "datagrams_from_gcs", "forwarded_to_vehicle", "forwarded_to_gcs",
            "rejected_peer", "rejected_claim", "no_peer", "ticks", "acks", "bad_control", "mixed_control", "clock_backwards",
            "socket_errors", "send_would_block", "tick_echoes", "held_for_vehicle", "held_dropped", "gcs_lagged",
            "gcs_unresponsive", "released_late", "ticks_held")}
        self.codec = MavCodec(0, 0, key=config.key, sign_outgoing=False)  # verifies control messages only
        self.sim_time = 0.0  # lockstep clock (s)
        self.last_tick: "int | None" = None
        self._loop: "asyncio.AbstractEventLoop | None" = None
        self._t0 = 0.0
        self._timers: dict[str, "PreciseTimer | None"] = {"down": None, "up": None}
        self._scheduled: dict[str, "float | None"] = {"down": None, "up": None}  # sim s the timer is armed for
        self._lateness: list[float] = []  # realtime: wall s between scheduled and actual release
        self._tick_waiters: list[tuple[int, asyncio.Future]] = []
        self._timing_info: dict = {}
        self.closed = False
        #: releases driven by ticks (lockstep always; realtime once the vehicle's first datagram is a tick)
        self.tick_mode: "bool | None" = True if config.clock == "lockstep" else None
        self._held: list[tuple["float | None", bytes]] = []  # realtime, mode undecided: GCS datagrams
        self._unacked: "deque[tuple[int, float]]" = deque()  # ticks forwarded to the GCS, not yet acked
        #: lockstep: the vehicle's next tick, held until the GCS acknowledges its pending one (shim_ticks)
        self._held_tick: "tuple | None" = None
        self._gcs_acks = False  # the GCS acknowledges ticks (so its data can be stamped by them)
        #: fault-draw keys (shim_ticks): start-up datagrams per line, datagrams per (line, stamp ms), held GCS step
        self._start_count = {"down": 0, "up": 0}
        self._stamp_count: dict[str, dict[int, int]] = {"down": {}, "up": {}}
        self._gcs_batch: list[tuple[float, bytes]] = []
        self._tick_log: list[tuple[float, float, float, int]] = []  # realtime ticks: (t_k, rx, done, released)
        self._seen_ticks: set[int] = set()
        self.warn = _stderr_warn
        labels = {"vehicle": "vehicle", "gcs": "GCS"}
        self.drops = {side: DropReporter("daa-sil shim", lambda side=side: self._peer_text(side),
                                         hint=f"the shim keeps the first {labels[side]} it heard from",
                                         emit=lambda text: self.warn(text))
                      for side in ("vehicle", "gcs")}
        self._last_rx: dict[str, "float | None"] = {"vehicle": None, "gcs": None}
        self._silent: dict[str, "float | None"] = {"vehicle": None, "gcs": None}
        self._no_peer_warned: set[str] = set()
        #: every datagram's handling runs under it (:mod:`daa_sil.sil.shim_socket`)
        self.guard = MessageGuard("daa-sil shim", emit=lambda text: self.warn(text))
        self._watch: "asyncio.TimerHandle | None" = None

    def _peer_text(self, side: str) -> str:
        p = self.peers[side]
        return f"{format_udp_address(p) if p else '(none yet)'} ({'vehicle' if side == 'vehicle' else 'GCS'} side)"

    # -- lifecycle -----------------------------------------------------------------------------
    async def start(self) -> None:
        """Bind both sockets (and, realtime, set up the release timers)."""
        self._loop = asyncio.get_running_loop()
        self._t0 = self._loop.time()
        realtime = self.config.clock == "realtime"
        precise = realtime and self.config.timing == "precise"
        for name, spec, flag in (("vehicle", self.config.listen_vehicle, "--listen-vehicle"),
                                 ("gcs", self.config.listen_gcs, "--listen-gcs")):
            addr = parse_udp_address(spec, flag)
            try:
                sock = bind_udp(addr)
            except OSError as exc:
                await self.close()
                raise UsageError(f"{flag}: cannot bind {format_udp_address(addr)}: {exc.strerror or exc}") from None
            self.sides[name] = ShimSocket(self, name, sock, stamped=precise)
        if realtime:
            info = {"timing": self.config.timing, "rx_kernel_stamps": all(sd.stamped for sd in self.sides.values())}
            if precise:
                info["timer_slack_1us"] = set_timer_slack(1000)
                info["short_slice"] = request_short_slice(0.0001)
            for direction in ("down", "up"):
                self._timers[direction] = PreciseTimer(self._loop, lambda d=direction: self._fire(d),
                                                       spin_s=self.config.spin_s, use_timerfd=precise)
            info["timer"] = self._timers["down"].kind
            self._timing_info = info
        self._watch = self._loop.call_later(1.0, self._watch_silence)

    def _watch_silence(self) -> None:
        """Once a second: report a side that talked and has been silent for SILENCE_WARN_S (and its return)."""
        if self.closed:
            return
        now = self._loop.time()
        for side, what in (("vehicle", "the vehicle"), ("gcs", "the GCS")):
            last = self._last_rx[side]
            if last is None or self._silent[side] is not None:
                continue
            if now - last >= SILENCE_WARN_S:
                self._silent[side] = last
                self.warn(f"no datagram from {what} ({self._peer_text(side)}) for {now - last:.0f} s"
                          f"{f' (last tick {self.last_tick}, t = {self.sim_time:g} s)' if self.last_tick is not None else ''}"
                          f": has it stopped?")
        self._watch = self._loop.call_later(1.0, self._watch_silence)

    def timing_info(self) -> dict:
        """Realtime only: how releases are timed (timer kind, kernel arrival stamps, slack, short slice)."""
        return dict(self._timing_info)

    @property
    def vehicle_side(self) -> Address:
        """Address the vehicle sends to."""
        return self.sides["vehicle"].sockname

    @property
    def gcs_side(self) -> Address:
        """Address the GCS sends to."""
        return self.sides["gcs"].sockname

    async def close(self) -> None:
        """Cancel timers, close sockets; in-flight datagrams are dropped (reported in stats)."""
        self.closed = True
        if self._watch is not None:
            self._watch.cancel()
        for d, tm in self._timers.items():
            if tm is not None:
                tm.close()
            self._timers[d] = None
        for side in self.sides.values():
            side.close()
        await asyncio.sleep(0)

    # -- clock ---------------------------------------------------------------------------------
    def now(self) -> float:
        """Current sim time (s) of the shim's clock."""
        if self.config.clock == "lockstep" or self.tick_mode:
            return self.sim_time
        return (self._loop.time() - self._t0) * self.config.speed

    def _wall_of(self, sim_t: float) -> float:
        return self._t0 + sim_t / self.config.speed

    # -- datapath ------------------------------------------------------------------------------
    def _on_datagram(self, side: str, data: bytes, addr: Address, t_rx: "float | None" = None) -> None:
        """One datagram from ``side``; ``t_rx``: kernel arrival time (loop clock, s) if known."""
        if self.closed:
            return
        c = self.counters
        c["datagrams_from_" + side] += 1
        peer = self.peers[side]
        if peer is None:
            # garbage or (with a key) unsigned / forged packets cannot claim a side of the link
            if not self.codec.decode(data, commit=False):
                c["rejected_claim"] += 1
                return
            self.peers[side] = addr
        elif peer != addr:
            c["rejected_peer"] += 1
            self.drops[side].note(addr)
            return
        self._heard(side)
        if self.tick_mode is None:  # realtime: the vehicle side's first datagram decides the mode
            if side == "gcs":
                if len(self._held) < MAX_HELD:
                    self._held.append((t_rx, data))
                    c["held_for_vehicle"] += 1
                else:
                    c["held_dropped"] += 1
                return
            self._decide_mode(data)
        if self.tick_mode:
            self._tick_datapath(side, data, t_rx)
        else:
            self._timer_datapath(side, data, t_rx)

    def _heard(self, side: str) -> None:
        now = self._loop.time() if self._loop is not None else 0.0
        quiet_since = self._silent[side]
        if quiet_since is not None:
            self._silent[side] = None
            self.warn(f"{'the vehicle' if side == 'vehicle' else 'the GCS'} is back after {now - quiet_since:.0f} s "
                      f"of silence ({self._peer_text(side)})")
        self._last_rx[side] = now

    def _decide_mode(self, first_vehicle_datagram: bytes) -> None:
        """Realtime: tick-driven if the vehicle's first datagram is a valid SIM_TICK; then replay held GCS data."""
        tick = False
        if TICK_ID in control_ids(first_vehicle_datagram):
            tick = any(m.get_msgId() == TICK_ID for m in self.codec.decode(first_vehicle_datagram, commit=False))
        self.tick_mode = tick
        if self._timing_info:
            self._timing_info["release"] = "ticks" if tick else "timer"
        held, self._held = self._held, []
        for t_rx, data in held:
            (self._tick_datapath if tick else self._timer_datapath)("gcs", data, t_rx)

    def _timer_datapath(self, side: str, data: bytes, t_rx: "float | None") -> None:
        """Free-running realtime: stamp with the kernel arrival time, release by the line's timer."""
        direction = "down" if side == "vehicle" else "up"
        t_in = self.now() if t_rx is None else min(self.now(), (t_rx - self._t0) * self.config.speed)
        self.lines[direction].push(t_in, data)
        self._arm(direction)

    def _send(self, dest: str, data: bytes) -> bool:
        peer = self.peers[dest]
        side = self.sides.get("gcs" if dest == "gcs" else "vehicle")
        if peer is None or side is None or side.closed:
            self.counters["no_peer"] += 1
            if dest not in self._no_peer_warned and not self.closed:
                self._no_peer_warned.add(dest)
                self.warn(f"dropping datagrams due for the {'GCS' if dest == 'gcs' else 'vehicle'}: nothing has sent "
                          f"to the shim's {dest} side yet, so it does not know where to (the shim learns each side "
                          f"from its first datagram; counted as no_peer)")
            return False
        if side.sendto(data, peer):
            self.counters["forwarded_to_" + dest] += 1
            return True
        return False

    def _release(self, direction: str, t_now: float) -> int:
        dest = "gcs" if direction == "down" else "vehicle"
        items = self.lines[direction].pop_due(t_now)
        for data in items:
            self._send(dest, data)
        return len(items)

    # -- realtime scheduling ---------------------------------------------------------------------
    def _arm(self, direction: str) -> None:
        """Make sure the direction's timer fires at its earliest pending release."""
        nxt = self.lines[direction].next_release()
        timer = self._timers[direction]
        if nxt is None or timer is None:
            return
        cur = self._scheduled[direction]
        if cur is not None and cur <= nxt:
            return
        self._scheduled[direction] = nxt
        timer.arm(self._wall_of(nxt))

    def _fire(self, direction: str) -> None:
        scheduled = self._scheduled[direction]
        self._scheduled[direction] = None
        if self.closed or scheduled is None:
            return
        if len(self._lateness) < 1_000_000:
            self._lateness.append(self._loop.time() - self._wall_of(scheduled))
        self._release(direction, max(self.now(), scheduled))
        self._arm(direction)

    def stats(self) -> dict:
        """Counters, per-direction line stats (delays in sim s) and realtime release lateness (ms)."""
        out = {"clock": self.config.clock, "speed": self.config.speed, "sim_time_s": self.now() if self._loop else 0.0,
               "last_tick": self.last_tick, "seed": self.config.seed, "epoch_s": self.config.epoch_s,
               "peers": {k: (format_udp_address(v) if v else None) for k, v in self.peers.items()},
               "counters": {**self.counters, "malformed_content": self.guard.total},
               "control_codec": {k: v for k, v in self.codec.counters.as_dict().items() if v},
               "down": self.lines["down"].stats(), "up": self.lines["up"].stats()}
        if self._timing_info:
            out["realtime_timing"] = self.timing_info()
        if self.config.clock == "realtime":
            out["release"] = {None: "undecided", True: "ticks", False: "timer"}[self.tick_mode]
        lat = self._tick_lateness() if self.tick_mode and self.config.clock == "realtime" else (
            np.array(self._lateness) if self._lateness else None)
        if lat is not None and lat.size:
            lat = lat * 1000.0
            out["release_lateness_ms"] = {"n": int(lat.size), "p50": float(np.percentile(lat, 50)),
                                          "p99": float(np.percentile(lat, 99)), "max": float(lat.max()),
                                          "reference": "tick schedule" if self.tick_mode else "release time"}
        if self.config.clock == "realtime" and self.tick_mode:
            out["tick_schedule"] = self._tick_schedule_stats()
        for side in ("vehicle", "gcs"):
            if self.drops[side].total:
                out.setdefault("unexpected_peers", {})[side] = {
                    format_udp_address(a): n for a, n in self.drops[side].by_addr.most_common(10)}
        return to_jsonable(out)





def _stderr_warn(text: str) -> None:
    print(f"daa-sil shim: warning: {text}" if not text.startswith("daa-sil shim:") else text,
          file=sys.stderr, flush=True)


async def run_shim(config: ShimConfig, *, stop: "asyncio.Event | None" = None,
                   on_ready: "Callable[[DelayShim], object] | None" = None,
                   duration: "float | None" = None) -> dict:
    """Run the shim until ``stop`` is set (or ``duration`` wall seconds pass); return its stats.

    ``on_ready(shim)`` is called once both sockets are bound (addresses in ``shim.vehicle_side`` /
    ``shim.gcs_side``). Stats are written to ``config.stats_json`` (atomically) if set.
    """
    shim = DelayShim(config)
    await shim.start()
    try:
        if on_ready is not None:
            r = on_ready(shim)
            if inspect.isawaitable(r):
                await r
        stop = stop or asyncio.Event()
        try:
            await asyncio.wait_for(stop.wait(), duration)
        except asyncio.TimeoutError:
            pass
    finally:
        await shim.close()
    stats = shim.stats()
    if config.stats_json:
        atomic_write_json(config.stats_json, stats)
    return stats
