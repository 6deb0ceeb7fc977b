"""The vehicle node's clock handshake: sending SIM_TICK, waiting for its answer (lockstep: the shim's
echo -- the GCS's ack for tick 0, after the last step and without a shim; realtime: the shim's echo,
within a grace past the deadline), recording who answered and naming a partner that went silent
(docs/sil.md, "Realtime and lockstep")."""

from __future__ import annotations

import asyncio

from daa_sil.errors import DaaSilError
from daa_sil.link.codec import CONTROL_LINK_ID
from daa_sil.link.codec import mavlink as M
from vehicle import telemetry as T

#: realtime: SIM_TICK(k) is sent this fraction of a step before step k's deadline (at most TICK_LEAD_MAX_S)
TICK_LEAD_FRACTION = 0.5
TICK_LEAD_MAX_S = 0.25
#: realtime: wait at most this fraction of a step past the deadline for the partner's answer to the tick
CONFIRM_GRACE_FRACTION = 0.5
#: wall seconds without an answer to ticks before the partner is reported silent (and not waited for)
SILENT_AFTER_S = 3.0
SILENT_AFTER_STEPS = 10


class TickTimeout(DaaSilError):
    """The lockstep partner did not acknowledge a tick in time."""


class TickClock:
    """Part of :class:`vehicle.node.VehicleNode` (a mixin: it uses the node's attributes)."""

    def _send_tick(self, k: int, t: float) -> None:
        if self.peer is None:  # --out udpin: no GCS yet; the retry sends it once one has spoken
            return
        data = self.codec.encode(M.MAVLink_sim_tick_message(k, T.time_ms(t)),
                                 link_id=CONTROL_LINK_ID if self.codec.signed else None)
        self._tick_sent_k = max(self._tick_sent_k, k)
        self.ep.transport.sendto(data, self.peer)
        self.stats.ticks_sent += 1

    # -- tick answers: who is alive ----------------------------------------------------------------
    def _answered(self, who: str) -> None:
        """An echo (``who="shim"``) or an ack (``"gcs"``) of one of our ticks arrived."""
        now = asyncio.get_running_loop().time()
        if self._silent[who]:
            self._silent[who] = False
            self._say(f"the {'shim' if who == 'shim' else 'GCS'} answers ticks again at t = {self.t:g} s "
                      f"(silent for {now - self._last_answer[who]:.1f} s)")
        self._last_answer[who] = now
        if who == "shim":
            self.stats.sync_partner = "shim"
        elif self.stats.sync_partner == "none":
            self.stats.sync_partner = "gcs"

    def _check_silence(self) -> None:
        """Report (once, until it answers again) a shim or GCS that answered ticks and then stopped.

        Silent = no answer for SILENT_AFTER_S wall seconds, or for SILENT_AFTER_STEPS steps if that is
        shorter (fast runs), but never less than 1 s."""
        now = asyncio.get_running_loop().time()
        limit = max(1.0, min(SILENT_AFTER_S, SILENT_AFTER_STEPS * self.core.dt / self.opts.speed))
        for who in ("shim", "gcs"):
            last = self._last_answer[who]
            if last is None or self._silent[who] or now - last < limit:
                continue
            self._silent[who] = True
            if who == "gcs" and self._silent["shim"]:
                continue  # the shim between us is silent: that is the news, not the GCS behind it
            self.stats.silence_warnings += 1
            peer = self.out.text
            if who == "shim":
                why = f"the shim at {peer} has not echoed a tick for {now - last:.1f} s: has it stopped?"
            elif self.stats.sync_partner == "shim":
                why = (f"the GCS behind the shim at {peer} has not acknowledged a tick for {now - last:.1f} s "
                       f"(last tick acked: {self._acked}): has it stopped?")
            else:
                why = f"the GCS at {peer} has not acknowledged a tick for {now - last:.1f} s: has it stopped?"
            self._say(f"warning: {why} Flying on; the agent hands over to the onboard DAA when the link "
                      f"times out")

    def _say(self, text: str) -> None:
        import sys

        print(f"daa-vehicle: {text}", file=sys.stderr, flush=True)

    def _who_is_silent(self, k: int) -> str:
        """Why tick ``k`` got no ack: which of shim and GCS is not there (for the one-line error)."""
        import time

        peer = self.out.text
        if k > 0 and self._echoed == k - 1 and self._acked < k - 1:
            return (f"the shim at {peer} holds tick {k} until the GCS behind it acknowledges tick {k - 1}, which "
                    f"it has not: is daa-gcs still running (with --clock lockstep), pointed at the shim's GCS side?")
        if self._echoed >= k:
            return (f"the shim at {peer} relays tick {k} but the GCS behind it does not acknowledge it: is daa-gcs "
                    f"running (with --clock lockstep) and pointed at the shim's GCS side?")
        refused = self.ep.last_refused is not None and time.monotonic() - self.ep.last_refused < 5.0
        if refused:
            return (f"nothing is listening at {peer} (ICMP port unreachable): is the shim (or the GCS) running "
                    f"there?")
        return (f"no answer at all from {peer} (no tick echo, no ack): is a lockstep shim or GCS running there "
                f"with --clock lockstep?")

    def _lockstep_ready(self, k: int, need_ack: bool = False) -> bool:
        """May lockstep step ``k`` run? Once the GCS acknowledged tick ``k``; behind a shim (it echoes
        ticks) already on its echo of tick ``k >= 1``: the shim processes tick ``k`` only after the
        GCS acknowledged tick ``k - 1`` (:mod:`daa_sil.sil.shim_ticks`), so every uplink packet due at
        ``t_k`` has been sent to us; what the GCS sends at ``t_k`` is released at a later tick at the
        earliest (the shim releases only when it processes a tick): the two steps of a tick run in
        parallel. Tick 0 waits for the ack (the GCS may still be starting and must run its step 0),
        and so does ``need_ack``."""
        return self._acked >= k or (k > 0 and not need_ack and self._echoed >= k)

    async def _await_ack(self, k: int, t: float, need_ack: bool = False, send: bool = True) -> None:
        """Send SIM_TICK(k) (unless ``send`` is False: already sent) and wait until step ``k`` may run
        (:meth:`_lockstep_ready`), re-sending it every ``tick_retry_s``; TickTimeout after the limit."""
        loop = asyncio.get_running_loop()
        limit = self.opts.tick_timeout_s
        if k == 0 and self.opts.start_timeout_s is not None:
            limit = self.opts.start_timeout_s
        deadline = loop.time() + limit
        retry = self.opts.tick_retry_s if k > 0 else min(0.2, self.opts.tick_retry_s)  # GCS may still start
        next_retry = loop.time() + retry
        if send:
            self._send_tick(k, t)
        while not self._lockstep_ready(k, need_ack):
            self._check_stop()
            now = loop.time()
            if now >= deadline:
                what = "SIM_TICK_ACK" if need_ack or k == 0 or self.stats.sync_partner != "shim" else "echo"
                raise TickTimeout(f"no {what} for tick {k} (t = {t:g} s) within {limit:g} s: "
                                  + self._who_is_silent(k))
            try:  # what already arrived first (one wait per burst of datagrams, not per message)
                r = self.ep.inbox.get_nowait()
            except asyncio.QueueEmpty:
                try:
                    r = await asyncio.wait_for(self.ep.inbox.get(), min(deadline, next_retry) - now)
                except asyncio.TimeoutError:
                    if loop.time() >= next_retry and loop.time() < deadline:
                        if k > 0 and not need_ack and self._acked < k - 1:
                            # a shim holds tick k until the GCS acknowledges tick k - 1: send that one
                            # again too (the shim forwards a repeated tick), in case it was lost
                            self._send_tick(k - 1, t - self.core.dt)
                        self._send_tick(k, t)
                        self.stats.tick_retries += 1
                        next_retry = loop.time() + retry
                    continue
            self.take(r)

    def _confirmed(self, k: int) -> bool:
        """Realtime: has the partner answered tick ``k`` (shim: echo; GCS wired directly: ack)?"""
        if self.stats.sync_partner == "shim":
            return self._echoed >= k
        if self.stats.sync_partner == "gcs":
            return self._acked >= k
        return True  # a partner that answers no tick (stock GCS): free-running

    async def _receive_until(self, when: float, until=None) -> None:
        """Handle messages until loop time ``when`` (or until ``until()`` is true)."""
        loop = asyncio.get_running_loop()
        while until is None or not until():
            self._check_stop()
            left = when - loop.time()
            if left <= 0:
                return
            try:
                r = await asyncio.wait_for(self.ep.inbox.get(), left)
            except asyncio.TimeoutError:
                return
            self.take(r)

    async def _realtime_tick(self, k: int, t: float, period: float) -> float:
        """Realtime step ``k``: send its tick a lead before the deadline, then wait for the partner's
        answer (at most a grace past the deadline; without a partner, until the deadline). Once the
        shim has echoed tick ``k`` every input of step ``k`` is in (uplink is released only at ticks),
        so the step may be computed before its deadline; :meth:`run` publishes it at the deadline.
        Returns the step's deadline (loop time)."""
        loop = asyncio.get_running_loop()
        lead = min(TICK_LEAD_FRACTION * period, TICK_LEAD_MAX_S)
        if k == 0:
            if self.opts.tick_sync == "wait":
                await self._await_ack(0, t)  # (re-)sends tick 0 until the GCS (behind the shim) answers
            else:
                self._send_tick(0, t)
            self._wall0 = loop.time() + lead
            if callable(self.opts.on_clock_start):
                self.opts.on_clock_start(self._wall0)
        else:
            if (self._acked < k - 1 and self._last_answer["gcs"] is not None and not self._silent["gcs"]
                    and not self._silent["shim"]):
                self.stats.acks_late += 1
            await self._receive_until(self._wall0 + t / self.opts.speed - lead)
            self._drain()
            self._send_tick(k, t)
        due = self._wall0 + t / self.opts.speed
        self._check_silence()
        partner = self.stats.sync_partner
        if partner == "none" or self._silent["shim" if partner == "shim" else "gcs"]:
            await self._receive_until(due)  # nobody to wait for: take what arrived by the deadline
        else:
            await self._receive_until(due + CONFIRM_GRACE_FRACTION * period, until=lambda: self._confirmed(k))
        if not self._confirmed(k):
            self.stats.steps_unconfirmed += 1
        self._check_silence()
        return due
