"""The vehicle's MAVLink protocol, sans-IO: datagrams in, sends, console lines and step-log rows out.

:class:`VehicleProtocol` never reads a clock or touches a socket (the pattern of h11's
``Connection`` and of :class:`daa_sil.sil.shim_core.ShimCore`). The node (:mod:`vehicle.node`) binds
one socket per :class:`vehicle.ports.Port` and hands each datagram to :meth:`VehicleProtocol.receive`
with the port, the sender and the arrival time; it sends what :meth:`VehicleProtocol.take_sends`
returns and prints what :meth:`VehicleProtocol.take_notices` returns. A test does the same with bytes.

What happens to a message:

* **on arrival** (:meth:`~VehicleProtocol.receive`): the port's :class:`daa_sil.sil.intake.Intake`
  decodes the datagram (address policy, codec, counts); the tick protocol's messages from the pilot
  link (the shim's echo of our SIM_TICK, the GCS's SIM_TICK_ACK) are taken at once
  (:class:`vehicle.tick_rules.TickRules`); reads (:meth:`GcsServices.is_read`) join their peer's
  read queue, settings (PARAM_SET, modes) its settings queue, the pilot link's commands the
  command queue (:mod:`vehicle.peers`: each queue has a byte budget, past which messages are
  dropped and counted as ``dropped_queue``); in realtime the reads are answered at once, within the
  peer's reply budget;
* **at the step boundary** (:meth:`~VehicleProtocol.process`, which the node calls while it waits for
  a tick and before each step): link liveness (data from the pilot link), settings from writable
  links (:class:`vehicle.services.GcsServices`), the pilot's commands through the
  :class:`vehicle.commands.CommandGate` into the simulation (``plant``, a
  :class:`vehicle.core.VehicleCore`), then the reads, each peer within its reply budget per step;
* **each step** (:meth:`~VehicleProtocol.publish`): the step's telemetry, one datagram per output
  with the messages due on that output's rates, and a STATUSTEXT when the authority changes.

Every message's handling runs under ``guard`` (:class:`daa_sil.sil.msgguard.MessageGuard`): one that
raises is counted as malformed and the rest of its datagram is still handled. Link liveness for the
agent counts only **data** from the GCS, never the tick messages, which bypass the delay line.
"""

from __future__ import annotations

from collections import deque
from functools import partial

from daa_sil.link.codec import MavCodec
from daa_sil.link.codec import mavlink as M
from daa_sil.sil.intake import Address, Received
from daa_sil.sil.lockstep import TickPeer
from daa_sil.sil.msgguard import MessageGuard
from daa_sil.sil.outputs import PILOT_LINK, OutputSpec

from . import telemetry as T
from .commands import CommandGate, reposition_command, setpoint_command
from .node_options import VehicleStats
from .params import ParamTable
from .peers import FULL, wire_size
from .ports import MAIN, Notice, OutputLink, Port, Send, open_ports
from .services import GcsServices, SettingEvent
from .streams import STREAMED
from .tick_rules import TickOptions, TickRules

__all__ = ["VehicleProtocol", "Send", "Notice", "OutputLink", "Port", "MAIN", "VEHICLE_SYSID", "VEHICLE_COMPID"]

VEHICLE_SYSID, VEHICLE_COMPID = 1, 1
PILOT_MANEUVER_ID = M.MAVLINK_MSG_ID_PILOT_MANEUVER
#: wire bytes of the pilot's commands waiting for the step boundary (a GCS sends about one a step)
COMMAND_QUEUE_BYTES = 64 * 1024
#: setting writes printed per step (a flood of PARAM_SET is summed up in one line instead)
ANNOUNCED_PER_STEP = 20


def is_pilot_command(msg) -> bool:
    """PILOT_MANEUVER, SET_POSITION_TARGET_GLOBAL_INT, or a COMMAND_INT / COMMAND_LONG DO_REPOSITION."""
    mtype = msg.get_type()
    return mtype in ("PILOT_MANEUVER", "SET_POSITION_TARGET_GLOBAL_INT") or (
        mtype in ("COMMAND_INT", "COMMAND_LONG") and int(msg.command) == M.MAV_CMD_DO_REPOSITION)


class VehicleProtocol:
    """The vehicle's protocol (see the module docstring).

    ``plant``: the simulation (a :class:`vehicle.core.VehicleCore`: policy, mode, commands, telemetry);
    ``specs``: the outputs (the first is the pilot's link), hosts resolved; ``listen``: the main
    socket's address when the first output does not listen itself; ``ticks``: the tick settings.
    """

    def __init__(self, plant, specs: "list[OutputSpec]", listen: Address, codec: MavCodec, ticks: TickOptions, *,
                 guard: "MessageGuard | None" = None, out_text: str = ""):
        self.plant = plant
        self.codec = codec
        self.lockstep = ticks.clock == "lockstep"
        self.speed = ticks.speed
        self.guard = guard if guard is not None else MessageGuard("daa-vehicle")
        self.stats = VehicleStats()
        self.gate = CommandGate()
        self.dt = float(plant.dt)
        writable = frozenset(s.name for s in specs if s.writable or s.name == PILOT_LINK)
        self.services = GcsServices(ParamTable(plant.sc.thresholds), plant, dt=self.dt, writable=writable)
        self.ticks = TickRules(TickPeer("vehicle", codec), ticks, self.dt, self.stats, out_text or specs[0].conn.text)
        self.ports, self.outputs = open_ports(specs, listen, codec, self.guard, self.dt)
        self.k, self.t = 0, 0.0
        self.authority = "pilot"
        self.home: "T.Kin | None" = None
        self.latest: dict = {}  #: the newest step's telemetry ``{msg_id: [messages]}``
        self._step_t, self._step_wall = 0.0, None  # sim and wall time of the last publish
        self.commands: "deque[tuple[Received, int]]" = deque()  #: the pilot link's commands and their sizes
        self.command_bytes = 0
        self._gcs_data = False  # data from the pilot link since the last step boundary
        self._stamp: "tuple | None" = None  # (sender, t_sent) of a SYSTEM_TIME in the datagram being read
        self._sends: "list[Send]" = []
        self._notices: "list[Notice]" = []
        self._warned: "set[str]" = set()
        self._announced, self._unannounced = 0, 0  # setting lines printed / not printed this step

    # -- what goes out ---------------------------------------------------------------------------
    def take_sends(self) -> "list[Send]":
        """The datagrams to send, in order (the list is emptied)."""
        out, self._sends = self._sends, []
        return out

    def take_notices(self) -> "list[Notice]":
        """The console lines to print, in order (the list is emptied)."""
        out, self._notices = self._notices, []
        return out

    @property
    def events(self) -> "list[SettingEvent]":
        """Every parameter and mode write, as the step log keeps them."""
        return self.services.events

    def _send(self, port: int, addr: Address, msgs: list, counted: bool = True) -> None:
        self._sends.append(Send(port, addr, self.codec.encode_many(msgs), len(msgs), counted))

    def _warn(self, text: str) -> None:
        self._notices.append(Notice("stderr", text))

    def _warn_once(self, key: str, text: str) -> None:
        if key not in self._warned:
            self._warned.add(key)
            self._warn(f"warning: {text}")

    # -- clock -----------------------------------------------------------------------------------
    def begin_step(self, k: int) -> None:
        """Step ``k`` (at ``k * dt`` sim s) is the current one: what arrives from now on is handled at it, and
        every peer's reply budget is full again."""
        if self._unannounced:
            self._notices.append(Notice("stdout", f"t={self.t:5.0f}s {self._unannounced} more setting writes "
                                                  f"(not printed)"))
        self._announced, self._unannounced = 0, 0
        self.k, self.t = int(k), float(k) * self.dt
        for o in self.outputs:
            o.peer.new_step()

    def sim_time_of(self, wall: float) -> float:
        """Sim time (s) of wall instant ``wall`` (s, the caller's monotonic clock): lockstep the current step;
        realtime the last published step plus the wall time since x speed."""
        if self.lockstep or self._step_wall is None:
            return self.t
        return self._step_t + max(0.0, wall - self._step_wall) * self.speed

    # -- receiving -------------------------------------------------------------------------------
    def output_at(self, addr: Address, port: int = MAIN) -> "OutputLink | None":
        """The output ``addr`` is on for a datagram on ``port``, or None (someone else)."""
        a = tuple(addr)
        for o in self.outputs:
            if o.port == port and o.addr is not None and tuple(o.addr) == a:
                return o
        return None

    def link_of(self, addr: Address, port: int = MAIN) -> "str | None":
        """The name of the output ``addr`` is on (``gcs``, ``tap``, ``out2``, ...), or None."""
        o = self.output_at(addr, port)
        return o.name if o is not None else None

    def receive(self, port: int, data: bytes, addr: Address, now: float) -> None:
        """One datagram on ``port`` from ``addr`` at wall ``now`` (s) (see the module docstring)."""
        p = self.ports[port]
        known = self.output_at(addr, port)
        self._stamp = None
        for r in p.intake.receive(data, addr, now, known.peer.admit() if known is not None else None):
            self.guard.run(partial(self._arrive, port=port), r)
        self._stamp = None

    def _arrive(self, r: Received, port: int) -> None:
        msg = r.msg
        mtype = msg.get_type()
        intake = self.ports[port].intake
        intake.counters.received += 1
        out = self.output_at(r.addr, port)
        link = out.name if out is not None else None
        if mtype == "SIM_TICK_ACK":  # the GCS's, from the pilot link; anyone else's changes nothing
            if link == PILOT_LINK:
                self._answered("gcs", int(msg.tick), r.t)
            return
        own = msg.get_srcSystem() == VEHICLE_SYSID
        if mtype == "SIM_TICK" and own and link == PILOT_LINK:
            self.stats.tick_echoes += 1  # our own tick, echoed by the shim (one we never sent changes nothing)
            self._answered("shim", int(msg.tick), r.t)
            return
        if own:
            self.stats.foreign_messages_ignored += 1  # our own sysid echoed back / spoofed
            return
        if out is None:
            self.stats.other_address_ignored += 1
            return
        pilot = link == PILOT_LINK
        if pilot:
            self._gcs_data = True  # link liveness: noted at the step boundary
        if mtype == "SYSTEM_TIME":  # a GCS's send-time stamp for the settings in the same datagram
            self._stamp = (tuple(r.addr), msg.time_boot_ms / 1000.0)
            return
        peer = out.peer
        if GcsServices.is_read(msg):
            if peer.offer_request(r) == FULL:
                self._dropped(intake, f"reads from {link}")
            elif not self.lockstep:  # realtime: answered on arrival, within the reply budget
                self._pump(out, r.t)
            return
        if pilot and is_pilot_command(msg):
            size = wire_size(msg)
            if self.command_bytes + size > COMMAND_QUEUE_BYTES:
                self._dropped(intake, "pilot commands")
                return
            self.commands.append((r, size))
            self.command_bytes += size
            return
        if GcsServices.is_write(msg) or is_pilot_command(msg):  # settings; an observer's command (refused)
            stamp = self._stamp
            if not peer.offer_setting(r, stamp[1] if stamp is not None and stamp[0] == tuple(r.addr) else None):
                self._dropped(intake, f"settings from {link}")

    def _dropped(self, intake, what: str) -> None:
        intake.counters.dropped_queue += 1
        self.stats.dropped_queue += 1
        self._warn_once(f"queue:{what}", f"dropping {what}: their queue is full (a flood?); counted as "
                                         f"dropped_queue, summarised at the end")

    def _answered(self, who: str, k: int, now: float) -> None:
        line = self.ticks.answered(who, k, self.t, now)
        if line is not None:
            self._warn(line)

    def pending(self, port: "int | None" = None) -> bool:
        """Does something wait for the step boundary (on ``port``, or on any)?"""
        main = port is None or port == MAIN
        if main and (self._gcs_data or self.commands):
            return True
        return any(o.peer.pending() for o in self.outputs if port is None or o.port == port)

    def process(self, port: "int | None" = None) -> None:
        """The step boundary, for every port (the main one first) or ``port`` only: link liveness, settings,
        the pilot's commands, then the reads within each peer's reply budget."""
        main = port is None or port == MAIN
        if main and self._gcs_data:
            self._gcs_data = False
            self.plant.note_gcs_data(self.t)
        outs = [o for o in self.outputs if port is None or o.port == port]
        for o in outs:
            for r, t_sent in o.peer.take_settings():
                self.guard.run(partial(self._setting, out=o, t_sent=t_sent), r)
        if main:
            while self.commands:
                r, size = self.commands.popleft()
                self.command_bytes -= size
                self.guard.run(self._pilot_command, r)
        for o in outs:
            self._pump(o, None)

    def _pump(self, out: OutputLink, wall: "float | None") -> None:
        """Send ``out``'s waiting replies and answers within its budget (reads at sim time of ``wall``)."""
        if out.addr is None:
            return
        now = self.t if wall is None else self.sim_time_of(wall)
        peer = out.peer
        before = peer.counters.answered
        for data, n in peer.pump(self.services, self.codec, now, self.latest, self.guard):
            self._sends.append(Send(out.port, out.addr, data, n))
        self.stats.gcs_requests_answered += peer.counters.answered - before

    def _setting(self, r: Received, out: OutputLink, t_sent: "float | None") -> None:
        """A setting (or an observer's command) at the step boundary; its reply within the reply budget."""
        msg = r.msg
        if is_pilot_command(msg):  # a command must cross the delayed link: only the first --out flies
            self.stats.commands_from_observers_ignored += 1
            if msg.get_type().startswith("COMMAND"):
                self._send(out.port, r.addr, [M.MAVLink_command_ack_message(
                    msg.command, M.MAV_RESULT_DENIED, 0, 0, msg.get_srcSystem(), msg.get_srcComponent())])
                self.stats.gcs_requests_answered += 1
            return
        n0 = len(self.services.events)
        replies = self.services.write(msg, out.name, self.sim_time_of(r.t), self.t, t_sent)
        if replies:
            out.peer.queue_reply(replies)
            self.stats.gcs_requests_answered += 1
        for ev in self.services.events[n0:]:
            self._announce(ev)
        if self.services.events_unlogged:
            self._warn_once("events", f"more than {len(self.services.events)} setting writes: the rest are "
                                      f"applied and answered but not logged")

    def _pilot_command(self, r: Received) -> None:
        msg = r.msg
        is_cmd = msg.get_type().startswith("COMMAND")
        if is_cmd:
            if msg.target_system not in (0, VEHICLE_SYSID):
                return
            cmd = reposition_command(msg, self.plant.own_position(), self.plant.sc.origin, self.sim_time_of(r.t),
                                     msg.get_seq())
        else:
            cmd = setpoint_command(msg, VEHICLE_SYSID)
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        if cmd is None or isinstance(cmd, str):
            self.gate.counters.invalid += 1
            if is_cmd:
                self._send(MAIN, r.addr, [M.MAVLink_command_ack_message(msg.command, M.MAV_RESULT_DENIED, 0, 0, *src),
                                          T.statustext(str(cmd)[:50] if cmd else "DO_REPOSITION: invalid")])
                self.stats.gcs_requests_answered += 1
            return
        ok = self.gate.offer(cmd, self.t)
        if ok:
            self.plant.add_command(cmd)
        if cmd.kind == "PILOT_MANEUVER" and ok:  # our dialect acknowledges with its cmd_seq
            self._send(MAIN, r.addr, [T.command_ack(PILOT_MANEUVER_ID, M.MAV_RESULT_ACCEPTED, cmd.seq, *src)])
        elif is_cmd:
            self._send(MAIN, r.addr, [M.MAVLink_command_ack_message(
                msg.command, M.MAV_RESULT_ACCEPTED if ok else M.MAV_RESULT_DENIED, 0, 0, *src)])
            self.stats.gcs_requests_answered += 1
        # SET_POSITION_TARGET_GLOBAL_INT: no COMMAND_ACK (not a command); POSITION_TARGET_GLOBAL_INT is the feedback

    def _announce(self, ev: SettingEvent) -> None:
        """A setting write: one console line, and an accepted one as a STATUSTEXT to the other outputs too."""
        sent = f", sent t={ev.t_sent:g}s" if ev.t_sent is not None else ""
        if self._announced < ANNOUNCED_PER_STEP:
            self._announced += 1
            self._notices.append(Notice("stdout", f"t={ev.t_applied:5.0f}s {ev.kind} {ev.name} {ev.status}: "
                                                  f"{ev.reason} (from {ev.link}, received t={ev.t_received:.1f}s{sent})"))
        else:
            self._unannounced += 1
        if ev.status == "accepted":
            for o in self.outputs:
                if o.name != ev.link and o.name != PILOT_LINK and o.addr is not None:
                    o.peer.queue_reply([T.statustext(ev.reason[:50])])

    # -- ticks -----------------------------------------------------------------------------------
    def send_tick(self, k: int, t: float) -> None:
        """SIM_TICK(k, t) alone in its datagram to the pilot link (not before a ``udpin:`` GCS has spoken:
        the retries send it once one has)."""
        dest = self.outputs[0].addr
        if dest is None:
            return
        self._sends.append(Send(MAIN, dest, self.ticks.peer.tick(k, t), 1, counted=False))
        self.stats.ticks_sent += 1

    def check_silence(self, now: float) -> None:
        """Report (once, until it answers again) a shim or GCS that stopped answering ticks by wall ``now``."""
        for line in self.ticks.silence_warnings(now):
            self._warn(line)

    # -- sending ---------------------------------------------------------------------------------
    def publish(self, t: float, out, wall: float) -> None:
        """Telemetry of the step at ``t`` (s; ``out`` the plant's step output) at wall ``wall`` (s): per
        output, one datagram of the messages due on that output's stream."""
        pol = self.plant.policy
        if self.home is None:
            self.home = T.kin_of(out.own, 0)
        msgs = T.step_messages(self.plant, t, out, self.home, agent_enabled=bool(pol.enabled))
        self.latest = msgs
        self._step_t, self._step_wall = t, wall
        extra = []
        new_auth = self.plant.last_authority
        if new_auth != self.authority:
            self.stats.authority_changes += 1
            extra.append(T.statustext(f"DAA-SIL t={t:.0f}s authority {self.authority}->{new_auth}"
                                      f" ({self.plant.last_decision})"))
            self.authority = new_auth
        for o in self.outputs:
            if o.addr is None:  # udpin: nobody has spoken yet
                continue
            due = o.peer.rates.due(t)
            self._send(o.port, o.addr, [m for mid in STREAMED if mid in due for m in msgs.get(mid, ())] + extra)

    # -- counts ----------------------------------------------------------------------------------
    def dropped(self) -> int:
        """Messages dropped on every port: codec rejections, unexpected peers, full queues, malformed content."""
        return sum(p.intake.stats()["dropped"] - self.guard.total for p in self.ports) + self.guard.total

    def queue_summary(self) -> "str | None":
        """One line on what the queues dropped and what the reply budget held back (None if nothing)."""
        parts = []
        for o in self.outputs:
            c = o.peer.counters
            if c.dropped_queue or c.coalesced or c.deferred_steps:
                parts.append(f"{o.name}: {c.dropped_queue} dropped, {c.coalesced} parameter lists coalesced, "
                             f"replies held back for budget in {c.deferred_steps} steps")
        if self.stats.dropped_queue or self.codec.counters.shed:
            parts.insert(0, f"{self.stats.dropped_queue} messages past a queue's budget, {self.codec.counters.shed} "
                            f"more not decoded")
        return ("queues: " + "; ".join(parts)) if parts else None
