"""The asyncio vehicle node: one :class:`daa_sil.onboard.OnboardCore` (N = 1) behind a MAVLink endpoint.

Per step ``k`` (``t_k = k`` s, ``docs/architecture.md`` "The step order") the node's
:class:`vehicle.ticks.VehicleClock` sends ``SIM_TICK(k, t_k)`` and waits until the step may run:
lockstep on the shim's echo (the GCS's ack for tick 0 and the last one), realtime by the wall clock
with the echo as confirmation (its module docstring has the rules).
Then ``OnboardCore.step(t_k, pilot input)`` decides, the telemetry for ``t_k`` is published (one
datagram to the peer, and the same undelayed to the observer ``tap`` if set), a step-log row is
kept (and, with ``live``, sent at once to the Rerun recorder's loopback feed, fire-and-forget:
:class:`daa_sil.sil.live.LiveSender`), and truth advances. The step log is written atomically at the end, on Ctrl-C and on
SIGTERM (:meth:`VehicleNode.write_steplog`).

Outputs (:mod:`daa_sil.sil.outputs`): the first ``--out`` is the pilot's link (``gcs``); further
``--out`` and ``--tap`` are observers with their own stream rates, read-only unless marked writable.

Hostile input: the endpoint/codec count and drop malformed, forged and replayed packets; every
message's handling runs under the endpoint's :class:`daa_sil.sil.msgguard.MessageGuard`, so one
that raises is counted as malformed and the rest of its datagram is still handled; the
:class:`~vehicle.commands.CommandGate` drops duplicate, older, future-stamped and invalid pilot
commands; pilot commands from an observer are ignored. Link liveness for the agent counts only
**data** from the GCS (HEARTBEAT, commands), never the lockstep control messages, which bypass the
delay line.
"""

from __future__ import annotations

import asyncio
import time
from functools import partial
from pathlib import Path

from daa_sil.link.codec import MavCodec
from daa_sil.link.codec import mavlink as M
from daa_sil.sil.connstr import LISTEN, parse_connection
from daa_sil.sil.endpoint import MavEndpoint, Received, format_udp_address, open_endpoint
from daa_sil.sil.msgguard import MessageGuard
from daa_sil.sil.outputs import PILOT_LINK, Output, output_specs

from . import telemetry as T
from .commands import CommandGate, reposition_command, setpoint_command
from .core import VehicleCore
from .params import ParamTable
from .services import GcsServices
from .streams import STREAMED
from daa_sil.sil.lockstep import TickPeer
from vehicle.ticks import VehicleClock
from vehicle.node_steplog import StepTiming, steplog_meta
from vehicle.node_options import VehicleOptions, VehicleStats

VEHICLE_SYSID, VEHICLE_COMPID = 1, 1
PILOT_MANEUVER_ID = M.MAVLINK_MSG_ID_PILOT_MANEUVER


class VehicleNode:
    """The vehicle process logic around a :class:`vehicle.core.VehicleCore`.

    ``await node.start()`` binds the socket; ``await node.run()`` plays every step;
    ``node.write_steplog()`` writes what was simulated so far (safe to call more than once).
    """

    def __init__(self, scenario, opts: VehicleOptions, core: "VehicleCore | None" = None):
        self.sc = scenario
        self.opts = opts
        self.core = core if core is not None else VehicleCore(scenario, waitmap=opts.waitmap, config=opts.config)
        self.specs = output_specs([opts.out, *opts.also_out], opts.tap, opts.tap_writable)
        self.out = self.specs[0].conn
        self.listen = parse_connection(opts.listen, "--listen", LISTEN, allow=(LISTEN,))
        self.codec = MavCodec(VEHICLE_SYSID, VEHICLE_COMPID, key=opts.key, allow_unsigned=())
        self.ep: "MavEndpoint | None" = None  #: the main socket (the pilot's link, fixed observers)
        self.outputs: "list[Output]" = []  #: filled by :meth:`start`; outputs[0] is the pilot's link
        #: every received message's handling runs under it (all endpoints share it)
        self.guard = MessageGuard("daa-vehicle")
        self.gate = CommandGate()
        self.stats = VehicleStats()
        self.k = 0
        self.t = 0.0
        self.authority = "pilot"
        #: the tick protocol (:class:`daa_sil.sil.lockstep.TickPeer`) and the waiting on it
        self.clock = VehicleClock(TickPeer("vehicle", self.codec), opts, self.core.dt, self.stats, self.out.text,
                                  ep=lambda: self.ep, dest=lambda: self.peer, take=self.take, drain=self._drain,
                                  check_stop=self._check_stop)
        #: set by :meth:`request_stop` (SIGINT / SIGTERM): the loop stops at the next step or wait even if
        #: the task's cancellation was lost (Python 3.11's ``asyncio.wait_for`` can swallow a cancel that
        #: arrives together with the awaited message)
        self.stop_requested = False
        self.timing = StepTiming()  #: realtime: per-step lateness and readiness (ms)
        self._step_t, self._step_wall = 0.0, None  # sim and monotonic time of the last publish
        self._stamp = None  # (addr, datagram time, t_sent) of the GCS's last SYSTEM_TIME
        self.home: "T.Kin | None" = None
        self.latest: dict = {}
        self.services = GcsServices(ParamTable(scenario.thresholds), lambda: self.core.core.policy, self._set_policy,
                                    lambda: self.latest, self.sim_now, dt=self.core.dt,
                                    writable=frozenset(s.name for s in self.specs if s.writable or s.name == PILOT_LINK),
                                    step_t=lambda: self.t, current_mode=self._mode_now)
        self.live = None
        if opts.live:
            from daa_sil.sil.live import LiveSender

            self.live = LiveSender(opts.live)

    @property
    def peer(self):
        """The pilot's link (the first ``--out``): fixed, or with ``udpin:`` the first address that sent a good
        message; None before that (or before :meth:`start`)."""
        return self.outputs[0].addr if self.outputs else None

    def _mode_now(self) -> int:
        from .identity import mode_of

        return mode_of(self.core.last_authority, bool(self.core.core.policy.enabled))

    def _set_policy(self, policy) -> None:
        """Swap the onboard core's AllocationPolicy (called at a step boundary: it holds from this step)."""
        self.core.core.policy = policy
        self.core.policy = policy

    def sim_now(self) -> float:
        """Vehicle sim time now (s): lockstep the current step; realtime the last published step plus the
        wall time since x speed."""
        return self._sim_time_of(time.monotonic())

    def _sim_time_of(self, wall: float) -> float:
        """Sim time (s) of monotonic instant ``wall`` (e.g. a datagram's arrival)."""
        if self.opts.clock == "lockstep" or self._step_wall is None:
            return self.t
        return self._step_t + max(0.0, wall - self._step_wall) * self.opts.speed

    # -- lifecycle -------------------------------------------------------------------------------
    async def start(self) -> None:
        """Bind the sockets: the main one (``--listen``, or the first ``--out`` if it is ``udpin:``) and one
        per further ``udpin:`` output.

        Only datagrams from the outputs' exact ``(host, port)`` are accepted (a ``udpin:`` output: its
        first sender); anything else (another port claiming the GCS's system id, an early copy of a
        genuine packet, ...) is counted, reported and dropped by the endpoint without touching the
        signing state.
        """
        primary, rest = self.specs[0], self.specs[1:]
        fixed = [s.addr for s in rest if not s.listens]
        common = dict(name="daa-vehicle", guard=self.guard)
        if primary.listens:  # --out udpin:HOST:PORT: listen there, answer the first GCS that sends
            self.ep = await open_endpoint(self.codec, primary.addr, peer=None, learn_peer=True, lock_peer=True,
                                          allow_peers=fixed, peer_label="--out udpin: the first GCS that sent",
                                          drop_hint="the vehicle answers only the first GCS that sent to "
                                                    f"{primary.conn.text}", **common)
        else:
            self.ep = await open_endpoint(self.codec, self.listen.addr, peer=primary.addr, learn_peer=False,
                                          allow_peers=[primary.addr] + fixed, peer_label="--out / --tap",
                                          drop_hint="if that is your GCS or shim, give its address as --out "
                                                    "(commands are taken only from the first --out)", **common)
        self.outputs = [Output(primary, self.ep)]
        for s in rest:
            ep = self.ep
            if s.listens:
                ep = await open_endpoint(self.codec, s.addr, peer=None, learn_peer=True, lock_peer=True,
                                         peer_label=f"{s.name}: the first sender",
                                         drop_hint=f"{s.name} ({s.conn.text}) answers only its first sender", **common)
            self.outputs.append(Output(s, ep))
        if self.opts.clock != "lockstep":  # realtime: reads are answered the moment they arrive
            for ep in self.endpoints:
                ep.on_message = partial(self._on_message, ep=ep)

    def dropped(self) -> int:
        """Messages dropped on every socket: codec rejections, unexpected peers, overflow, malformed content."""
        return sum(ep.stats()["dropped"] - ep.guard.total for ep in self.endpoints) + self.guard.total

    @property
    def endpoints(self) -> "list[MavEndpoint]":
        """Every socket of the vehicle, the main one first."""
        eps = [self.ep] if self.ep is not None else []
        return eps + [o.ep for o in self.outputs if o.ep is not self.ep]

    def request_stop(self) -> None:
        """Stop playing: :meth:`run` raises ``asyncio.CancelledError`` at its next step or wait."""
        self.stop_requested = True

    def _check_stop(self) -> None:
        if self.stop_requested:
            raise asyncio.CancelledError("stop requested")

    @property
    def local_address(self) -> str:
        return format_udp_address(self.ep.local_address)

    def close(self) -> None:
        for ep in self.endpoints:
            ep.close()
        if self.live is not None:
            self.live.close()

    # -- receiving -------------------------------------------------------------------------------
    def _link_of(self, addr, ep=None) -> "str | None":
        """The name of the output ``addr`` is on (``gcs``, ``tap``, ``out2``, ...) for a datagram that came in on
        ``ep`` (default: the main socket), or None (someone else)."""
        ep, a = ep or self.ep, tuple(addr)
        for o in self.outputs:
            if o.ep is ep and o.addr is not None and tuple(o.addr) == a:
                return o.name
        return None

    def _on_message(self, r: Received, ep=None) -> None:
        """Realtime: answer reads (parameters, requests, TIMESYNC, ...) the moment they arrive."""
        msg = r.msg
        if msg.get_srcSystem() == VEHICLE_SYSID or not GcsServices.is_read(msg):
            return
        link = self._link_of(r.addr, ep)
        if link is not None:
            self._reply(self.services.read(msg, link), r.addr, ep=ep)

    def _reply(self, msgs: list, addr, count: bool = True, ep=None) -> None:
        if msgs:
            (ep or self.ep).send_many(msgs, addr)
            self.stats.gcs_requests_answered += int(count)

    def take(self, r: Received, ep=None) -> None:
        """:meth:`handle` ``r`` under the guard: if it raises, ``r`` counts as malformed (warned, with counts)
        and nothing else is lost."""
        self.guard.run(partial(self.handle, ep=ep), r)

    def handle(self, r: Received, ep=None) -> None:
        """Process one good message (commands, settings, stock-GCS requests, acks) that came in on ``ep``
        (default: the main socket). Run it through :meth:`take`: content it did not foresee may raise."""
        msg = r.msg
        mtype = msg.get_type()
        link = self._link_of(r.addr, ep)
        if mtype == "SIM_TICK_ACK":
            if link == PILOT_LINK:
                self.clock.answered("gcs", int(msg.tick), self.t)
            return
        if mtype == "SIM_TICK" and msg.get_srcSystem() == VEHICLE_SYSID and link == PILOT_LINK:
            self.stats.tick_echoes += 1  # our own tick, echoed by the shim (one we never sent changes nothing)
            self.clock.answered("shim", int(msg.tick), self.t)
            return
        if msg.get_srcSystem() == VEHICLE_SYSID:
            self.stats.foreign_messages_ignored += 1  # our own sysid echoed back / spoofed
            return
        if link is None:
            self.stats.other_address_ignored += 1
            return
        observer = link != PILOT_LINK
        if not observer:
            self.core.note_gcs_data(self.t)
        if mtype == "SYSTEM_TIME":  # a GCS's send-time stamp for the settings in the same datagram
            self._stamp = (tuple(r.addr), r.t, msg.time_boot_ms / 1000.0)
            return
        if GcsServices.is_read(msg):
            if self.opts.clock == "lockstep":  # realtime: answered on arrival (_on_message)
                self._reply(self.services.read(msg, link), r.addr, ep=ep)
            return
        if GcsServices.is_write(msg):
            stamp = self._stamp
            t_sent = stamp[2] if stamp is not None and stamp[0] == tuple(r.addr) and stamp[1] == r.t else None
            n0 = len(self.services.events)
            self._reply(self.services.write(msg, link, self._sim_time_of(r.t), t_sent), r.addr, ep=ep)
            for ev in self.services.events[n0:]:
                self._announce(ev)
            return
        if mtype in ("PILOT_MANEUVER", "SET_POSITION_TARGET_GLOBAL_INT") or (
                mtype in ("COMMAND_INT", "COMMAND_LONG") and int(msg.command) == M.MAV_CMD_DO_REPOSITION):
            if observer:  # a command must cross the delayed link: only the first --out flies
                self.stats.commands_from_observers_ignored += 1
                if mtype.startswith("COMMAND"):
                    self._reply([M.MAVLink_command_ack_message(msg.command, M.MAV_RESULT_DENIED, 0, 0,
                                                               msg.get_srcSystem(), msg.get_srcComponent())],
                                r.addr, ep=ep)
                return
            self._pilot_command(msg, r)

    def _pilot_command(self, msg, r: Received) -> None:
        mtype = msg.get_type()
        is_cmd = mtype.startswith("COMMAND")
        if is_cmd:
            if msg.target_system not in (0, VEHICLE_SYSID):
                return
            o = self.core.core.own
            cmd = reposition_command(msg, (float(o.x[0]), float(o.y[0]), float(o.z[0])), self.sc.origin,
                                     self._sim_time_of(r.t), msg.get_seq())
        else:
            cmd = setpoint_command(msg, VEHICLE_SYSID)
        if cmd is None or isinstance(cmd, str):
            self.gate.counters.invalid += 1
            if is_cmd:
                self._reply([M.MAVLink_command_ack_message(msg.command, M.MAV_RESULT_DENIED, 0, 0, msg.get_srcSystem(),
                                                           msg.get_srcComponent()),
                             T.statustext(str(cmd)[:50] if cmd else "DO_REPOSITION: invalid")], r.addr)
            return
        ok = self.gate.offer(cmd, self.t)
        if ok:
            self.core.add_command(cmd)
        if cmd.kind == "PILOT_MANEUVER" and ok:  # our dialect acknowledges with its cmd_seq
            self._reply([T.command_ack(PILOT_MANEUVER_ID, M.MAV_RESULT_ACCEPTED, cmd.seq, msg.get_srcSystem(),
                                       msg.get_srcComponent())], r.addr, count=False)
        elif is_cmd:
            self._reply([M.MAVLink_command_ack_message(msg.command, M.MAV_RESULT_ACCEPTED if ok else M.MAV_RESULT_DENIED,
                                                       0, 0, msg.get_srcSystem(), msg.get_srcComponent())], r.addr)
        # SET_POSITION_TARGET_GLOBAL_INT: no COMMAND_ACK (not a command); POSITION_TARGET_GLOBAL_INT is the feedback

    def _announce(self, ev) -> None:
        """A setting write: one console line, and an accepted one as a STATUSTEXT to the other outputs too."""
        sent = f", sent t={ev.t_sent:g}s" if ev.t_sent is not None else ""
        print(f"t={ev.t_applied:5.0f}s {ev.kind} {ev.name} {ev.status}: {ev.reason} (from {ev.link}, "
              f"received t={ev.t_received:.1f}s{sent})", flush=True)
        if ev.status == "accepted":
            for o in self.outputs:
                if o.name != ev.link and o.name != PILOT_LINK and o.addr is not None:
                    o.ep.send_many([T.statustext(ev.reason[:50])], o.addr)

    def _drain(self) -> None:
        """Handle everything received on every socket so far (each message under the guard)."""
        for ep in self.endpoints:
            while True:
                try:
                    r = ep.inbox.get_nowait()
                except asyncio.QueueEmpty:
                    break
                self.take(r, ep if ep is not self.ep else None)

    # -- sending ---------------------------------------------------------------------------------
    def publish(self, t: float, out) -> None:
        """Telemetry for ``t`` (s): per output, one datagram of the messages due on that output's stream."""
        pol = self.core.core.policy
        if self.home is None:
            self.home = T.kin_of(out.own, 0)
        msgs = T.step_messages(self.core, t, out, self.home, agent_enabled=bool(pol.enabled))
        self.latest = msgs
        self._step_t, self._step_wall = t, time.monotonic()
        extra = []
        new_auth = self.core.last_authority
        if new_auth != self.authority:
            self.stats.authority_changes += 1
            extra.append(T.statustext(f"DAA-SIL t={t:.0f}s authority {self.authority}->{new_auth}"
                                      f" ({self.core.last_decision})"))
            self.authority = new_auth
        for o in self.outputs:
            if o.addr is None:  # udpin: nobody has spoken yet
                continue
            due = self.services.link_rates(o.name).due(t)
            batch = [m for mid in STREAMED if mid in due for m in msgs.get(mid, ())]
            o.ep.send_many(batch + extra, o.addr)

    # -- main loop -------------------------------------------------------------------------------
    async def run(self, on_step=None) -> None:
        """Play every step of the scenario (see the module docstring)."""
        loop = asyncio.get_running_loop()
        n = self.core.n_steps
        lockstep = self.opts.clock == "lockstep"
        period = self.core.dt / self.opts.speed
        self.clock.wall0 = loop.time()
        if not lockstep:
            self.clock.sharpen()
        for k in range(n):
            self._check_stop()
            self.k, self.t = k, float(k) * self.core.dt
            if lockstep:
                self._drain()
                await self.clock.await_ready(k, self.t)
            else:
                due = await self.clock.realtime_tick(k, self.t, period)
            self._drain()
            out = self.core.step(self.t)
            if not lockstep:  # computed ahead (inputs complete once the tick is echoed): out at the deadline
                self.timing.ready(1000.0 * (loop.time() - due))
                wait = due - loop.time()
                if wait > 0:
                    await asyncio.sleep(wait)
                self._check_stop()
            self.publish(self.t, out)
            if self.live is not None:
                self.live.send(self.core.rows[-1])  # non-blocking; failures are counted, never raised
            self.stats.steps = k + 1
            if not lockstep:
                self.timing.published(1000.0 * (loop.time() - due), self.stats)
            if on_step is not None:
                on_step(self, out)
            await asyncio.sleep(0)
        if lockstep and n:
            # the GCS ran its last step in parallel: done once it acknowledged it (as every other tick)
            await self.clock.await_ready(n - 1, (n - 1) * self.core.dt, need_ack=True, send=False)

    def write_steplog(self) -> "Path | None":
        """Write the step log so far (atomic Parquet; only the steps published); returns its path or None."""
        if self.opts.steplog is None or self.stats.steps == 0:
            return None
        if self.timing.late_ms:
            self.stats.late_p99_ms = self.timing.p99_ms()
        meta = steplog_meta(self.sc, self.opts, self.core, self.stats, signed=self.codec.signed,
                            gate=self.gate.counters.__dict__, link=self.ep.stats() if self.ep else {},
                            live=self.live.stats.__dict__ if self.live is not None else None,
                            timing=self.timing, wall0=self.clock.wall0, events=self.services.events)
        return self.core.write_steplog(self.opts.steplog, meta, n_rows=self.stats.steps)


