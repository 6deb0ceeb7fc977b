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
from dataclasses import dataclass, field
from pathlib import Path

from daa_sil.errors import DaaSilError
from daa_sil.link.codec import CONTROL_LINK_ID, MavCodec
from daa_sil.link.codec import mavlink as M
from daa_sil.link.endpoint import MavEndpoint, Received, format_udp_address, open_endpoint, parse_udp_address

from . import telemetry as T
from .commands import CommandGate, PilotCommand
from .core import VehicleCore

VEHICLE_SYSID, VEHICLE_COMPID = 1, 1
AUTOPILOT_VERSION_ID = 148
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


@dataclass
class VehicleStats:
    steps: int = 0
    ticks_sent: int = 0
    tick_retries: int = 0
    gcs_requests_answered: int = 0
    commands_from_tap_ignored: int = 0
    foreign_messages_ignored: int = 0
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
        self.peer = parse_udp_address(opts.out, "--out", allow_port_zero=False)
        self.tap = parse_udp_address(opts.tap, "--tap", allow_port_zero=False) if opts.tap else None
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
        self.live = None
        if opts.live:
            from daa_sil.live import LiveSender

            self.live = LiveSender(opts.live)

    # -- lifecycle -------------------------------------------------------------------------------
    async def start(self) -> None:
        """Bind the listen socket; the peer (``--out``) is fixed, the tap only observes.

        Only datagrams from the peer's and the tap's exact ``(host, port)`` are accepted; anything
        else (another port claiming the GCS's system id, an early copy of a genuine packet, ...)
        is counted and dropped by the endpoint without touching the signing state.
        """
        allow = [self.peer] + ([self.tap] if self.tap is not None else [])
        self.ep = await open_endpoint(self.codec, self.opts.listen, peer=self.peer, learn_peer=False,
                                      allow_peers=allow)

    @property
    def local_address(self) -> str:
        return format_udp_address(self.ep.local_address)

    def close(self) -> None:
        if self.ep is not None:
            self.ep.close()
        if self.live is not None:
            self.live.close()

    # -- receiving -------------------------------------------------------------------------------
    def _is_tap(self, addr) -> bool:
        return self.tap is not None and tuple(addr) == tuple(self.tap) and tuple(addr) != tuple(self.peer)

    def handle(self, r: Received) -> None:
        """Process one good message (commands, stock-GCS requests, acks); never raises on content."""
        msg = r.msg
        mtype = msg.get_type()
        if mtype == "SIM_TICK_ACK":
            if not self._is_tap(r.addr):
                self._acked = max(self._acked, int(msg.tick)) if int(msg.tick) <= self.k else self._acked
            return
        if msg.get_srcSystem() == VEHICLE_SYSID:
            self.stats.foreign_messages_ignored += 1  # our own sysid echoed back / spoofed
            return
        from_tap = self._is_tap(r.addr)
        if not from_tap:
            self.core.note_gcs_data(self.t)
        if mtype in ("PILOT_MANEUVER", "SET_POSITION_TARGET_GLOBAL_INT"):
            if from_tap:
                self.stats.commands_from_tap_ignored += 1
                return
            cmd = self._command_from(msg)
            if cmd is None:
                self.gate.counters.invalid += 1
                return
            if self.gate.offer(cmd, self.t):
                self.core.add_command(cmd)
                cid = PILOT_MANEUVER_ID if cmd.kind == "PILOT_MANEUVER" else SET_POS_GLOBAL_ID
                self._send([T.command_ack(cid, M.MAV_RESULT_ACCEPTED, cmd.seq, msg.get_srcSystem(),
                                          msg.get_srcComponent())], r.addr)
        elif mtype == "COMMAND_LONG":
            self._answer_command_long(msg, r.addr)
        elif mtype == "PARAM_REQUEST_LIST":
            self._send([M.MAVLink_param_value_message(b"DAA_SIL_VER", 1.0, M.MAV_PARAM_TYPE_REAL32, 1, 0)], r.addr)
            self.stats.gcs_requests_answered += 1
        elif mtype == "MISSION_REQUEST_LIST":
            self._send([M.MAVLink_mission_count_message(msg.get_srcSystem(), msg.get_srcComponent(), 0,
                                                        getattr(msg, "mission_type", 0))], r.addr)
            self.stats.gcs_requests_answered += 1

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

    def _answer_command_long(self, msg, addr) -> None:
        """Minimal answers to a stock GCS (mavlink_spec §6): AUTOPILOT_VERSION, else UNSUPPORTED."""
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        if msg.target_system not in (0, VEHICLE_SYSID):
            return
        out = []
        if msg.command == M.MAV_CMD_REQUEST_MESSAGE and int(msg.param1) == AUTOPILOT_VERSION_ID:
            out.append(M.MAVLink_command_ack_message(msg.command, M.MAV_RESULT_ACCEPTED, 0, 0, *src))
            out.append(M.MAVLink_autopilot_version_message(M.MAV_PROTOCOL_CAPABILITY_MAVLINK2, 0, 0, 0, 0,
                                                           [0] * 8, [0] * 8, [0] * 8, 0, 0, 0))
        else:
            out.append(M.MAVLink_command_ack_message(msg.command, M.MAV_RESULT_UNSUPPORTED, 0, 0, *src))
        self._send(out, addr)
        self.stats.gcs_requests_answered += 1

    def _drain(self) -> None:
        while True:
            try:
                r = self.ep.inbox.get_nowait()
            except asyncio.QueueEmpty:
                return
            self.handle(r)

    # -- sending ---------------------------------------------------------------------------------
    def _send(self, msgs: list, addr=None) -> None:
        self.ep.send_many(msgs, addr or self.peer)

    def _send_tick(self, k: int, t: float) -> None:
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
                    f"running with --clock lockstep and is {format_udp_address(self.peer)} a lockstep shim or the GCS?")
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
        """Telemetry for ``t`` (s): one datagram to the peer (and the same to the tap)."""
        msgs = self.core.telemetry_messages(t, out)
        new_auth = self.core.last_authority
        if new_auth != self.authority:
            self.stats.authority_changes += 1
            msgs.append(T.statustext(f"DAA-SIL t={t:.0f}s authority {self.authority}->{new_auth}"
                                     f" ({self.core.last_decision})"))
            self.authority = new_auth
        self._send(msgs)
        if self.tap is not None:
            self.ep.send_many(msgs, self.tap)

    # -- main loop -------------------------------------------------------------------------------
    async def run(self, on_step=None) -> None:
        """Play every step of the scenario (see the module docstring)."""
        loop = asyncio.get_running_loop()
        n = self.core.n_steps
        lockstep = self.opts.clock == "lockstep"
        if not lockstep:  # say hello so a direct GCS learns our address before the first step
            self._send([T.heartbeat("pilot")])
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
        return self.core.write_steplog(self.opts.steplog, meta)
