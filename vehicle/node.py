"""The asyncio vehicle node: one :class:`daa_sil.onboard.OnboardCore` (N = 1) behind a MAVLink endpoint.

Per step ``k`` (``t_k = k`` s, ``docs/architecture.md`` "The step order"):

* **lockstep**: send ``SIM_TICK(k, t_k)`` alone in its datagram to the peer (the shim), then
  receive until the shim echoes it: the shim processes tick ``k`` (releases every packet due at
  ``t_k``, forwards the tick to the GCS, echoes it) only once the GCS acknowledged tick ``k - 1``,
  so the GCS's step ``k`` and this step ``k`` run in parallel -- neither reads the other's output
  of the same tick, which the shim releases at tick ``k + 1`` at the earliest
  (:meth:`vehicle.ticks.TickClock._lockstep_ready`).
  Tick 0 and the end of the run wait for the GCS's ``SIM_TICK_ACK``; wired straight to a GCS (no
  shim, no echo) every tick does. No answer within ``tick_timeout_s`` wall seconds ->
  :class:`vehicle.ticks.TickTimeout` (one clear line). The tick is re-sent every ``tick_retry_s``
  in case a datagram was lost (the GCS re-acks a tick it already did).
* **realtime**: the same ticks, paced by the wall clock instead of waiting for the GCS (see
  ``docs/sil.md``, "Realtime and lockstep"). ``SIM_TICK(k)`` goes out a lead of half a step
  (at most 0.25 s) before the step's deadline ``W_k = t0 + t_k / speed``; the shim releases
  everything due at ``t_k``, forwards the tick to the GCS (which steps on it) and echoes it back.
  Once the echo is in, every input of step ``k`` is there (uplink is released only at ticks), so
  the vehicle computes the step then and publishes it at ``W_k``; it waits at most half a step
  past ``W_k`` for a late echo, so every step sees exactly what the lockstep step sees. Partner = the shim (it echoes) or, wired straight to a GCS, the GCS (it acks); a
  peer that answers no tick (a stock GCS) gives free-running realtime with no waiting.
  ``tick_sync="wait"`` (what ``daa-sil run`` uses) starts the clock only once tick 0 is
  acknowledged, so the GCS plays from step 0 as in lockstep. A partner silent for 3 s is
  reported (stderr) and no longer waited for until it answers again; steps that ran without
  their confirmation are counted (``steps_unconfirmed``: 0 means lockstep-equivalent input).

Then ``OnboardCore.step(t_k, pilot input)`` decides, the telemetry for ``t_k`` is published (one
datagram to the peer, and the same undelayed to the observer ``tap`` if set), a step-log row is
kept (and, with ``live``, sent at once to the Rerun recorder's loopback feed, fire-and-forget:
:class:`daa_sil.sil.live.LiveSender`), and truth advances. The step log is written atomically at the end, on Ctrl-C and on
SIGTERM (:meth:`VehicleNode.write_steplog`).

Hostile input: the endpoint/codec count and drop malformed, forged and replayed packets; the
:class:`~vehicle.commands.CommandGate` drops duplicate, older, future-stamped and invalid pilot
commands; commands from the tap address are ignored (it may only observe). Link liveness for the
agent counts only **data** from the GCS (HEARTBEAT, commands), never the lockstep control
messages, which bypass the delay line.
"""

from __future__ import annotations

import asyncio
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

from daa_sil.link.codec import MavCodec
from daa_sil.link.codec import mavlink as M
from daa_sil.sil.connstr import LISTEN, SEND, parse_connection
from daa_sil.sil.endpoint import MavEndpoint, Received, _norm_host, format_udp_address, open_endpoint

from . import telemetry as T
from .commands import CommandGate, PilotCommand, reposition_command
from .core import VehicleCore
from .params import ParamTable
from .services import GcsServices
from .streams import STREAMED
from vehicle.ticks import TickClock
from vehicle.node_steplog import StepLogWriter

VEHICLE_SYSID, VEHICLE_COMPID = 1, 1
PILOT_MANEUVER_ID = M.MAVLINK_MSG_ID_PILOT_MANEUVER
#: SET_POSITION_TARGET_GLOBAL_INT type_mask bits that must be clear for a velocity setpoint
_VEL_IGNORE = (M.POSITION_TARGET_TYPEMASK_VX_IGNORE | M.POSITION_TARGET_TYPEMASK_VY_IGNORE
               | M.POSITION_TARGET_TYPEMASK_VZ_IGNORE)


@dataclass
class VehicleOptions:
    """Runtime options of the vehicle node (addresses ``udp:HOST:PORT``; timeouts in wall s)."""

    out: str = "udp:127.0.0.1:14550"
    listen: str = "udp:127.0.0.1:0"
    tap: "str | None" = None
    clock: str = "realtime"
    speed: float = 1.0
    key: "bytes | None" = None
    steplog: "Path | None" = None
    tick_timeout_s: float = 10.0
    tick_retry_s: float = 2.0
    #: wall seconds to wait for the answer to tick 0 (the partner may still be starting); None = tick_timeout_s
    start_timeout_s: "float | None" = None
    #: ``udp:127.0.0.1:PORT``: publish each step's step-log row there (:mod:`daa_sil.sil.live`)
    live: "str | None" = None
    #: ``--waitmap``: map preset, grid spec or family directory (None = the default map)
    waitmap: "str | None" = None
    #: ``--config``: a :class:`daa_sil.config.run_config.RunConfig` (None = the scenario alone)
    config: "object | None" = None
    #: let the (undelayed) tap set parameters and modes; by default it may only read
    tap_writable: bool = False
    #: realtime: "auto" (start at once, wait for tick answers only from a partner that gives them) or
    #: "wait" (start the clock once tick 0 is acknowledged; error after tick_timeout_s)
    tick_sync: str = "auto"
    #: called once with the wall (``time.monotonic``) instant of step 0's deadline when the clock starts
    on_clock_start: "object | None" = None


@dataclass
class VehicleStats:
    steps: int = 0
    ticks_sent: int = 0
    tick_retries: int = 0
    gcs_requests_answered: int = 0
    commands_from_tap_ignored: int = 0
    foreign_messages_ignored: int = 0
    #: ``--out udpin:``: messages from an address other than the learned GCS (or the tap), dropped
    other_address_ignored: int = 0
    authority_changes: int = 0
    #: realtime: how late each step's telemetry went out after its due wall time ``W_k``, ms
    late_mean_ms: float = 0.0
    late_max_ms: float = 0.0
    late_p99_ms: float = 0.0
    #: ticks the shim echoed back (it is alive, and the uplink due at that tick was sent)
    tick_echoes: int = 0
    #: realtime: who confirms ticks: "shim" (echoes), "gcs" (acks, no shim between) or "none"
    sync_partner: str = "none"
    #: realtime: steps that ran before their tick was confirmed (0 = each step saw what lockstep sees)
    steps_unconfirmed: int = 0
    #: realtime: ticks the GCS acknowledged only after the next tick had gone out
    acks_late: int = 0
    #: warnings printed because the shim or the GCS stopped answering ticks
    silence_warnings: int = 0
    extra: dict = field(default_factory=dict)


class VehicleNode(StepLogWriter, TickClock):
    """The vehicle process logic around a :class:`vehicle.core.VehicleCore`.

    ``await node.start()`` binds the socket; ``await node.run()`` plays every step;
    ``node.write_steplog()`` writes what was simulated so far (safe to call more than once).
    """

    def __init__(self, scenario, opts: VehicleOptions, core: "VehicleCore | None" = None):
        self.sc = scenario
        self.opts = opts
        self.core = core if core is not None else VehicleCore(scenario, waitmap=opts.waitmap, config=opts.config)
        self.out = parse_connection(opts.out, "--out", SEND)
        self.listen = parse_connection(opts.listen, "--listen", LISTEN, allow=(LISTEN,))
        tap = parse_connection(opts.tap, "--tap", SEND, allow=(SEND,)).addr if opts.tap else None
        # numeric hosts, so they compare equal to the addresses datagrams come from ("localhost" -> 127.0.0.1)
        self.tap = (_norm_host(tap[0]), tap[1]) if tap is not None else None
        self._peer = None if self.out.listens else (_norm_host(self.out.addr[0]), self.out.addr[1])
        self.codec = MavCodec(VEHICLE_SYSID, VEHICLE_COMPID, key=opts.key, allow_unsigned=())
        self.ep: "MavEndpoint | None" = None
        self.gate = CommandGate()
        self.stats = VehicleStats()
        self.k = 0
        self.t = 0.0
        self.authority = "pilot"
        self._acked = -1
        self._echoed = -1  # highest tick the shim echoed back
        self._tick_sent_k = -1
        self._last_answer = {"shim": None, "gcs": None}  # wall time (loop clock) of the last echo / ack
        self._silent = {"shim": False, "gcs": False}
        self._steplog_written = False
        #: set by :meth:`request_stop` (SIGINT / SIGTERM): the loop stops at the next step or wait even if
        #: the task's cancellation was lost (Python 3.11's ``asyncio.wait_for`` can swallow a cancel that
        #: arrives together with the awaited message)
        self.stop_requested = False
        self._late_sum_ms = 0.0
        self._lates: list = []  # realtime: per-step lateness (ms)
        self._ready: list = []  # realtime: when each step's computation was done, ms after its deadline
        self._step_t, self._step_wall = 0.0, None  # sim and monotonic time of the last publish
        self._stamp = None  # (addr, datagram time, t_sent) of the GCS's last SYSTEM_TIME
        self.home: "T.Kin | None" = None
        self.latest: dict = {}
        self.services = GcsServices(ParamTable(scenario.thresholds), lambda: self.core.core.policy, self._set_policy,
                                    lambda: self.latest, self.sim_now, dt=self.core.dt, tap_writable=opts.tap_writable,
                                    step_t=lambda: self.t, current_mode=self._mode_now)
        self.live = None
        if opts.live:
            from daa_sil.sil.live import LiveSender

            self.live = LiveSender(opts.live)

    @property
    def peer(self):
        """The GCS side (``--out``): fixed, or with ``--out udpin:`` the first address that sent a good message."""
        if self._peer is None and self.ep is not None and self.ep.peer is not None:
            self._peer = tuple(self.ep.peer)
        return self._peer

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
        """Bind the listen socket; the peer (``--out``) is fixed, the tap only observes.

        Only datagrams from the peer's and the tap's exact ``(host, port)`` are accepted; anything
        else (another port claiming the GCS's system id, an early copy of a genuine packet, ...)
        is counted and dropped by the endpoint without touching the signing state.
        """
        on_msg = self._on_message if self.opts.clock != "lockstep" else None
        if self.out.listens:  # --out udpin:HOST:PORT: listen there, answer the first GCS that sends
            self.ep = await open_endpoint(self.codec, self.out.addr, peer=None, learn_peer=True, on_message=on_msg,
                                          name="daa-vehicle")
            return
        allow = [self.peer] + ([self.tap] if self.tap is not None else [])
        self.ep = await open_endpoint(self.codec, self.listen.addr, peer=self.peer, learn_peer=False,
                                      allow_peers=allow, on_message=on_msg, name="daa-vehicle",
                                      peer_label="--out / --tap",
                                      drop_hint="if that is your GCS or shim, give its address as --out "
                                                "(commands are taken only from --out)")

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
        if self.ep is not None:
            self.ep.close()
        if self.live is not None:
            self.live.close()

    # -- receiving -------------------------------------------------------------------------------
    def _link_of(self, addr) -> "str | None":
        """``"gcs"`` (the --out peer), ``"tap"`` or None (``--out udpin:``: someone else)."""
        a = tuple(addr)
        if self.peer is not None and a == tuple(self.peer):
            return "gcs"
        if self.tap is not None and a == tuple(self.tap):
            return "tap"
        return None

    def _on_message(self, r: Received) -> None:
        """Realtime: answer reads (parameters, requests, TIMESYNC, ...) the moment they arrive."""
        msg = r.msg
        if msg.get_srcSystem() == VEHICLE_SYSID or not GcsServices.is_read(msg):
            return
        link = self._link_of(r.addr)
        if link is not None:
            self._reply(self.services.read(msg, link), r.addr)

    def _reply(self, msgs: list, addr, count: bool = True) -> None:
        if msgs:
            self.ep.send_many(msgs, addr)
            self.stats.gcs_requests_answered += int(count)

    def handle(self, r: Received) -> None:
        """Process one good message (commands, settings, stock-GCS requests, acks); never raises on content."""
        msg = r.msg
        mtype = msg.get_type()
        link = self._link_of(r.addr)
        if mtype == "SIM_TICK_ACK":
            if link == "gcs" and int(msg.tick) <= self._tick_sent_k:
                if int(msg.tick) > self._acked:
                    self._acked = int(msg.tick)
                    self._answered("gcs")
            return
        if mtype == "SIM_TICK" and msg.get_srcSystem() == VEHICLE_SYSID and link == "gcs":
            self.stats.tick_echoes += 1  # our own tick, echoed by the shim (one we never sent changes nothing)
            if int(msg.tick) <= self._tick_sent_k:
                if int(msg.tick) > self._echoed:
                    self._echoed = int(msg.tick)
                    self._answered("shim")
            return
        if msg.get_srcSystem() == VEHICLE_SYSID:
            self.stats.foreign_messages_ignored += 1  # our own sysid echoed back / spoofed
            return
        if link is None:
            self.stats.other_address_ignored += 1
            return
        from_tap = link == "tap"
        if not from_tap:
            self.core.note_gcs_data(self.t)
        if mtype == "SYSTEM_TIME":  # a GCS's send-time stamp for the settings in the same datagram
            self._stamp = (tuple(r.addr), r.t, msg.time_boot_ms / 1000.0)
            return
        if GcsServices.is_read(msg):
            if self.opts.clock == "lockstep":  # realtime: answered on arrival (_on_message)
                self._reply(self.services.read(msg, link), r.addr)
            return
        if GcsServices.is_write(msg):
            stamp = self._stamp
            t_sent = stamp[2] if stamp is not None and stamp[0] == tuple(r.addr) and stamp[1] == r.t else None
            n0 = len(self.services.events)
            self._reply(self.services.write(msg, link, self._sim_time_of(r.t), t_sent), r.addr)
            for ev in self.services.events[n0:]:
                self._announce(ev)
            return
        if mtype in ("PILOT_MANEUVER", "SET_POSITION_TARGET_GLOBAL_INT") or (
                mtype in ("COMMAND_INT", "COMMAND_LONG") and int(msg.command) == M.MAV_CMD_DO_REPOSITION):
            if from_tap:
                self.stats.commands_from_tap_ignored += 1
                if mtype.startswith("COMMAND"):
                    self._reply([M.MAVLink_command_ack_message(msg.command, M.MAV_RESULT_DENIED, 0, 0,
                                                               msg.get_srcSystem(), msg.get_srcComponent())], r.addr)
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
            cmd = self._command_from(msg)
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
        """A setting write: one console line, and a STATUSTEXT to the observer too."""
        sent = f", sent t={ev.t_sent:g}s" if ev.t_sent is not None else ""
        print(f"t={ev.t_applied:5.0f}s {ev.kind} {ev.name} {ev.status}: {ev.reason} (from {ev.link}, "
              f"received t={ev.t_received:.1f}s{sent})", flush=True)
        if ev.status == "accepted" and self.tap is not None and ev.link != "tap":
            self.ep.send_many([T.statustext(ev.reason[:50])], self.tap)

    def _command_from(self, msg) -> "PilotCommand | None":
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        if msg.get_type() == "PILOT_MANEUVER":
            if msg.target_system not in (0, VEHICLE_SYSID):
                return None
            return PilotCommand(msg.time_boot_ms / 1000.0, int(msg.cmd_seq), float(msg.track_deg), float(msg.vs),
                                float(msg.gs), src, "PILOT_MANEUVER")
        # stock GCS: SET_POSITION_TARGET_GLOBAL_INT velocity setpoint (NED m/s) -> track/vs/gs
        if msg.target_system not in (0, VEHICLE_SYSID) or msg.type_mask & _VEL_IGNORE:
            return None
        vn, ve, vd = float(msg.vx), float(msg.vy), float(msg.vz)
        if not all(math.isfinite(v) for v in (vn, ve, vd)):
            return None
        gs = math.hypot(vn, ve)
        trk = math.degrees(math.atan2(ve, vn)) % 360.0 if gs > 0.5 else math.nan
        return PilotCommand(msg.time_boot_ms / 1000.0, 0, trk, -vd, gs if gs > 0.5 else math.nan, src,
                            "SET_POSITION_TARGET_GLOBAL_INT")

    def _drain(self) -> None:
        while True:
            try:
                r = self.ep.inbox.get_nowait()
            except asyncio.QueueEmpty:
                return
            self.handle(r)

    # -- sending ---------------------------------------------------------------------------------
    def _send(self, msgs: list, addr=None) -> None:
        dest = addr or self.peer
        if dest is not None:  # --out udpin: nobody to send to before a GCS has spoken
            self.ep.send_many(msgs, dest)

    def publish(self, t: float, out) -> None:
        """Telemetry for ``t`` (s): per link (peer, tap), one datagram of the messages due on that link."""
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
        for link, addr in (("gcs", self.peer), ("tap", self.tap)):
            if addr is None:
                continue
            due = self.services.link_rates(link).due(t)
            batch = [m for mid in STREAMED if mid in due for m in msgs.get(mid, ())]
            self.ep.send_many(batch + extra, addr)

    # -- main loop -------------------------------------------------------------------------------
    async def run(self, on_step=None) -> None:
        """Play every step of the scenario (see the module docstring)."""
        loop = asyncio.get_running_loop()
        n = self.core.n_steps
        lockstep = self.opts.clock == "lockstep"
        period = self.core.dt / self.opts.speed
        self._wall0 = loop.time()
        if not lockstep:
            # like the shim: wake at the deadline without timer coalescing, and ask for a short EEVDF
            # slice so a woken vehicle preempts sooner on a busy machine (unprivileged; no-op elsewhere)
            import os

            from daa_sil.sil.rtclock import request_short_slice, set_timer_slack

            self.stats.extra["timer_slack_1us"] = set_timer_slack(1000)
            # DAA_SIL_VEHICLE_SLICE_US: the slice asked for (0 = keep the default; benchmarks compare both)
            slice_us = float(os.environ.get("DAA_SIL_VEHICLE_SLICE_US", "100") or 0)
            self.stats.extra["short_slice"] = request_short_slice(slice_us * 1e-6) if slice_us > 0 else False
        for k in range(n):
            self._check_stop()
            self.k, self.t = k, float(k) * self.core.dt
            if lockstep:
                self._drain()
                await self._await_ack(k, self.t)
            else:
                due = await self._realtime_tick(k, self.t, period)
            self._drain()
            out = self.core.step(self.t)
            if not lockstep:  # computed ahead (inputs complete once the tick is echoed): out at the deadline
                self._ready.append(1000.0 * (loop.time() - due))
                wait = due - loop.time()
                if wait > 0:
                    await asyncio.sleep(wait)
                self._check_stop()
            self.publish(self.t, out)
            if self.live is not None:
                self.live.send(self.core.rows[-1])  # non-blocking; failures are counted, never raised
            self.stats.steps = k + 1
            if not lockstep:
                late = 1000.0 * (loop.time() - due)
                self.stats.late_max_ms = round(max(self.stats.late_max_ms, late), 3)
                self._late_sum_ms += late
                self.stats.late_mean_ms = round(self._late_sum_ms / (k + 1), 3)
                self._lates.append(late)
            if on_step is not None:
                on_step(self, out)
            await asyncio.sleep(0)
        if lockstep and n:
            # the GCS ran its last step in parallel: done once it acknowledged it (as every other tick)
            await self._await_ack(n - 1, (n - 1) * self.core.dt, need_ack=True, send=False)


