"""The delay shim: a UDP relay between the vehicle and the GCS, around a sans-IO :class:`ShimCore`.

::

    vehicle  --datagrams-->  [vehicle side socket]  --down line-->  [gcs side socket]  -->  GCS
    vehicle  <------------   [vehicle side socket]  <--up line----  [gcs side socket]  <--  GCS

:class:`DelayShim` owns the two sockets (:mod:`daa_sil.sil.shim_socket`), the release timer of the
free-running clock and the silence watcher; everything else -- both delay lines, the tick clock,
stamping, fault keys and the protocol's counters -- is :class:`daa_sil.sil.shim_core.ShimCore`
(read its docstring for the rules). Per datagram: check the sender against the side's peer, hand
the bytes to ``core.receive(side, data, t)``, send what it returns.

Peers are the configured ``vehicle`` / ``gcs`` addresses or learned from the first datagram on
each side that holds a good MAVLink packet (with ``key``: a validly signed one; checked without
changing any signing state, :meth:`ShimCore.claim`) -- garbage and forged packets cannot claim a
side (``rejected_claim``); datagrams from other addresses are counted (``rejected_peer``) and
dropped. A datagram due while its destination is still unknown is counted as ``no_peer`` and
dropped. In lockstep the GCS must be known before the first tick: give ``gcs`` or let the GCS send
any datagram (e.g. a HEARTBEAT) to the shim first.

Seeds (:func:`daa_sil.sil.shim_config.shim_delay_processes`): the delays of a shim seeded ``seed``
are the encounter's fast-time delay streams (:func:`daa_sil.models.streams.encounter_streams`), so
a SIL run sees draw for draw the delays fast-time gives the same encounter: a packet sent at sim
time ``t`` is released at ``fifo_release(t, d)`` and, with ticks, delivered at the first tick
``t_k >= release`` (fast-time: the first step with ``release <= t_k``). This needs ``epoch_s > 0``
(per-datagram draws would count heartbeats too). The impairment draws come from
:func:`daa_sil.sil.shim_config.direction_seeds`; fast-time has no impairments.

``realtime`` with a vehicle that sends ticks (what ``daa-vehicle`` does) follows the same tick
rules as lockstep, the ticks paced by the vehicle's wall clock, so it releases every packet at the
same step as the lockstep run. ``release_lateness_ms`` is then measured against the tick schedule
(the earliest-arriving tick defines its origin). ``realtime`` with a vehicle that sends no ticks:
sim time = (loop time - start) x ``speed``; a datagram enters its line at its kernel arrival time
(``SO_TIMESTAMPNS``) and one timer (a Linux ``timerfd``, :mod:`daa_sil.sil.rtclock`; ``timing="poll"``
or non-Linux: ``call_at`` + poll) is armed for the core's :meth:`ShimCore.next_release`.

Hostile input: each datagram's handling runs under a :class:`daa_sil.sil.msgguard.MessageGuard`:
one that raises is counted (``malformed_content``) and reported, and the next datagram is handled.

Never silent: datagrams past a queue's byte budget (a flood) are dropped with one warning and
counted (``dropped_queue``, in the stats); datagrams from an address that is not the learned peer are
dropped with a warning
(first one per address at once, then with counts at most every 10 s), datagrams due for a side
nobody has claimed yet likewise, and a side that has talked and then falls silent for
``SILENT_AFTER_S["shim"]`` (:mod:`daa_sil.sil.silence`) is reported (stderr, ``daa-sil shim: warning: ...``).
"""

from __future__ import annotations

import asyncio
import inspect
import sys
from typing import Callable

import numpy as np

from daa_sil.errors import UsageError
from daa_sil.files import atomic_write_json, to_jsonable
from .endpoint import Address, DropReporter, format_udp_address, parse_udp_address
from .msgguard import MessageGuard
from .rtclock import PreciseTimer, request_short_slice, set_timer_slack
from .shim_config import ShimConfig
from .shim_core import Send, ShimCore
from .shim_socket import ShimSocket, bind_udp
from .silence import SILENT_AFTER_S, Silence

#: the socket side's counters (the protocol's are :data:`daa_sil.sil.shim_core.COUNTERS`)
IO_COUNTERS = ("datagrams_from_vehicle", "datagrams_from_gcs", "forwarded_to_vehicle", "forwarded_to_gcs",
               "rejected_peer", "no_peer")
SIDES = ("vehicle", "gcs")
LABELS = {"vehicle": "vehicle", "gcs": "GCS"}


class DelayShim:
    """The relay. ``await start()``, then ``vehicle_side`` / ``gcs_side`` addresses; ``await close()``."""

    def __init__(self, config: ShimConfig):
        self.core = ShimCore(config)  # validates the configuration
        self.config = config
        self.peers: dict[str, "Address | None"] = {
            "vehicle": parse_udp_address(config.vehicle, "--vehicle") if config.vehicle else None,
            "gcs": parse_udp_address(config.gcs, "--gcs") if config.gcs else None}
        self.sides: dict[str, ShimSocket] = {}
        self.io_counters = {k: 0 for k in IO_COUNTERS}
        self._loop: "asyncio.AbstractEventLoop | None" = None
        self._t0 = 0.0
        self._timer: "PreciseTimer | None" = None  # free-running clock: armed for the core's next release
        self._scheduled: "float | None" = None  # sim s the timer is armed for
        self._lateness: list[float] = []  # free-running: wall s between scheduled and actual release
        self._tick_waiters: list[tuple[int, asyncio.Future]] = []
        self._timing_info: dict = {}
        self.closed = False
        self._tick_log: list[tuple[float, float, float, int]] = []  # realtime ticks: (t_k, rx, done, released)
        self._seen_ticks: set[int] = set()
        self.warn = _stderr_warn
        self.drops = {side: DropReporter("daa-sil shim", lambda side=side: self._peer_text(side),
                                         hint=f"the shim keeps the first {LABELS[side]} it heard from",
                                         emit=lambda text: self.warn(text))
                      for side in SIDES}
        self.silence = {side: Silence(SILENT_AFTER_S["shim"]) for side in SIDES}
        self._no_peer_warned: set[str] = set()
        self._queue_warned = False
        #: every datagram's handling runs under it
        self.guard = MessageGuard("daa-sil shim", emit=lambda text: self.warn(text))
        self._watch: "asyncio.TimerHandle | None" = None

    @property
    def counters(self) -> dict:
        """Every counter: the socket side's, the sockets' errors and the core's (a fresh dict)."""
        io = dict(self.io_counters)
        io["socket_errors"] = sum(s.socket_errors for s in self.sides.values())
        io["send_would_block"] = sum(s.send_would_block for s in self.sides.values())
        return {**io, **self.core.counters}

    def _peer_text(self, side: str) -> str:
        p = self.peers[side]
        return f"{format_udp_address(p) if p else '(none yet)'} ({LABELS[side]} side)"

    # -- lifecycle -----------------------------------------------------------------------------
    async def start(self) -> None:
        """Bind both sockets (and, realtime, set up the release timer)."""
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
            # under the guard: a datagram whose handling raises is counted as malformed, the burst goes on
            on_datagram = (lambda data, src, t_rx, name=name: self.guard.call(
                self._on_datagram, name, data, src, t_rx, what=f"datagram from the {name} side", source=src))
            self.sides[name] = ShimSocket(self._loop, sock, precise, on_datagram)
        if realtime:
            info = {"timing": self.config.timing, "rx_kernel_stamps": all(sd.stamped for sd in self.sides.values())}
            if precise:
                info["timer_slack_1us"] = set_timer_slack(1000)
                info["short_slice"] = request_short_slice(0.0001)
            self._timer = PreciseTimer(self._loop, self._fire, spin_s=self.config.spin_s, use_timerfd=precise)
            info["timer"] = self._timer.kind
            self._timing_info = info
        self._watch = self._loop.call_later(1.0, self._watch_silence)

    def _watch_silence(self) -> None:
        """Once a second: report a side that talked and has been silent too long (and its return, :meth:`_heard`)."""
        if self.closed:
            return
        core = self.core
        for side in SIDES:
            quiet = self.silence[side].check(self._loop.time())
            if quiet is not None:
                self.warn(f"no datagram from the {LABELS[side]} ({self._peer_text(side)}) for {quiet:.0f} s"
                          f"{f' (last tick {core.last_tick}, t = {core.sim_time:g} s)' if core.last_tick is not None else ''}"
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
        if self._timer is not None:
            self._timer.close()
            self._timer = None
        for side in self.sides.values():
            side.close()
        await asyncio.sleep(0)

    # -- clock ---------------------------------------------------------------------------------
    def now(self) -> float:
        """Current sim time (s) of the shim's clock."""
        if self.core.tick_mode:
            return self.core.sim_time
        return (self._loop.time() - self._t0) * self.config.speed

    def _wall_of(self, sim_t: float) -> float:
        return self._t0 + sim_t / self.config.speed

    # -- datapath ------------------------------------------------------------------------------
    def _on_datagram(self, side: str, data: bytes, addr: Address, t_rx: "float | None" = None) -> None:
        """One datagram from ``side``; ``t_rx``: kernel arrival time (loop clock, s) if known."""
        if self.closed:
            return
        self.io_counters["datagrams_from_" + side] += 1
        peer = self.peers[side]
        if peer is None:
            if not self.core.claim(side, data):
                return
            self.peers[side] = addr
        elif peer != addr:
            self.io_counters["rejected_peer"] += 1
            self.drops[side].note(addr)
            return
        now = self._loop.time() if self._loop is not None else 0.0
        back = self.silence[side].heard(now)
        if back is not None:
            self.warn(f"the {LABELS[side]} is back after {back:.0f} s of silence ({self._peer_text(side)})")
        core = self.core
        t_in = 0.0
        if not core.tick_mode and self._loop is not None:  # the free-running clock: kernel arrival time
            t_in = self.now() if t_rx is None else min(self.now(), (t_rx - self._t0) * self.config.speed)
        self._send_all(core.receive(side, data, t_in))
        if core.counters["dropped_queue"] and not self._queue_warned:
            self._queue_warned = True
            cfg = self.config
            self.warn(f"dropping datagrams from the {LABELS[side]}: a queue is past its byte budget (delay lines "
                      f"{cfg.max_line_bytes // 2**20} MiB each, held datagrams {cfg.max_held_bytes // 2**20} MiB; "
                      f"a flood?); counted as dropped_queue in the stats")
        if core.processed:
            self._ticks_done(core.processed, t_rx)
        elif core.tick_mode is False:
            self._arm()

    def _send_all(self, sends: "list[Send]") -> None:
        for dest, data in sends:
            peer = self.peers[dest]
            sock = self.sides.get(dest)
            if peer is None or sock is None or sock.closed:
                self.io_counters["no_peer"] += 1
                if dest not in self._no_peer_warned and not self.closed:
                    self._no_peer_warned.add(dest)
                    self.warn(f"dropping datagrams due for the {LABELS[dest]}: nothing has sent to the shim's "
                              f"{dest} side yet, so it does not know where to (the shim learns each side from "
                              f"its first datagram; counted as no_peer)")
            elif sock.sendto(data, peer):
                self.io_counters["forwarded_to_" + dest] += 1

    def _ticks_done(self, processed: list, t_rx: "float | None") -> None:
        """After the core processed ticks: log them (realtime tick schedule), wake :meth:`wait_tick`."""
        if self.config.clock == "realtime":
            done = self._loop.time()
            rx = t_rx if t_rx is not None else done
            for k, t_k, n in processed:
                if k not in self._seen_ticks and len(self._tick_log) < 1_000_000:
                    self._seen_ticks.add(k)
                    self._tick_log.append((t_k, rx, done, n))
        last = self.core.last_tick
        for tick, fut in self._tick_waiters:
            if tick <= last and not fut.done():
                fut.set_result(last)
        self._tick_waiters = [w for w in self._tick_waiters if not w[1].done()]

    # -- free-running release timer --------------------------------------------------------------
    def _arm(self) -> None:
        """Make sure the timer fires at the core's earliest pending release."""
        nxt = self.core.next_release()
        if nxt is None or self._timer is None:
            return
        if self._scheduled is not None and self._scheduled <= nxt:
            return
        self._scheduled = nxt
        self._timer.arm(self._wall_of(nxt))

    def _fire(self) -> None:
        scheduled, self._scheduled = self._scheduled, None
        if self.closed or scheduled is None:
            return
        if len(self._lateness) < 1_000_000:
            self._lateness.append(self._loop.time() - self._wall_of(scheduled))
        self._send_all(self.core.release(max(self.now(), scheduled)))
        self._arm()

    # -- observability -----------------------------------------------------------------------------
    async def wait_tick(self, tick: int, timeout: float) -> int:
        """Wait until a tick >= ``tick`` has been processed; returns the last tick."""
        last = self.core.last_tick
        if last is not None and last >= tick:
            return last
        fut = asyncio.get_running_loop().create_future()
        self._tick_waiters.append((tick, fut))
        return await asyncio.wait_for(fut, timeout)

    def _tick_origin(self) -> "float | None":
        """Wall origin of the tick schedule: min over ticks k >= 1 of (arrival - t_k / speed) (s)."""
        rows = [(t, rx) for t, rx, _, _ in self._tick_log if t > 0]
        if not rows:
            return None
        return min(rx - t / self.config.speed for t, rx in rows)

    def _tick_lateness(self) -> "np.ndarray | None":
        """Per released packet: wall s from its tick's ideal instant to the end of that tick's releases."""
        w0 = self._tick_origin()
        if w0 is None:
            return None
        out = [done - (w0 + t / self.config.speed) for t, _, done, n in self._tick_log if t > 0 for _ in range(n)]
        return np.array(out, float)

    def _tick_schedule_stats(self) -> dict:
        """How late ticks arrived against their schedule (ms): the vehicle's pacing plus the transit."""
        w0 = self._tick_origin()
        if w0 is None:
            return {"ticks": len(self._tick_log)}
        late = np.array([rx - (w0 + t / self.config.speed) for t, rx, _, _ in self._tick_log if t > 0]) * 1000.0
        return {"ticks": int(late.size), "arrival_late_p50_ms": float(np.percentile(late, 50)),
                "arrival_late_p99_ms": float(np.percentile(late, 99)), "arrival_late_max_ms": float(late.max())}

    def stats(self) -> dict:
        """Counters, per-direction line stats (delays in sim s) and realtime release lateness (ms)."""
        core = self.core
        ticks_rt = bool(core.tick_mode) and self.config.clock == "realtime"
        out = {"clock": self.config.clock, "speed": self.config.speed, "sim_time_s": self.now() if self._loop else 0.0,
               "last_tick": core.last_tick, "seed": self.config.seed, "epoch_s": self.config.epoch_s,
               "peers": {k: (format_udp_address(v) if v else None) for k, v in self.peers.items()},
               "counters": {**self.counters, "malformed_content": self.guard.total},
               "control_codec": {k: v for k, v in core.codec.counters.as_dict().items() if v},
               "down": core.lines["down"].stats(), "up": core.lines["up"].stats()}
        if self._timing_info:
            out["realtime_timing"] = {**self.timing_info(), **(
                {"release": "ticks" if core.tick_mode else "timer"} if core.tick_mode is not None else {})}
        if self.config.clock == "realtime":
            out["release"] = {None: "undecided", True: "ticks", False: "timer"}[core.tick_mode]
        lat = self._tick_lateness() if ticks_rt else (np.array(self._lateness) if self._lateness else None)
        if lat is not None and lat.size:
            lat = lat * 1000.0
            out["release_lateness_ms"] = {"n": int(lat.size), "p50": float(np.percentile(lat, 50)),
                                          "p99": float(np.percentile(lat, 99)), "max": float(lat.max()),
                                          "reference": "tick schedule" if core.tick_mode else "release time"}
        if ticks_rt:
            out["tick_schedule"] = self._tick_schedule_stats()
        for side in SIDES:
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
