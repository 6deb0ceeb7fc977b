"""The vehicle's MAVLink protocol, sans-IO: datagrams in, sends, console lines and step-log rows out.

:class:`VehicleProtocol` never reads a clock or touches a socket (the pattern of h11's
``Connection`` and of :class:`daa_sil.sil.shim_core.ShimCore`). The node (:mod:`vehicle.node`) binds
one socket per :class:`Port` and hands each datagram to :meth:`VehicleProtocol.receive` with the
port, the sender and the arrival time; it sends what :meth:`VehicleProtocol.take_sends` returns and
prints what :meth:`VehicleProtocol.take_notices` returns. A test does the same with bytes alone.

What happens to a message:

* **on arrival** (:meth:`~VehicleProtocol.receive`): the port's :class:`daa_sil.sil.intake.Intake`
  decodes the datagram (address policy, codec, counts); the tick protocol's messages from the pilot
  link (the shim's echo of our SIM_TICK, the GCS's SIM_TICK_ACK) are taken at once
  (:class:`vehicle.tick_rules.TickRules`); in realtime, reads (:meth:`GcsServices.is_read`) are
  answered at once; everything else waits in the port's queue for the step boundary;
* **at the step boundary** (:meth:`~VehicleProtocol.process`, which the node calls while it waits for
  a tick and before each step): link liveness (data from the pilot link), SYSTEM_TIME send stamps,
  reads (lockstep), writes (PARAM_SET, modes: :class:`vehicle.services.GcsServices`) from writable
  links, and pilot commands from the pilot link through the :class:`vehicle.commands.CommandGate`
  into the simulation (``plant``, a :class:`vehicle.core.VehicleCore`);
* **each step** (:meth:`~VehicleProtocol.publish`): the step's telemetry, one datagram per output
  with the messages due on that output's rates, and a STATUSTEXT when the authority changes.

Every message's handling runs under ``guard`` (:class:`daa_sil.sil.msgguard.MessageGuard`): one that
raises is counted as malformed and the rest of its datagram is still handled. Link liveness for the
agent counts only **data** from the GCS, never the tick messages, which bypass the delay line.
"""

from __future__ import annotations

from collections import deque
from functools import partial
from typing import NamedTuple

from daa_sil.link.codec import MavCodec
from daa_sil.link.codec import mavlink as M
from daa_sil.sil.intake import Address, Intake, Received
from daa_sil.sil.lockstep import TickPeer
from daa_sil.sil.msgguard import MessageGuard
from daa_sil.sil.outputs import PILOT_LINK, OutputSpec

from . import telemetry as T
from .commands import CommandGate, reposition_command, setpoint_command
from .node_options import VehicleStats
from .params import ParamTable
from .services import GcsServices, SettingEvent
from .streams import STREAMED
from .tick_rules import TickOptions, TickRules

VEHICLE_SYSID, VEHICLE_COMPID = 1, 1
PILOT_MANEUVER_ID = M.MAVLINK_MSG_ID_PILOT_MANEUVER
#: messages a port keeps for the step boundary (past this: ``inbox_overflow``)
INBOX_SIZE = 10_000
MAIN = 0  #: the main socket's port number


class Send(NamedTuple):
    """One datagram to send on socket ``port`` (0 = the main one) to ``addr``; ``messages`` packets in it,
    counted in the socket's ``sent`` unless ``counted`` is False (the tick protocol's own)."""

    port: int
    addr: Address
    data: bytes
    messages: int
    counted: bool = True


class Notice(NamedTuple):
    """One console line: ``stream`` ``"stdout"`` (a setting applied or refused) or ``"stderr"`` (a warning,
    ``daa-vehicle:`` in front)."""

    stream: str
    text: str


class Port:
    """One socket of the vehicle: where it binds, its receiving rules and the messages that wait for the
    step boundary."""

    def __init__(self, bind: Address, intake: Intake):
        self.bind, self.intake = bind, intake
        self.queue: "deque[Received]" = deque()


class OutputLink:
    """An output while the vehicle runs: its spec and the port serving it (the main one, or a ``udpin:``
    output's own). ``addr``: where its datagrams go (fixed, or a ``udpin:`` port's first sender)."""

    def __init__(self, spec: OutputSpec, port: int, intake: Intake):
        self.spec, self.port, self.intake = spec, port, intake

    @property
    def name(self) -> str:
        return self.spec.name

    @property
    def addr(self) -> "Address | None":
        if self.spec.listens:
            return tuple(self.intake.peer) if self.intake.peer is not None else None
        return self.spec.addr


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
        self.ports: "list[Port]" = []
        self.outputs: "list[OutputLink]" = []
        self._open_ports(specs, listen)
        self.k, self.t = 0, 0.0
        self.authority = "pilot"
        self.home: "T.Kin | None" = None
        self.latest: dict = {}  #: the newest step's telemetry ``{msg_id: [messages]}``
        self._step_t, self._step_wall = 0.0, None  # sim and wall time of the last publish
        self._stamp = None  # (addr, datagram time, t_sent) of the GCS's last SYSTEM_TIME
        self._sends: "list[Send]" = []
        self._notices: "list[Notice]" = []

    def _open_ports(self, specs: "list[OutputSpec]", listen: Address) -> None:
        """The main port (the first output's socket if it listens, else ``listen``) and one per further
        ``udpin:`` output, with the receiving rules of each."""
        primary, rest = specs[0], specs[1:]
        fixed = [s.addr for s in rest if not s.listens]
        common = dict(name="daa-vehicle", guard=self.guard)
        if primary.listens:  # --out udpin:HOST:PORT: listen there, answer the first GCS that sends
            main = Intake(self.codec, peer=None, learn_peer=True, lock_peer=True, allow_peers=fixed,
                          peer_label="--out udpin: the first GCS that sent",
                          drop_hint=f"the vehicle answers only the first GCS that sent to {primary.conn.text}", **common)
            self.ports.append(Port(primary.addr, main))
        else:
            main = Intake(self.codec, peer=primary.addr, learn_peer=False, allow_peers=[primary.addr] + fixed,
                          peer_label="--out / --tap",
                          drop_hint="if that is your GCS or shim, give its address as --out (commands are taken "
                                    "only from the first --out)", **common)
            self.ports.append(Port(listen, main))
        self.outputs.append(OutputLink(primary, MAIN, main))
        for s in rest:
            port = MAIN
            if s.listens:
                self.ports.append(Port(s.addr, Intake(self.codec, peer=None, learn_peer=True, lock_peer=True,
                                                      peer_label=f"{s.name}: the first sender",
                                                      drop_hint=f"{s.name} ({s.conn.text}) answers only its first "
                                                                f"sender", **common)))
                port = len(self.ports) - 1
            self.outputs.append(OutputLink(s, port, self.ports[port].intake))

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

    def _reply(self, msgs: list, addr: Address, port: int, count: bool = True) -> None:
        if msgs:
            self._send(port, addr, msgs)
            self.stats.gcs_requests_answered += int(count)

    def _warn(self, text: str) -> None:
        self._notices.append(Notice("stderr", text))

    # -- clock -----------------------------------------------------------------------------------
    def begin_step(self, k: int) -> None:
        """Step ``k`` (at ``k * dt`` sim s) is the current one: what arrives from now on is handled at it."""
        self.k, self.t = int(k), float(k) * self.dt

    def sim_time_of(self, wall: float) -> float:
        """Sim time (s) of wall instant ``wall`` (s, the caller's monotonic clock): lockstep the current step;
        realtime the last published step plus the wall time since x speed."""
        if self.lockstep or self._step_wall is None:
            return self.t
        return self._step_t + max(0.0, wall - self._step_wall) * self.speed

    # -- receiving -------------------------------------------------------------------------------
    def link_of(self, addr: Address, port: int = MAIN) -> "str | None":
        """The output ``addr`` is on (``gcs``, ``tap``, ``out2``, ...) for a datagram on ``port``, or None."""
        a = tuple(addr)
        for o in self.outputs:
            if o.port == port and o.addr is not None and tuple(o.addr) == a:
                return o.name
        return None

    def receive(self, port: int, data: bytes, addr: Address, now: float) -> None:
        """One datagram on ``port`` from ``addr`` at wall ``now`` (s) (see the module docstring)."""
        p = self.ports[port]
        for r in p.intake.receive(data, addr, now):
            self.guard.run(partial(self._arrive, port=port), r)

    def _arrive(self, r: Received, port: int) -> None:
        msg = r.msg
        mtype = msg.get_type()
        p = self.ports[port]
        link = self.link_of(r.addr, port)
        if mtype == "SIM_TICK_ACK":  # the GCS's, from the pilot link; anyone else's changes nothing
            p.intake.counters.received += 1
            if link == PILOT_LINK:
                self._answered("gcs", int(msg.tick), r.t)
            return
        if mtype == "SIM_TICK" and msg.get_srcSystem() == VEHICLE_SYSID and link == PILOT_LINK:
            p.intake.counters.received += 1
            self.stats.tick_echoes += 1  # our own tick, echoed by the shim (one we never sent changes nothing)
            self._answered("shim", int(msg.tick), r.t)
            return
        if not self.lockstep and link is not None and msg.get_srcSystem() != VEHICLE_SYSID \
                and GcsServices.is_read(msg):  # realtime: reads are answered the moment they arrive
            self._reply(self.services.read(msg, link, self.sim_time_of(r.t), self.latest), r.addr, port)
        if len(p.queue) >= INBOX_SIZE:
            p.intake.counters.inbox_overflow += 1
            return
        p.queue.append(r)
        p.intake.counters.received += 1

    def _answered(self, who: str, k: int, now: float) -> None:
        line = self.ticks.answered(who, k, self.t, now)
        if line is not None:
            self._warn(line)

    def pending(self, port: "int | None" = None) -> bool:
        """Do messages wait for the step boundary (on ``port``, or on any)?"""
        ports = self.ports if port is None else [self.ports[port]]
        return any(p.queue for p in ports)

    def process(self, port: "int | None" = None) -> None:
        """Handle the messages waiting on every port (the main one first), or on ``port`` only."""
        for i in (range(len(self.ports)) if port is None else (port,)):
            q = self.ports[i].queue
            while q:
                self.guard.run(partial(self.handle, port=i), q.popleft())

    def handle(self, r: Received, port: int = MAIN) -> None:
        """Handle one message at the step boundary (run it under the guard: content it did not foresee may
        raise)."""
        msg = r.msg
        mtype = msg.get_type()
        link = self.link_of(r.addr, port)
        if msg.get_srcSystem() == VEHICLE_SYSID:
            self.stats.foreign_messages_ignored += 1  # our own sysid echoed back / spoofed
            return
        if link is None:
            self.stats.other_address_ignored += 1
            return
        observer = link != PILOT_LINK
        if not observer:
            self.plant.note_gcs_data(self.t)
        if mtype == "SYSTEM_TIME":  # a GCS's send-time stamp for the settings in the same datagram
            self._stamp = (tuple(r.addr), r.t, msg.time_boot_ms / 1000.0)
            return
        if GcsServices.is_read(msg):
            if self.lockstep:  # realtime: answered on arrival
                self._reply(self.services.read(msg, link, self.sim_time_of(r.t), self.latest), r.addr, port)
            return
        if GcsServices.is_write(msg):
            stamp = self._stamp
            t_sent = stamp[2] if stamp is not None and stamp[0] == tuple(r.addr) and stamp[1] == r.t else None
            n0 = len(self.services.events)
            self._reply(self.services.write(msg, link, self.sim_time_of(r.t), self.t, t_sent), r.addr, port)
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
                                r.addr, port)
                return
            self._pilot_command(msg, r, port)

    def _pilot_command(self, msg, r: Received, port: int) -> None:
        mtype = msg.get_type()
        is_cmd = mtype.startswith("COMMAND")
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
                self._reply([M.MAVLink_command_ack_message(msg.command, M.MAV_RESULT_DENIED, 0, 0, *src),
                             T.statustext(str(cmd)[:50] if cmd else "DO_REPOSITION: invalid")], r.addr, port)
            return
        ok = self.gate.offer(cmd, self.t)
        if ok:
            self.plant.add_command(cmd)
        if cmd.kind == "PILOT_MANEUVER" and ok:  # our dialect acknowledges with its cmd_seq
            self._reply([T.command_ack(PILOT_MANEUVER_ID, M.MAV_RESULT_ACCEPTED, cmd.seq, *src)], r.addr, port,
                        count=False)
        elif is_cmd:
            self._reply([M.MAVLink_command_ack_message(msg.command, M.MAV_RESULT_ACCEPTED if ok else M.MAV_RESULT_DENIED,
                                                       0, 0, *src)], r.addr, port)
        # SET_POSITION_TARGET_GLOBAL_INT: no COMMAND_ACK (not a command); POSITION_TARGET_GLOBAL_INT is the feedback

    def _announce(self, ev: SettingEvent) -> None:
        """A setting write: one console line, and an accepted one as a STATUSTEXT to the other outputs too."""
        sent = f", sent t={ev.t_sent:g}s" if ev.t_sent is not None else ""
        self._notices.append(Notice("stdout", f"t={ev.t_applied:5.0f}s {ev.kind} {ev.name} {ev.status}: {ev.reason} "
                                              f"(from {ev.link}, received t={ev.t_received:.1f}s{sent})"))
        if ev.status == "accepted":
            for o in self.outputs:
                if o.name != ev.link and o.name != PILOT_LINK and o.addr is not None:
                    self._send(o.port, o.addr, [T.statustext(ev.reason[:50])])

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
            due = self.services.link_rates(o.name).due(t)
            self._send(o.port, o.addr, [m for mid in STREAMED if mid in due for m in msgs.get(mid, ())] + extra)

    # -- counts ----------------------------------------------------------------------------------
    def dropped(self) -> int:
        """Messages dropped on every port: codec rejections, unexpected peers, overflow, malformed content."""
        return sum(p.intake.stats()["dropped"] - self.guard.total for p in self.ports) + self.guard.total
