"""Lockstep clock protocol helpers for the vehicle and GCS nodes (``docs/architecture.md``).

Per step ``k`` (sim time ``t_k``)::

    vehicle                      shim                                   GCS
    SIM_TICK(k, t_k)  ───────▶  clock := t_k, release due packets  ───▶ (telemetry due, then the tick)
                                                                        step 1: pilot decides, sends cmds
    (cmds due, then the ack) ◀── cmds queued at t_k, ack forwarded ◀─── SIM_TICK_ACK(k)
    step 2: OnboardCore.step(t_k, commands received so far), publish telemetry, advance truth

:class:`LockstepVehicle` sends the tick and collects every message that arrives before the ack;
:class:`LockstepGcs` waits for the next tick (collecting what arrived before it) and acks. Ticks
are re-sent after ``timeout`` s (``retries`` times); the GCS re-acks a repeated tick without
running the step again. With signing, control messages go on their own signing stream
(:data:`~daa_sil.link.codec.CONTROL_LINK_ID`) because they overtake delayed data in the shim.
Control datagrams bypass the shim's delay, loss and outages. The shim echoes every tick back to
the vehicle (it is alive, and the uplink due at that tick has been sent); :class:`LockstepVehicle`
counts the echoes (``echoes``) and does not hand them on.

Realtime runs use the same messages, paced by the vehicle's wall clock (``vehicle/node.py``,
``docs/sil.md`` "Realtime and lockstep"). ``daa-vehicle`` itself steps on the shim's echo (the
shim holds a tick until the GCS acknowledged the previous one, :mod:`daa_sil.sil.shim_ticks`);
:class:`LockstepVehicle` waits for the ack, which that shim rule never delays.
"""

from __future__ import annotations

import asyncio

from daa_sil.errors import DaaSilError
from daa_sil.link.codec import CONTROL_LINK_ID
from .endpoint import MavEndpoint, Received
from daa_sil.link.messages import sim_tick, sim_tick_ack


class LockstepTimeout(DaaSilError):
    """The peer did not answer a tick (exit 1)."""

    exit_code = 1


class LockstepVehicle:
    """Vehicle side: ``msgs = await clock.step(k, t_s)`` sends SIM_TICK and returns what arrived before the ack."""

    def __init__(self, ep: MavEndpoint, timeout: float = 5.0, retries: int = 3):
        self.ep, self.timeout, self.retries = ep, float(timeout), int(retries)
        self.link_id = CONTROL_LINK_ID if ep.codec.signed else None
        self.resent = 0
        self.echoes = 0

    async def step(self, k: int, t_s: float) -> list[Received]:
        """Run the tick handshake of step ``k`` at sim time ``t_s`` (s)."""
        got: list[Received] = []
        loop = asyncio.get_running_loop()
        for attempt in range(self.retries + 1):
            if attempt:
                self.resent += 1
            if not self.ep.send(sim_tick(k, t_s), link_id=self.link_id):
                raise LockstepTimeout("lockstep: no peer to send SIM_TICK to (is the shim address right?)")
            deadline = loop.time() + self.timeout
            while True:
                left = deadline - loop.time()
                if left <= 0:
                    break
                try:
                    r = await self.ep.recv(left)
                except asyncio.TimeoutError:
                    break
                if r.msg.get_type() == "SIM_TICK_ACK":
                    if r.msg.tick == k:
                        return got
                    continue  # an ack of an earlier (re-sent) tick
                if r.msg.get_type() == "SIM_TICK" and r.msg.get_srcSystem() == self.ep.codec.mav.srcSystem:
                    self.echoes += 1  # the shim echoes our tick: it is alive (not a message for the step)
                    continue
                got.append(r)
        raise LockstepTimeout(f"lockstep: no SIM_TICK_ACK for tick {k} after {self.retries + 1} tries "
                              f"of {self.timeout:g} s (is the GCS running?)")


class LockstepGcs:
    """GCS side: ``k, t_s, msgs = await clock.next_tick()``; run step 1; then ``clock.ack(k, t_s, sent)``."""

    def __init__(self, ep: MavEndpoint):
        self.ep = ep
        self.link_id = CONTROL_LINK_ID if ep.codec.signed else None
        self.last_acked: "tuple[int, float, int] | None" = None
        self.reacked = 0

    async def next_tick(self, timeout: "float | None" = None) -> tuple[int, float, list[Received]]:
        """Wait for a new SIM_TICK; returns ``(k, t_k s, messages that arrived before it)``."""
        got: list[Received] = []
        loop = asyncio.get_running_loop()
        deadline = None if timeout is None else loop.time() + timeout
        while True:
            left = None if deadline is None else deadline - loop.time()
            if left is not None and left <= 0:
                raise LockstepTimeout(f"lockstep: no SIM_TICK within {timeout:g} s")
            try:
                r = await self.ep.recv(left)
            except asyncio.TimeoutError:
                raise LockstepTimeout(f"lockstep: no SIM_TICK within {timeout:g} s") from None
            if r.msg.get_type() != "SIM_TICK":
                got.append(r)
                continue
            k = int(r.msg.tick)
            if self.last_acked is not None and k <= self.last_acked[0]:
                if k == self.last_acked[0]:  # the vehicle re-sent: our ack was late or lost
                    self.ep.send(sim_tick_ack(*self.last_acked), link_id=self.link_id)
                    self.reacked += 1
                continue
            return k, r.msg.time_ms / 1000.0, got

    def ack(self, k: int, t_s: float, sent: int = 0) -> None:
        """Acknowledge step ``k`` after sending this step's commands."""
        self.last_acked = (int(k), float(t_s), int(sent))
        self.ep.send(sim_tick_ack(k, t_s, sent), link_id=self.link_id)
