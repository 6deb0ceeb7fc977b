"""The asyncio vehicle node: one :class:`daa_sil.onboard.OnboardCore` (N = 1) behind a MAVLink endpoint.

Per step ``k`` (``t_k = k`` s, ``docs/architecture.md`` "The step order"):

* **lockstep**: send ``SIM_TICK(k, t_k)`` alone in its datagram to the peer (the shim), then
  receive until ``SIM_TICK_ACK(k)`` arrives (the shim forwards it after releasing every packet due
  at ``t_k`` and queueing the GCS's step-k commands). No ack within ``tick_timeout_s`` wall
  seconds -> :class:`TickTimeout` (one clear line). The tick is re-sent every ``tick_retry_s``
  in case a datagram was lost (the GCS re-acks a tick it already did).
* **realtime**: sleep until wall ``t0 + t_k / speed``; whatever arrived by then is used.

Then ``OnboardCore.step(t_k, pilot input)`` decides, the telemetry for ``t_k`` is published (one
datagram to the peer, and the same undelayed to the observer ``tap`` if set), a step-log row is
kept (and, with ``live``, sent at once to the Rerun recorder's loopback feed, fire-and-forget:
:class:`daa_sil.live.LiveSender`), and truth advances. The step log is written atomically at the end, on Ctrl-C and on
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

from daa_sil.errors import DaaSilError
from daa_sil.link.codec import CONTROL_LINK_ID, MavCodec
from daa_sil.link.codec import mavlink as M
from daa_sil.link.connstr import LISTEN, SEND, parse_connection
from daa_sil.link.endpoint import MavEndpoint, Received, _norm_host, format_udp_address, open_endpoint

from . import telemetry as T
from .commands import CommandGate, PilotCommand, reposition_command
from .core import VehicleCore
from .params import ParamTable
from .services import GcsServices
from .streams import STREAMED

VEHICLE_SYSID, VEHICLE_COMPID = 1, 1
PILOT_MANEUVER_ID = M.MAVLINK_MSG_ID_PILOT_MANEUVER
SET_POS_GLOBAL_ID = M.MAVLINK_MSG_ID_SET_POSITION_TARGET_GLOBAL_INT
#: SET_POSITION_TARGET_GLOBAL_INT type_mask bits that must be clear for a velocity setpoint
_VEL_IGNORE = (M.POSITION_TARGET_TYPEMASK_VX_IGNORE | M.POSITION_TARGET_TYPEMASK_VY_IGNORE
               | M.POSITION_TARGET_TYPEMASK_VZ_IGNORE)


class TickTimeout(DaaSilError):
    """The lockstep partner did not acknowledge a tick in time."""


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
    #: ``udp:127.0.0.1:PORT``: publish each step's step-log row there (:mod:`daa_sil.live`)
    live: "str | None" = None
    #: ``--waitmap``: map preset, grid spec or family directory (None = the default map)
    waitmap: "str | None" = None
    #: let the (undelayed) tap set parameters and modes; by default it may only read
    tap_writable: bool = False


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
    #: realtime: how late each step was done (telemetry and live row sent) after its due wall time, ms
    late_mean_ms: float = 0.0
    late_max_ms: float = 0.0
    extra: dict = field(default_factory=dict)


class VehicleNode:
    """The vehicle process logic around a :class:`vehicle.core.VehicleCore`.

    ``await node.start()`` binds the socket; ``await node.run()`` plays every step;
    ``node.write_steplog()`` writes what was simulated so far (safe to call more than once).
    """

    def __init__(self, scenario, opts: VehicleOptions, core: "VehicleCore | None" = None):
        self.sc = scenario
        self.opts = opts
        self.core = core if core is not None else VehicleCore(scenario, waitmap=opts.waitmap)
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
        self._steplog_written = False
        self._late_sum_ms = 0.0
        self._step_t, self._step_wall = 0.0, None  # sim and monotonic time of the last publish
        self._stamp = None  # (addr, datagram time, t_sent) of the GCS's last SYSTEM_TIME
        self.home: "T.Kin | None" = None
        self.latest: dict = {}
        self.services = GcsServices(ParamTable(scenario.thresholds), lambda: self.core.core.policy, self._set_policy,
                                    lambda: self.latest, self.sim_now, dt=self.core.dt, tap_writable=opts.tap_writable,
                                    step_t=lambda: self.t, current_mode=self._mode_now)
        self.live = None
        if opts.live:
            from daa_sil.live import LiveSender

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
            self.ep = await open_endpoint(self.codec, self.out.addr, peer=None, learn_peer=True, on_message=on_msg)
            return
        allow = [self.peer] + ([self.tap] if self.tap is not None else [])
        self.ep = await open_endpoint(self.codec, self.listen.addr, peer=self.peer, learn_peer=False,
                                      allow_peers=allow, on_message=on_msg)

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

    def _is_tap(self, addr) -> bool:
        return self._link_of(addr) == "tap"

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
            if link == "gcs":
                self._acked = max(self._acked, int(msg.tick)) if int(msg.tick) <= self.k else self._acked
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

    def _send_tick(self, k: int, t: float) -> None:
        if self.peer is None:  # --out udpin: no GCS yet; the retry sends it once one has spoken
            return
        data = self.codec.encode(M.MAVLink_sim_tick_message(k, T.time_ms(t)),
                                 link_id=CONTROL_LINK_ID if self.codec.signed else None)
        self.ep.transport.sendto(data, self.peer)
        self.stats.ticks_sent += 1

    async def _await_ack(self, k: int, t: float) -> None:
        loop = asyncio.get_running_loop()
        deadline = loop.time() + self.opts.tick_timeout_s
        retry = self.opts.tick_retry_s if k > 0 else min(0.2, self.opts.tick_retry_s)  # GCS may still start
        next_retry = loop.time() + retry
        self._send_tick(k, t)
        while self._acked < k:
            now = loop.time()
            if now >= deadline:
                raise TickTimeout(
                    f"no SIM_TICK_ACK for tick {k} (t = {t:g} s) within {self.opts.tick_timeout_s:g} s: is the GCS "
                    f"running with --clock lockstep and is {self.out.text} a lockstep shim or the GCS?")
            try:
                r = await asyncio.wait_for(self.ep.inbox.get(), min(deadline, next_retry) - now)
            except asyncio.TimeoutError:
                if loop.time() >= next_retry and loop.time() < deadline:
                    self._send_tick(k, t)
                    self.stats.tick_retries += 1
                    next_retry = loop.time() + retry
                continue
            self.handle(r)

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
        if not lockstep:  # say hello so a direct GCS learns our address before the first step
            self._send([T.heartbeat("pilot", bool(self.core.core.policy.enabled))])
        wall0 = loop.time()
        for k in range(n):
            self.k, self.t = k, float(k) * self.core.dt
            if lockstep:
                self._drain()
                await self._await_ack(k, self.t)
            else:
                delay = wall0 + self.t / self.opts.speed - loop.time()
                if delay > 0:
                    await asyncio.sleep(delay)
            self._drain()
            out = self.core.step(self.t)
            self.publish(self.t, out)
            if self.live is not None:
                self.live.send(self.core.rows[-1])  # non-blocking; failures are counted, never raised
            self.stats.steps = k + 1
            if not lockstep:
                late = 1000.0 * (loop.time() - (wall0 + self.t / self.opts.speed))
                self.stats.late_max_ms = round(max(self.stats.late_max_ms, late), 3)
                self._late_sum_ms += late
                self.stats.late_mean_ms = round(self._late_sum_ms / (k + 1), 3)
            if on_step is not None:
                on_step(self, out)
            await asyncio.sleep(0)

    def write_steplog(self) -> "Path | None":
        """Write the step log so far (atomic Parquet); returns its path or None."""
        if self.opts.steplog is None or self.stats.steps == 0:
            return None
        import json

        meta = {"scenario": self.sc.name, "seed": str(self.sc.seed), "preset": self.sc.thresholds,
                "clock": self.opts.clock, "complete": str(self.stats.steps >= self.core.n_steps).lower(),
                "signed": str(self.codec.signed).lower(),
                "gate": json.dumps(self.gate.counters.__dict__, sort_keys=True),
                "link": json.dumps(self.ep.stats() if self.ep else {}, sort_keys=True),
                "vehicle": json.dumps({k: v for k, v in self.stats.__dict__.items() if k != "extra"}, sort_keys=True)}
        if self.live is not None:
            meta["live"] = json.dumps(self.live.stats.__dict__, sort_keys=True)
        # parameter / mode writes: kind, name, old, new, status, link, source, t_received, t_applied, t_sent
        meta["settings"] = json.dumps([e.as_dict() for e in self.services.events], sort_keys=True)
        return self.core.write_steplog(self.opts.steplog, meta)
