"""The asyncio vehicle node: sockets, timers and the loop around a :class:`vehicle.protocol.VehicleProtocol`.

Per step ``k`` (``t_k = k`` s, ``docs/architecture.md`` "The step order") the node sends
``SIM_TICK(k, t_k)`` and waits until the step may run -- lockstep on the shim's echo (the GCS's ack
for tick 0 and the last one), realtime by the wall clock with the echo as confirmation; the rules
(when to send again, when to give up, who is silent) are :class:`vehicle.tick_rules.TickRules`.
Then ``OnboardCore.step(t_k, pilot input)`` decides (:class:`vehicle.core.VehicleCore`), the
telemetry for ``t_k`` is published, a step-log row is kept (and, with ``live``, sent at once to
the Rerun recorder's loopback feed, fire-and-forget: :class:`daa_sil.sil.live.LiveSender`), and
truth advances. The step log is written atomically at the end, on Ctrl-C and on SIGTERM
(:meth:`VehicleNode.write_steplog`).

Everything a message does -- parameters, modes, rates, the command gate, acks, the tick protocol --
is the protocol core's (:mod:`vehicle.protocol`); this module moves bytes and time only: each
datagram goes to :meth:`VehicleProtocol.receive` as it arrives (a ``tcpin:`` output's stream to
:meth:`VehicleProtocol.receive_stream`, :class:`daa_sil.sil.tcp_server.TcpServer`), the core's sends go
out, its console lines are printed.

Start: :meth:`VehicleNode.start` binds every socket first (a taken port is one line, at once), then
:meth:`VehicleNode.prepare` readies the simulation beside the link (:mod:`vehicle.prepare`) while the
core, on a :class:`vehicle.boot.BootPlant`, sends its boot heartbeat once a wall second and answers;
with ``wait_gcs`` the clock then waits for the first ground station on the pilot's link. The
simulation clock starts after that. Without ``exit_at_end`` the vehicle flies on past the scenario's
last step until stopped.

Outputs (:mod:`daa_sil.sil.outputs`): the first ``--out`` is the pilot's link (``gcs``); further
``--out`` and ``--tap`` are observers with their own stream rates, read-only unless marked writable.
"""

from __future__ import annotations

import asyncio
import itertools
import sys
import time
from pathlib import Path

from daa_sil.link.codec import MavCodec
from daa_sil.sil.connstr import LISTEN, parse_connection
from daa_sil.sil.endpoint import MavEndpoint, format_udp_address, open_endpoint
from daa_sil.sil.msgguard import MessageGuard
from daa_sil.sil.outputs import output_specs

from .boot import BootPlant
from .core import VehicleCore
from .node_loop import NodeLoop
from .node_options import VehicleOptions, VehicleStats
from .node_steplog import StepTiming, steplog_meta
from .protocol import MAIN, VEHICLE_COMPID, VEHICLE_SYSID, OutputLink, VehicleProtocol
from .tick_rules import TickOptions
from daa_sil.sil.connstr import describe
import os

__all__ = ["VehicleNode", "VehicleOptions", "VEHICLE_SYSID", "VEHICLE_COMPID"]


def say(text: str) -> None:
    """One ``daa-vehicle:`` line on stderr."""
    print(f"daa-vehicle: {text}", file=sys.stderr, flush=True)


class VehicleNode:
    """The vehicle process around a :class:`vehicle.protocol.VehicleProtocol`.

    ``await node.start()`` binds the sockets; ``await node.run()`` plays every step;
    ``node.write_steplog()`` writes what was simulated so far (safe to call more than once).
    """

    def __init__(self, scenario, opts: VehicleOptions, core: "VehicleCore | None" = None):
        self.sc = scenario
        self.opts = opts
        #: the simulation: given, or made by :meth:`prepare` (None until then)
        self.core: "VehicleCore | None" = core
        self.boot = BootPlant(scenario, opts.config, flags=opts.settings)
        self.specs = output_specs([opts.out, *opts.also_out], opts.tap, opts.tap_writable)
        self.out = self.specs[0].conn
        self.listen = parse_connection(opts.listen, "--listen", LISTEN, allow=(LISTEN,))
        self.codec = MavCodec(VEHICLE_SYSID, VEHICLE_COMPID, key=opts.key, allow_unsigned=())
        #: every received message's handling runs under it (all sockets share it)
        self.guard = MessageGuard("daa-vehicle")
        ticks = TickOptions(opts.clock, opts.speed, opts.tick_timeout_s, opts.tick_retry_s, opts.start_timeout_s,
                            opts.tick_sync)
        #: the protocol: parameters, modes, rates, the command gate, acks, the tick protocol
        self.protocol = VehicleProtocol(core if core is not None else self.boot, self.specs, self.listen.addr,
                                        self.codec, ticks, guard=self.guard, out_text=self.out.text)
        #: one socket per protocol port (filled by :meth:`start`): a MavEndpoint, or a TcpServer for tcpin:
        self.eps: list = []
        #: the boot telemetry goes to the pilot's link too, unless a tick partner (a shim) may be there
        self.boot_to_pilot = opts.clock == "realtime" and opts.tick_sync == "auto"
        #: set by :meth:`request_stop` (SIGINT / SIGTERM): the loop stops at the next step or wait even if
        #: the task's cancellation was lost (Python 3.11's ``asyncio.wait_for`` can swallow a cancel that
        #: arrives together with the awaited message)
        self.stop_requested = False
        self.timing = StepTiming()  #: realtime: per-step lateness and readiness (ms)
        #: the waits (for ticks, deadlines, while booting)
        self.waits = NodeLoop(self.protocol, self.flush, self._check_stop, opts,
                              lambda: self.ep.last_refused if self.ep is not None else None)
        self.live = None
        if opts.live:
            from daa_sil.sil.live import LiveSender  # lazy: start-up time

            self.live = LiveSender(opts.live)

    # -- the protocol's state, by the names the CLI and the tests read ---------------------------
    @property
    def stats(self) -> VehicleStats:
        return self.protocol.stats

    @property
    def gate(self):
        return self.protocol.gate

    @property
    def services(self):
        return self.protocol.services

    @property
    def outputs(self) -> "list[OutputLink]":
        return self.protocol.outputs

    @property
    def k(self) -> int:
        return self.protocol.k

    @property
    def t(self) -> float:
        return self.protocol.t

    @property
    def ep(self) -> "MavEndpoint | None":
        """The main socket (the pilot's link, fixed observers)."""
        return self.eps[MAIN] if self.eps else None

    @property
    def peer(self):
        """The pilot's link (the first ``--out``): fixed, or with ``udpin:`` the first address that sent a good
        message; None before that."""
        return self.protocol.outputs[0].addr

    @property
    def endpoints(self) -> list:
        """Every socket of the vehicle, the main one first (a TcpServer for each tcpin: output)."""
        return list(self.eps)

    def bound_address(self, out) -> str:
        """Where output ``out`` (an :class:`vehicle.ports.OutputLink`) listens or sends, as bound."""

        if not out.listens:
            return describe(out.spec.conn)
        return describe(out.spec.conn, self.eps[out.port].local_address[1])

    def sim_now(self) -> float:
        """Vehicle sim time now (s)."""
        return self.protocol.sim_time_of(time.monotonic())

    # -- lifecycle -------------------------------------------------------------------------------
    async def start(self) -> None:
        """Bind one socket per protocol port: the main one (``--listen``, or the first ``--out`` if it is
        ``udpin:``) and one per further ``udpin:`` / ``tcpin:`` output. A taken port: one-line UsageError."""
        from daa_sil.sil.tcp_server import TcpServer  # lazy: start-up time

        p = self.protocol
        try:
            for i, port in enumerate(p.ports):
                if port.transport == "tcp":
                    ep = TcpServer(lambda addr, now, i=i: p.connect(i, addr, now),
                                   lambda addr, data, now, i=i: self._on_stream(i, data, addr, now),
                                   lambda addr, i=i: p.disconnect(i, addr))
                    self.eps.append(ep)
                    await ep.start(port.bind)
                    continue
                ep = await open_endpoint(self.codec, port.bind, intake=port.intake,
                                         on_datagram=lambda data, addr, now, i=i: self._on_datagram(i, data, addr, now))
                self.eps.append(ep)
        except BaseException:
            self.close()
            raise

    def _on_datagram(self, port: int, data: bytes, addr, now: float) -> None:
        self.protocol.receive(port, data, addr, now)
        self.flush()
        self.waits.wake.set()

    def _on_stream(self, port: int, data: bytes, addr, now: float) -> None:
        self.protocol.receive_stream(port, data, addr, now)
        self.flush()
        self.waits.wake.set()

    def flush(self) -> None:
        """Send what the protocol has to send and print its lines."""
        p = self.protocol
        for s in p.take_sends():
            ep = self.eps[s.port] if s.port < len(self.eps) else None
            if ep is None:
                continue
            if not isinstance(ep, MavEndpoint):  # a TCP client: the bytes go into its stream
                ep.send(s.addr, s.data)
                continue
            if ep.transport is None or ep.transport.is_closing():
                continue
            if s.counted:
                ep.send_datagram(s.data, s.addr, s.messages)
            else:
                ep.transport.sendto(s.data, s.addr)
        for n in p.take_notices():
            if n.stream == "stdout":
                print(n.text, flush=True)
            else:
                say(n.text)

    def dropped(self) -> int:
        """Messages dropped on every socket: codec rejections, unexpected peers, overflow, malformed content."""
        return self.protocol.dropped()

    @property
    def wall0(self) -> float:
        """Loop time of step 0's deadline (realtime)."""
        return self.waits.wall0

    def request_stop(self) -> None:
        """Stop playing: :meth:`run` raises ``asyncio.CancelledError`` at its next step or wait."""
        self.stop_requested = True

    def _check_stop(self) -> None:
        if self.stop_requested:
            raise asyncio.CancelledError("stop requested")

    @property
    def local_address(self) -> str:
        return format_udp_address(self.ep.local_address)

    async def prepare(self) -> None:
        """Ready the simulation beside the link (:mod:`vehicle.prepare`), serving the link as a booting vehicle
        meanwhile."""
        from .prepare import Preparation  # lazy: start-up time

        p = self.protocol
        if self.core is None:
            prep = Preparation(self.sc, self.opts, self.boot.policy,
                               lambda text: (p.boot_progress(text, self.boot_to_pilot), self.flush()))
            task = asyncio.ensure_future(prep.run())
            task.add_done_callback(lambda _: self.waits.wake.set())
            try:
                await self.waits.serve_until(task.done, self.boot_to_pilot)
                self.core = task.result()
            finally:
                if not task.done():
                    prep.cancel()
                    task.cancel()
        if p.booting:
            p.set_plant(self.core)
            p.boot_progress("ready", self.boot_to_pilot)
            self.flush()

    async def wait_for_gcs(self) -> None:
        """``wait_gcs``: serve the link (MAV_STATE_STANDBY) until a ground station on the pilot's link speaks."""
        p = self.protocol
        if self.opts.wait_gcs and not p.pilot_heard:
            say(f"ready; waiting for a ground station on {self.out.text} (--wait-gcs)")
            await self.waits.serve_until(lambda: p.pilot_heard, self.boot_to_pilot, standby=True)
            say("a ground station spoke: the clock starts")

    def close(self) -> None:
        for ep in self.eps:
            ep.close()
        if self.live is not None:
            self.live.close()

    def _sharpen(self) -> None:
        """Realtime: like the shim, wake at deadlines without timer coalescing, and ask for a short EEVDF
        slice so a woken vehicle preempts sooner on a busy machine (unprivileged; no-op elsewhere).
        ``DAA_SIL_VEHICLE_SLICE_US``: the slice asked for (0 = keep the default; benchmarks compare both)."""

        from daa_sil.sil.rtclock import request_short_slice, set_timer_slack  # lazy: start-up time

        self.stats.extra["timer_slack_1us"] = set_timer_slack(1000)
        slice_us = float(os.environ.get("DAA_SIL_VEHICLE_SLICE_US", "100") or 0)
        self.stats.extra["short_slice"] = request_short_slice(slice_us * 1e-6) if slice_us > 0 else False

    # -- main loop -------------------------------------------------------------------------------
    def publish(self, t: float, out) -> None:
        """Telemetry for ``t`` (s): per output, one datagram of the messages due on that output's stream."""
        self.protocol.publish(t, out, time.monotonic())
        self.flush()

    async def run(self, on_step=None) -> None:
        """Play every step of the scenario, and on past it unless ``exit_at_end`` (see the module docstring);
        prepares first if :meth:`prepare` has not run, and with ``wait_gcs`` waits for a ground station."""
        if self.core is None or self.protocol.booting:
            await self.prepare()
        await self.wait_for_gcs()
        loop = asyncio.get_running_loop()
        p = self.protocol
        n = self.core.n_steps
        lockstep = self.opts.clock == "lockstep"
        period = self.core.dt / self.opts.speed
        self.waits.wall0 = loop.time()
        if not lockstep:
            self._sharpen()
        for k in (range(n) if self.opts.exit_at_end else itertools.count()):
            self._check_stop()
            p.begin_step(k)
            t = p.t
            if lockstep:
                self.waits.drain()
                await self.waits.await_ready(k, t)
            else:
                due = await self.waits.realtime_tick(k, t, period)
            self.waits.drain()
            out = self.core.step(t)
            if not lockstep:  # computed ahead (inputs complete once the tick is echoed): out at the deadline
                self.timing.ready(1000.0 * (loop.time() - due))
                wait = due - loop.time()
                if wait > 0:
                    await asyncio.sleep(wait)
                self._check_stop()
            self.publish(t, out)
            if self.live is not None:
                self.live.send(self.core.last_row)  # non-blocking; failures are counted, never raised
            self.stats.steps = k + 1
            if not lockstep:
                self.timing.published(1000.0 * (loop.time() - due), self.stats)
            if on_step is not None:
                on_step(self, out)
            await asyncio.sleep(0)
        if lockstep and n and self.opts.exit_at_end:
            # the GCS ran its last step in parallel: done once it acknowledged it (as every other tick)
            await self.waits.await_ready(n - 1, (n - 1) * self.core.dt, need_ack=True, send=False)

    def write_steplog(self) -> "Path | None":
        """Write the step log so far (atomic Parquet; only the steps published); returns its path or None."""
        if self.opts.steplog is None or self.stats.steps == 0 or self.core is None:
            return None
        if self.timing.late_ms:
            self.stats.late_p99_ms = self.timing.p99_ms()
        meta = steplog_meta(self.sc, self.opts, self.core, self.stats, signed=self.codec.signed,
                            gate=self.gate.counters.__dict__, link=self.ep.stats() if self.ep else {},
                            live=self.live.stats.__dict__ if self.live is not None else None,
                            timing=self.timing, wall0=self.waits.wall0, events=self.services.events)
        return self.core.write_steplog(self.opts.steplog, meta, n_rows=self.stats.steps)
