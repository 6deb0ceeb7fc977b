"""The vehicle node's clock: sending SIM_TICK and waiting until each step may run.

The protocol state (ticks sent, echoes and acks heard, silence) is a
:class:`daa_sil.sil.lockstep.TickPeer`; :class:`VehicleClock` adds the waiting, which needs the
node's socket and message handling (given to it as callables).

* **lockstep**: send ``SIM_TICK(k, t_k)`` alone in its datagram to the peer (the shim), then
  receive until the shim echoes it: the shim processes tick ``k`` (releases every packet due at
  ``t_k``, forwards the tick to the GCS, echoes it) only once the GCS acknowledged tick ``k - 1``,
  so the GCS's step ``k`` and this step ``k`` run in parallel -- neither reads the other's output
  of the same tick, which the shim releases at tick ``k + 1`` at the earliest
  (:meth:`daa_sil.sil.lockstep.TickPeer.ready`). Tick 0 and the end of the run wait for the GCS's
  ``SIM_TICK_ACK``; wired straight to a GCS (no shim, no echo) every tick does. No answer within
  ``tick_timeout_s`` wall seconds -> :class:`TickTimeout` (one clear line naming who is silent).
  The tick is re-sent every ``tick_retry_s`` in case a datagram was lost (the GCS re-acks a tick
  it already did).
* **realtime** (docs/sil.md, "Realtime and lockstep"): the same ticks, paced by the wall clock.
  ``SIM_TICK(k)`` goes out a lead of half a step (at most 0.25 s) before the step's deadline
  ``W_k = t0 + t_k / speed``; the shim releases everything due at ``t_k``, forwards the tick to
  the GCS (which steps on it) and echoes it back. Once the echo is in, every input of step ``k``
  is there (uplink is released only at ticks), so the node computes the step then and publishes
  it at ``W_k``; it waits at most half a step past ``W_k`` for a late echo, so every step sees
  what the lockstep step sees. Partner = the shim (it echoes) or, wired straight to a GCS, the
  GCS (it acks); a peer that answers no tick (a stock GCS) gives free-running realtime.
  ``tick_sync="wait"`` (what ``daa-sil run`` uses) starts the clock only once tick 0 is
  acknowledged. A partner silent for the vehicle's ``SILENT_AFTER_S`` (:mod:`daa_sil.sil.silence`)
  is reported (stderr) and not waited for until it answers again; steps that ran without their
  confirmation are counted (``steps_unconfirmed``: 0 means lockstep-equivalent input).
"""

from __future__ import annotations

import asyncio
import os
import sys
import time
from typing import Callable

from daa_sil.errors import DaaSilError
from daa_sil.sil.endpoint import MavEndpoint, Received
from daa_sil.sil.lockstep import TickPeer

#: realtime: SIM_TICK(k) is sent this fraction of a step before step k's deadline (at most TICK_LEAD_MAX_S)
TICK_LEAD_FRACTION = 0.5
TICK_LEAD_MAX_S = 0.25
#: realtime: wait at most this fraction of a step past the deadline for the partner's answer to the tick
CONFIRM_GRACE_FRACTION = 0.5
#: a partner is also silent after this many steps without an answer if that is shorter (fast runs), >= 1 s
SILENT_AFTER_STEPS = 10


class TickTimeout(DaaSilError):
    """The lockstep partner did not acknowledge a tick in time."""


def say(text: str) -> None:
    """One ``daa-vehicle:`` line on stderr."""
    print(f"daa-vehicle: {text}", file=sys.stderr, flush=True)


class VehicleClock:
    """Ticks of one vehicle node. ``peer``: the protocol state; ``opts``: the node's
    :class:`vehicle.node_options.VehicleOptions`; ``dt``: the step (sim s); ``stats``: the node's
    :class:`vehicle.node_options.VehicleStats` (tick counters); ``out_text``: the pilot link's address
    as given. From the node: ``ep()`` its main endpoint, ``dest()`` the pilot link's address (None
    before a ``udpin:`` GCS spoke), ``take(r)`` handles one message, ``drain()`` handles what every
    socket received so far, ``check_stop()`` raises when a stop was requested."""

    def __init__(self, peer: TickPeer, opts, dt: float, stats, out_text: str, *,
                 ep: "Callable[[], MavEndpoint]", dest: Callable, take: "Callable[[Received], None]",
                 drain: Callable[[], None], check_stop: Callable[[], None]):
        self.peer, self.opts, self.dt, self.stats, self.out_text = peer, opts, dt, stats, out_text
        self.ep, self.dest, self.take, self.drain, self.check_stop = ep, dest, take, drain, check_stop
        self.wall0 = 0.0  #: loop time of step 0's deadline (realtime)

    def sharpen(self) -> None:
        """Realtime: like the shim, wake at deadlines without timer coalescing, and ask for a short EEVDF
        slice so a woken vehicle preempts sooner on a busy machine (unprivileged; no-op elsewhere).
        ``DAA_SIL_VEHICLE_SLICE_US``: the slice asked for (0 = keep the default; benchmarks compare both)."""
        from daa_sil.sil.rtclock import request_short_slice, set_timer_slack

        self.stats.extra["timer_slack_1us"] = set_timer_slack(1000)
        slice_us = float(os.environ.get("DAA_SIL_VEHICLE_SLICE_US", "100") or 0)
        self.stats.extra["short_slice"] = request_short_slice(slice_us * 1e-6) if slice_us > 0 else False

    def send_tick(self, k: int, t: float) -> None:
        dest = self.dest()
        if dest is None:  # --out udpin: no GCS yet; the retry sends it once one has spoken
            return
        self.ep().transport.sendto(self.peer.tick(k, t), dest)
        self.stats.ticks_sent += 1

    def answered(self, who: str, k: int, t: float) -> None:
        """An echo (``who="shim"``) or an ack (``"gcs"``) of tick ``k`` arrived during the step at ``t`` (sim s)."""
        back = self.peer.answered(who, k, asyncio.get_running_loop().time())
        self.stats.sync_partner = self.peer.partner
        if back is not None:
            say(f"the {'shim' if who == 'shim' else 'GCS'} answers ticks again at t = {t:g} s "
                f"(silent for {back:.1f} s)")

    def check_silence(self) -> None:
        """Report (once, until it answers again) a shim or GCS that answered ticks and then stopped:
        no answer for the role's SILENT_AFTER_S, or SILENT_AFTER_STEPS steps if that is shorter, >= 1 s."""
        watch = self.peer.silence["shim"]
        limit = max(1.0, min(watch.after_s, SILENT_AFTER_STEPS * self.dt / self.opts.speed))
        for who, quiet in self.peer.check_silence(asyncio.get_running_loop().time(), limit):
            self.stats.silence_warnings += 1
            if who == "shim":
                why = f"the shim at {self.out_text} has not echoed a tick for {quiet:.1f} s: has it stopped?"
            elif self.peer.partner == "shim":
                why = (f"the GCS behind the shim at {self.out_text} has not acknowledged a tick for {quiet:.1f} s "
                       f"(last tick acked: {self.peer.newest['gcs']}): has it stopped?")
            else:
                why = f"the GCS at {self.out_text} has not acknowledged a tick for {quiet:.1f} s: has it stopped?"
            say(f"warning: {why} Flying on; the agent hands over to the onboard DAA when the link times out")

    def who_is_silent(self, k: int) -> str:
        """Why tick ``k`` got no ack: which of shim and GCS is not there (for the one-line error)."""
        peer, echoed, acked = self.out_text, self.peer.newest["shim"], self.peer.newest["gcs"]
        if k > 0 and echoed == k - 1 and acked < k - 1:
            return (f"the shim at {peer} holds tick {k} until the GCS behind it acknowledges tick {k - 1}, which "
                    f"it has not: is daa-gcs still running (with --clock lockstep), pointed at the shim's GCS side?")
        if echoed >= k:
            return (f"the shim at {peer} relays tick {k} but the GCS behind it does not acknowledge it: is daa-gcs "
                    f"running (with --clock lockstep) and pointed at the shim's GCS side?")
        refused = self.ep().last_refused
        if refused is not None and time.monotonic() - refused < 5.0:
            return (f"nothing is listening at {peer} (ICMP port unreachable): is the shim (or the GCS) running "
                    f"there?")
        return (f"no answer at all from {peer} (no tick echo, no ack): is a lockstep shim or GCS running there "
                f"with --clock lockstep?")

    async def await_ready(self, k: int, t: float, need_ack: bool = False, send: bool = True) -> None:
        """Send SIM_TICK(k) (unless ``send`` is False: already sent) and handle messages until step ``k``
        may run (:meth:`TickPeer.ready`), re-sending it every ``tick_retry_s``; TickTimeout after the limit."""
        loop = asyncio.get_running_loop()
        limit = self.opts.tick_timeout_s
        if k == 0 and self.opts.start_timeout_s is not None:
            limit = self.opts.start_timeout_s
        deadline = loop.time() + limit
        retry = self.opts.tick_retry_s if k > 0 else min(0.2, self.opts.tick_retry_s)  # GCS may still start
        next_retry = loop.time() + retry
        if send:
            self.send_tick(k, t)
        inbox = self.ep().inbox
        while not self.peer.ready(k, need_ack):
            self.check_stop()
            now = loop.time()
            if now >= deadline:
                what = "SIM_TICK_ACK" if need_ack or k == 0 or self.peer.partner != "shim" else "echo"
                raise TickTimeout(f"no {what} for tick {k} (t = {t:g} s) within {limit:g} s: " + self.who_is_silent(k))
            try:  # what already arrived first (one wait per burst of datagrams, not per message)
                r = inbox.get_nowait()
            except asyncio.QueueEmpty:
                try:
                    r = await asyncio.wait_for(inbox.get(), min(deadline, next_retry) - now)
                except asyncio.TimeoutError:
                    if loop.time() >= next_retry and loop.time() < deadline:
                        if k > 0 and not need_ack and self.peer.newest["gcs"] < k - 1:
                            # a shim holds tick k until the GCS acknowledges tick k - 1: send that one
                            # again too (the shim forwards a repeated tick), in case it was lost
                            self.send_tick(k - 1, t - self.dt)
                        self.send_tick(k, t)
                        self.stats.tick_retries += 1
                        next_retry = loop.time() + retry
                    continue
            self.take(r)

    async def receive_until(self, when: float, until=None) -> None:
        """Handle messages until loop time ``when`` (or until ``until()`` is true)."""
        loop = asyncio.get_running_loop()
        inbox = self.ep().inbox
        while until is None or not until():
            self.check_stop()
            left = when - loop.time()
            if left <= 0:
                return
            try:
                r = await asyncio.wait_for(inbox.get(), left)
            except asyncio.TimeoutError:
                return
            self.take(r)

    async def realtime_tick(self, k: int, t: float, period: float) -> float:
        """Realtime step ``k``: send its tick a lead before the deadline, then wait for the partner's
        answer (at most a grace past the deadline; without a partner, until the deadline). Once the
        shim has echoed tick ``k`` every input of step ``k`` is in (uplink is released only at ticks),
        so the step may be computed before its deadline; the node publishes it at the deadline.
        Returns the step's deadline (loop time)."""
        loop = asyncio.get_running_loop()
        peer = self.peer
        lead = min(TICK_LEAD_FRACTION * period, TICK_LEAD_MAX_S)
        if k == 0:
            if self.opts.tick_sync == "wait":
                await self.await_ready(0, t)  # (re-)sends tick 0 until the GCS (behind the shim) answers
            else:
                self.send_tick(0, t)
            self.wall0 = loop.time() + lead
            if callable(self.opts.on_clock_start):
                self.opts.on_clock_start(self.wall0)
        else:
            gcs, shim = peer.silence["gcs"], peer.silence["shim"]
            if peer.newest["gcs"] < k - 1 and gcs.last is not None and not gcs.silent and not shim.silent:
                self.stats.acks_late += 1
            await self.receive_until(self.wall0 + t / self.opts.speed - lead)
            self.drain()
            self.send_tick(k, t)
        due = self.wall0 + t / self.opts.speed
        self.check_silence()
        partner = peer.partner
        if partner == "none" or peer.silence[partner].silent:
            await self.receive_until(due)  # nobody to wait for: take what arrived by the deadline
        else:
            await self.receive_until(due + CONFIRM_GRACE_FRACTION * period, until=lambda: peer.confirmed(k))
        if not peer.confirmed(k):
            self.stats.steps_unconfirmed += 1
        self.check_silence()
        return due
