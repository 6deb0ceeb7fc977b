"""The vehicle's MAVLink protocol, sans-IO: datagrams in, sends, console lines and step-log rows out.

:class:`VehicleProtocol` never reads a clock or touches a socket (h11's pattern, as
:class:`daa_sil.sil.shim_core.ShimCore`). The node (:mod:`vehicle.node`) binds one socket per
:class:`vehicle.ports.Port` and hands each datagram to :meth:`VehicleProtocol.receive` with the port,
the sender and the arrival time (TCP: :meth:`~VehicleProtocol.connect`, then the stream to
:meth:`~VehicleProtocol.receive_stream`, cut into packets by a :class:`daa_sil.link.framing.StreamFramer`
per connection); it sends what :meth:`~VehicleProtocol.take_sends` returns and prints what
:meth:`~VehicleProtocol.take_notices` returns. A test does the same with bytes. Each output serves its
ground stations (:mod:`vehicle.ports`), each a :class:`vehicle.peers.Peer` with its own rates, queues
and reply budget and the output's rights.

What happens to a message:

* **on arrival** (:meth:`~VehicleProtocol.receive`): the port's :class:`daa_sil.sil.intake.Intake`
  decodes the datagram (address policy, codec, counts); the tick protocol's messages from the pilot
  link (the shim's echo of our SIM_TICK, the GCS's SIM_TICK_ACK) are taken at once
  (:class:`vehicle.tick_rules.TickRules`); reads (:meth:`GcsServices.is_read`) join their peer's
  read queue, settings (PARAM_SET, modes, injected traffic) its settings queue, the pilot link's
  commands the command queue (:mod:`vehicle.peers`: each queue has a byte budget, past which
  messages are dropped and counted as ``dropped_queue``); in realtime the reads are answered at
  once, within the peer's reply budget;
* **at the step boundary** (:meth:`~VehicleProtocol.process`, which the node calls while it waits for
  a tick and before each step): link liveness (data from the pilot link), settings, the pilot's
  commands (:mod:`vehicle.orders`) into the simulation (``plant``, a :class:`vehicle.core.VehicleCore`,
  or a :class:`vehicle.boot.BootPlant` while the vehicle boots), then the reads, each peer within its
  reply budget per step;
* **each step** (:meth:`~VehicleProtocol.publish`): the step's telemetry, one datagram per ground station
  with the messages due on its rates, and the authority's STATUSTEXT (:mod:`vehicle.announce`);
  while booting, :meth:`~VehicleProtocol.publish_boot` sends the boot heartbeat instead.

Every message's handling runs under ``guard`` (:class:`daa_sil.sil.msgguard.MessageGuard`): one that
raises is counted as malformed and the rest of its datagram is still handled. Link liveness for the
agent counts only **data** from the GCS, never the tick messages, which bypass the delay line.
"""

from __future__ import annotations

from collections import deque
from functools import partial

from daa_sil.link.codec import MavCodec
from daa_sil.link.codec import mavlink as M
from daa_sil.link.framing import StreamFramer
from daa_sil.sil.intake import Address, Received
from daa_sil.sil.lockstep import TickPeer
from daa_sil.sil.msgguard import MessageGuard
from daa_sil.sil.outputs import PILOT_LINK, OutputSpec

from . import telemetry as T
from .announce import ModeAnnouncer
from .boot import boot_messages, progress_text
from .identity import mode_name
from .node_options import VehicleStats
from .orders import VEHICLE_SYSID, Orders, is_pilot_command, is_traffic
from .params import ParamTable
from .peers import FULL, wire_size
from .ports import MAIN, Notice, OutputLink, Outbox, Port, Send, open_ports, queue_summary
from .services import GcsServices, SettingEvent
from .streams import STREAMED
from .tick_rules import TickOptions, TickRules

__all__ = ["VehicleProtocol", "Send", "Notice", "OutputLink", "Port", "MAIN", "VEHICLE_SYSID", "VEHICLE_COMPID"]

VEHICLE_COMPID = 1
#: wire bytes of the pilot's commands waiting for the step boundary (a GCS sends about one a step)
COMMAND_QUEUE_BYTES = 64 * 1024


class VehicleProtocol:
    """The vehicle's protocol (see the module docstring).

    ``plant``: the simulation (a :class:`vehicle.core.VehicleCore`: policy, mode, commands, telemetry), or a
    :class:`vehicle.boot.BootPlant` until :meth:`set_plant` hands the simulation over; ``specs``: the
    outputs (the first is the pilot's link), hosts resolved; ``listen``: the main socket's address when the
    first output is not ``udpin:``; ``ticks``: the tick settings.
    """

    def __init__(self, plant, specs: "list[OutputSpec]", listen: Address, codec: MavCodec, ticks: TickOptions, *,
                 guard: "MessageGuard | None" = None, out_text: str = ""):
        self.plant = plant
        self.codec = codec
        self.lockstep = ticks.clock == "lockstep"
        self.speed = ticks.speed
        self.guard = guard if guard is not None else MessageGuard("daa-vehicle")
        self.stats = VehicleStats()
        self.dt = float(plant.dt)
        self.out = Outbox(codec)
        writable = frozenset(s.name for s in specs if s.writable or s.name == PILOT_LINK)
        self.services = GcsServices(ParamTable(plant.sc.thresholds), plant, dt=self.dt, writable=writable)
        self.orders = Orders(plant, self.services, self.out, self.stats)
        self.ticks = TickRules(TickPeer("vehicle", codec), ticks, self.dt, self.stats, out_text or specs[0].conn.text)
        self.ports, self.outputs = open_ports(specs, listen, codec, self.guard, self.dt)
        self.pilot = self.outputs[0]  #: the pilot's link (the first --out)
        self.k, self.t = 0, 0.0
        self.mode_text = ModeAnnouncer()
        self.authority = "pilot"  #: the authority of the last step published
        self.home: "T.Kin | None" = None
        self.latest: dict = {}  #: the newest step's telemetry ``{msg_id: [messages]}``
        self._step_t, self._step_wall = 0.0, None  # sim and wall time of the last publish
        self.commands: "deque[tuple[Received, int]]" = deque()  #: the pilot link's commands and their sizes
        self.command_bytes = 0
        self.framers: "dict[tuple[int, Address], StreamFramer]" = {}  #: one per TCP connection
        self._gcs_data = False  # data from the pilot link since the last step boundary
        self.pilot_heard = False  #: a ground station on the pilot link has sent a good message
        self.boot_text, self.boot_beats = "", 0  # the boot's latest progress line, boot heartbeats sent
        self._stamp: "tuple | None" = None  # (sender, t_sent) of a SYSTEM_TIME in the datagram being read

    # -- what goes out ---------------------------------------------------------------------------
    def take_sends(self) -> "list[Send]":
        """The datagrams to send, in order (the list is emptied)."""
        return self.out.take_sends()

    def take_notices(self) -> "list[Notice]":
        """The console lines to print, in order (the list is emptied)."""
        return self.out.take_notices()

    @property
    def events(self) -> "list[SettingEvent]":
        """Every parameter and mode write and injected traffic, as the step log keeps them."""
        return self.services.events

    @property
    def gate(self):
        return self.orders.gate

    @property
    def booting(self) -> bool:
        return bool(self.plant.booting)

    def set_plant(self, plant) -> None:
        """The simulation is ready: it replaces the boot plant (a parameter set while booting is carried over)."""
        boot = self.plant
        if getattr(boot, "written", False) and boot.policy != plant.policy:
            plant.set_policy(boot.policy)
        self.plant = self.services.plant = self.orders.plant = plant

    # -- clock -----------------------------------------------------------------------------------
    def begin_step(self, k: int) -> None:
        """Step ``k`` (at ``k * dt`` sim s) is the current one: what arrives from now on is handled at it, and
        every peer's reply budget is full again."""
        self.orders.new_step(self.t)
        self.k, self.t = int(k), float(k) * self.dt
        self._new_budget()

    def _new_budget(self) -> None:
        for o in self.outputs:
            for peer in o.peers.values():
                peer.new_step()

    def sim_time_of(self, wall: float) -> float:
        """Sim time (s) of wall instant ``wall`` (s, the caller's monotonic clock): lockstep the current step;
        realtime the last published step plus the wall time since x speed."""
        if self.lockstep or self._step_wall is None:
            return self.t
        return self._step_t + max(0.0, wall - self._step_wall) * self.speed

    # -- receiving -------------------------------------------------------------------------------
    def output_at(self, addr: Address, port: int = MAIN) -> "OutputLink | None":
        """The output ground station ``addr`` is on for a datagram on ``port``, or None (someone else)."""
        a = (addr[0], addr[1])
        for o in self.outputs:
            if o.port == port and a in o.peers:
                return o
        return None

    def listener(self, port: int) -> "OutputLink | None":
        """The listening output (``udpin:`` / ``tcpin:``) served on ``port``, if any."""
        return next((o for o in self.outputs if o.port == port and o.listens), None)

    def receive(self, port: int, data: bytes, addr: Address, now: float) -> None:
        """One datagram on ``port`` from ``addr`` at wall ``now`` (s) (see the module docstring)."""
        p = self.ports[port]
        out = self.output_at(addr, port)
        lst = self.listener(port) if out is None else None
        if out is None and lst is not None and not lst.has_room(addr, now):
            lst.refused += 1  # every slot is a live ground station: as a stranger's (no signing state touched)
            p.intake.reject(data, addr, now)
            return
        peer = out.peer_at(addr) if out is not None else None
        msgs = p.intake.receive(data, addr, now, peer.admit() if peer is not None else None)
        if msgs and (lst is not None or (out is not None and out.listens)):
            (out or lst).heard_from(addr, now)  # a good message: a new ground station, or one heard again
        self._stamp = None
        for r in msgs:
            self.guard.run(partial(self._arrive, port=port), r)
        self._stamp = None

    def connect(self, port: int, addr: Address, now: float) -> bool:
        """A TCP client connected from ``addr`` to ``port`` at wall ``now``: False if its output serves
        :data:`vehicle.ports.MAX_PEERS` already (the node then closes the connection)."""
        lst = self.listener(port)
        if lst is None or lst.heard_from(addr, now) is None:
            if lst is not None:
                lst.refused += 1
            return False
        self.framers[(port, (addr[0], addr[1]))] = StreamFramer()
        return True

    def receive_stream(self, port: int, data: bytes, addr: Address, now: float) -> None:
        """The next bytes of TCP connection ``addr`` on ``port``: its whole packets go to :meth:`receive`."""
        framer = self.framers.get((port, (addr[0], addr[1])))
        if framer is None:
            return
        chunk = framer.feed(data)
        if chunk:
            self.receive(port, chunk, addr, now)

    def disconnect(self, port: int, addr: Address) -> None:
        """TCP connection ``addr`` on ``port`` closed: its ground station and its queues are gone."""
        self.framers.pop((port, (addr[0], addr[1])), None)
        lst = self.listener(port)
        if lst is not None:
            lst.drop(addr)

    def _arrive(self, r: Received, port: int) -> None:
        msg = r.msg
        mtype = msg.get_type()
        intake = self.ports[port].intake
        intake.counters.received += 1
        out = self.output_at(r.addr, port)
        link = out.name if out is not None else None
        if link == PILOT_LINK and msg.get_srcSystem() != VEHICLE_SYSID:
            self.pilot_heard = True  # (--wait-gcs)
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
        peer = out.peer_at(r.addr)
        pilot = link == PILOT_LINK
        if pilot:
            self._gcs_data = True  # link liveness: noted at the step boundary
        if mtype == "SYSTEM_TIME":  # a GCS's send-time stamp for the settings in the same datagram
            self._stamp = (tuple(r.addr), msg.time_boot_ms / 1000.0)
            return
        if GcsServices.is_read(msg):
            if peer.offer_request(r) == FULL:
                self._dropped(intake, f"reads from {link}")
            elif not self.lockstep:  # realtime: answered on arrival, within the reply budget
                self._pump(out, r.addr, peer, r.t)
            return
        if pilot and is_pilot_command(msg):
            size = wire_size(msg)
            if self.command_bytes + size > COMMAND_QUEUE_BYTES:
                self._dropped(intake, "pilot commands")
                return
            self.commands.append((r, size))
            self.command_bytes += size
            return
        if GcsServices.is_write(msg) or is_pilot_command(msg) or is_traffic(msg):
            stamp = self._stamp  # settings, traffic, an observer's command (refused)
            if not peer.offer_setting(r, stamp[1] if stamp is not None and stamp[0] == tuple(r.addr) else None):
                self._dropped(intake, f"settings from {link}")

    def _dropped(self, intake, what: str) -> None:
        intake.counters.dropped_queue += 1
        self.stats.dropped_queue += 1
        self.out.warn_once(f"queue:{what}", f"dropping {what}: their queue is full (a flood?); counted as "
                                            f"dropped_queue, summarised at the end")

    def _answered(self, who: str, k: int, now: float) -> None:
        line = self.ticks.answered(who, k, self.t, now)
        if line is not None:
            self.out.warn(line)

    @property
    def pilot_port(self) -> int:
        return self.pilot.port

    def pending(self, port: "int | None" = None) -> bool:
        """Does something wait for the step boundary (on ``port``, or on any)?"""
        if (port is None or port == self.pilot.port) and (self._gcs_data or self.commands):
            return True
        return any(p.pending() for o in self.outputs if port is None or o.port == port for p in o.peers.values())

    def process(self, port: "int | None" = None) -> None:
        """The step boundary, for every port (the pilot's first) or ``port`` only: link liveness, settings, the
        pilot's commands, then the reads within each peer's reply budget."""
        main = port is None or port == self.pilot.port
        if main and self._gcs_data:
            self._gcs_data = False
            self.plant.note_gcs_data(self.t)
        outs = [o for o in self.outputs if port is None or o.port == port]
        for o in outs:
            for addr, peer in list(o.peers.items()):
                for r, t_sent in peer.take_settings():
                    self.guard.run(partial(self._setting, out=o, t_sent=t_sent), r)
        if main:
            while self.commands:
                r, size = self.commands.popleft()
                self.command_bytes -= size
                self.guard.run(self._pilot_command, r)
        for o in outs:
            for addr, peer in list(o.peers.items()):
                self._pump(o, addr, peer, None)

    def _pump(self, out: OutputLink, addr: Address, peer, wall: "float | None") -> None:
        """Send ``peer``'s waiting replies and answers within its budget (reads at sim time of ``wall``)."""
        now = self.t if wall is None else self.sim_time_of(wall)
        before = peer.counters.answered
        for data, n in peer.pump(self.services, self.codec, now, self.latest, self.guard):
            self.out.sends.append(Send(out.port, addr, data, n))
        self.stats.gcs_requests_answered += peer.counters.answered - before

    def _setting(self, r: Received, out: OutputLink, t_sent: "float | None") -> None:
        self.orders.setting(r, out, self.outputs, self.sim_time_of(r.t), self.t, t_sent)

    def _pilot_command(self, r: Received) -> None:
        self.orders.pilot_command(r, self.pilot.port, self.sim_time_of(r.t), self.t)

    # -- ticks -----------------------------------------------------------------------------------
    def send_tick(self, k: int, t: float) -> None:
        """SIM_TICK(k, t) alone in its datagram to the pilot link's ground stations (none before a ``udpin:``
        GCS has spoken: the retries send it once one has)."""
        dests = self.pilot.addrs()
        if not dests:
            return
        data = self.ticks.peer.tick(k, t)
        for d in dests:
            self.out.sends.append(Send(self.pilot.port, d, data, 1, counted=False))
        self.stats.ticks_sent += 1

    def check_silence(self, now: float) -> None:
        """Report (once, until it answers again) a shim or GCS that stopped answering ticks by wall ``now``."""
        for line in self.ticks.silence_warnings(now):
            self.out.warn(line)

    # -- sending ---------------------------------------------------------------------------------
    def publish(self, t: float, out, wall: float) -> None:
        """Telemetry of the step at ``t`` (s; ``out`` the plant's step output) at wall ``wall`` (s): per
        ground station, one datagram of the messages due on its stream."""
        pol = self.plant.policy
        if self.home is None:
            self.home = T.kin_of(out.own, 0)
        msgs = T.step_messages(self.plant, t, out, self.home, agent_enabled=bool(pol.enabled))
        self.latest = msgs
        self._step_t, self._step_wall = t, wall
        for o in self.outputs:
            o.expire(wall)  # udpin: ground stations silent too long
        extra = []
        new_auth = self.plant.last_authority
        text = self.mode_text.update(t, new_auth, self.plant.last_decision, mode_name(self.plant.mode()))
        if text is not None:
            extra.append(T.statustext(text))
        if new_auth != self.authority:
            self.stats.authority_changes += 1
            self.authority = new_auth
        for o in self.outputs:
            for addr, peer in o.peers.items():
                due = peer.rates.due(t)
                self.out.send(o.port, addr, [m for mid in STREAMED if mid in due for m in msgs.get(mid, ())] + extra)

    def publish_boot(self, wall: float, to_pilot: bool = True, standby: bool = False) -> None:
        """While booting (or waiting for a GCS: ``standby``), once a wall second: handle what waits (settings,
        reads; commands are refused), then a HEARTBEAT in MAV_STATE_BOOT (STANDBY) to every ground station
        (not the pilot's link unless ``to_pilot``: a shim there must see SIM_TICK first)."""
        self._new_budget()
        for o in self.outputs:
            o.expire(wall)  # udpin: ground stations silent too long
        self.process()
        self.boot_beats += 1
        msgs = boot_messages(self.plant, standby, self.boot_text, self.boot_beats)
        for o in self.outputs:
            if o is self.pilot and not to_pilot:
                continue
            for addr in o.addrs():
                self.out.send(o.port, addr, msgs)

    def boot_progress(self, text: str, to_pilot: bool = True) -> None:
        """A step of the preparation: a console line and a STATUSTEXT to every ground station (in its reply
        budget, after what it asked for)."""
        self.out.warn(f"boot: {text}")
        self.boot_text = text
        st = T.statustext(progress_text(text), M.MAV_SEVERITY_INFO)
        for o in self.outputs:
            if o is self.pilot and not to_pilot:
                continue
            for peer in o.peers.values():
                peer.queue_reply([st])

    # -- counts ----------------------------------------------------------------------------------
    def dropped(self) -> int:
        """Messages dropped on every port: codec rejections, unexpected peers, full queues, malformed content."""
        return sum(p.intake.stats()["dropped"] - self.guard.total for p in self.ports) + self.guard.total

    def queue_summary(self) -> "str | None":
        """One line on what the queues dropped and what the reply budget held back (None if nothing)."""
        return queue_summary(self.outputs, self.stats.dropped_queue, self.codec.counters.shed)
