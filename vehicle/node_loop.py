"""The vehicle node's waits (sockets and timers only): for a tick's answer, for a step's deadline, and while
it boots. Each wait hands what arrives to the protocol core at the step boundary and sends what the core
has to send (:class:`NodeLoop` wraps one :class:`vehicle.protocol.VehicleProtocol`; the rules -- when to
send a tick again, when to give up, whom to name -- are :class:`vehicle.tick_rules.TickRules`)."""

from __future__ import annotations

import asyncio
from typing import Callable


class NodeLoop:
    """The waits of one vehicle node: ``protocol`` its core, ``flush()`` sends and prints what the core has,
    ``check_stop()`` raises ``asyncio.CancelledError`` once a stop was requested, ``opts`` the node's
    :class:`vehicle.node_options.VehicleOptions`, ``last_refused()`` the wall time of the main socket's last
    ICMP port unreachable (or None). ``wall0``: loop time of step 0's deadline (realtime)."""

    def __init__(self, protocol, flush: Callable[[], None], check_stop: Callable[[], None], opts,
                 last_refused: "Callable[[], float | None]"):
        self.protocol, self.flush, self.check_stop, self.opts = protocol, flush, check_stop, opts
        self.last_refused = last_refused
        self.wake = asyncio.Event()
        self.wall0 = 0.0

    async def wait(self, timeout: float) -> None:
        """Until a datagram arrives (:attr:`wake`) or ``timeout`` (s) passes."""
        if not self.wake.is_set():
            try:
                await asyncio.wait_for(self.wake.wait(), max(0.0, timeout))
            except asyncio.TimeoutError:
                pass
        self.wake.clear()

    def drain(self) -> None:
        self.protocol.process()
        self.flush()

    def _handle_pilot(self) -> bool:
        """Process what waits on the pilot's port; True if there was something."""
        p = self.protocol
        if not p.pending(p.pilot_port):
            return False
        p.process(p.pilot_port)
        self.flush()
        return True

    async def await_ready(self, k: int, t: float, need_ack: bool = False, send: bool = True) -> None:
        """Send SIM_TICK(k) (unless ``send`` is False: already sent) and handle messages until step ``k``
        may run, sending it again when the rules say; :class:`vehicle.tick_rules.TickTimeout` past the limit."""
        loop = asyncio.get_running_loop()
        p = self.protocol
        w = p.ticks.wait(k, t, loop.time(), need_ack)
        if send:
            p.send_tick(k, t)
            self.flush()
        while not w.ready():
            self.check_stop()
            if self._handle_pilot():
                continue
            now = loop.time()
            if now >= w.next_timer():
                for kk, tt in w.on_timer(now, self.last_refused()):
                    p.send_tick(kk, tt)
                self.flush()
                continue
            await self.wait(w.next_timer() - now)

    async def receive_until(self, when: float, until=None) -> None:
        """Handle messages until loop time ``when`` (or until ``until()`` is true)."""
        loop = asyncio.get_running_loop()
        while until is None or not until():
            self.check_stop()
            if self._handle_pilot():
                continue
            left = when - loop.time()
            if left <= 0:
                return
            await self.wait(left)

    async def realtime_tick(self, k: int, t: float, period: float) -> float:
        """Realtime step ``k``: send its tick a lead before the deadline, then wait for the partner's
        answer (at most a grace past the deadline; without a partner, until the deadline). Returns the
        step's deadline (loop time)."""
        loop = asyncio.get_running_loop()
        p = self.protocol
        rules = p.ticks
        lead = rules.lead_s(period)
        if k == 0:
            if self.opts.tick_sync == "wait":
                await self.await_ready(0, t)  # (re-)sends tick 0 until the GCS (behind the shim) answers
            else:
                p.send_tick(0, t)
                self.flush()
            self.wall0 = loop.time() + lead
            if callable(self.opts.on_clock_start):
                self.opts.on_clock_start(self.wall0)
        else:
            rules.note_late_ack(k)
            await self.receive_until(self.wall0 + t / self.opts.speed - lead)
            self.drain()
            p.send_tick(k, t)
            self.flush()
        due = self.wall0 + t / self.opts.speed
        p.check_silence(loop.time())
        self.flush()
        until, stop_early = rules.confirm_deadline(due, period)
        await self.receive_until(until, until=(lambda: rules.confirmed(k)) if stop_early else None)
        rules.note_unconfirmed(k)
        p.check_silence(loop.time())
        self.flush()
        return due

    async def serve_until(self, done: Callable[[], bool], to_pilot: bool, standby: bool = False) -> None:
        """Serve the link as a booting (or, ``standby``, waiting) vehicle until ``done()``: a heartbeat once a
        wall second (to the pilot's link too if ``to_pilot``), settings and reads as they come."""
        loop = asyncio.get_running_loop()
        p = self.protocol
        next_hb = loop.time()
        while not done():
            self.check_stop()
            now = loop.time()
            if now >= next_hb:
                p.publish_boot(now, to_pilot, standby)
                next_hb = now + 1.0
            elif p.pending():
                p.process()
            self.flush()
            await self.wait(min(next_hb - loop.time(), 0.2))
