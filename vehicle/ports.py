"""The vehicle's sockets and outputs as the protocol core sees them (sans-IO): where each socket binds,
its receiving rules, which output an address is on, the ground stations (peers) of each output, and
what the core hands back to the node.

An output serves one or more ground stations, each a :class:`vehicle.peers.Peer` (its own rates,
queues and reply budget) keyed by its address:

* ``udp:`` / ``udpout:``: one peer, the address given;
* ``udpin:``: every sender of a good message, answered while it was heard within
  :data:`PEER_TIMEOUT_S` wall seconds (pymavlink's ``udpin`` rule: the most recent one is kept even
  when it falls silent, so a GCS that pauses is answered again at once). A stale sender never locks
  anyone out: a new ground station is answered from its first good datagram (its heartbeat);
* ``tcpin:``: one peer per TCP connection, from connect to close.

A listening output serves at most :data:`MAX_PEERS` ground stations at once; a new one past that
(every slot live) is refused and counted, its datagrams decoded without touching the signing state
(:meth:`daa_sil.sil.intake.Intake.reject`), as those of any stranger.
"""

from __future__ import annotations

from typing import NamedTuple

from daa_sil.link.codec import MavCodec
from daa_sil.sil.connstr import TCP, UDP
from daa_sil.sil.intake import Address, Intake
from daa_sil.sil.msgguard import MessageGuard
from daa_sil.sil.outputs import OutputSpec

from .peers import Peer

MAIN = 0  #: the main socket's port number (always UDP)
#: wall seconds a ``udpin:`` output keeps answering a ground station it no longer hears (pymavlink's rule)
PEER_TIMEOUT_S = 5.0
#: ground stations one listening output (``udpin:`` / ``tcpin:``) serves at once
MAX_PEERS = 8


class Send(NamedTuple):
    """One datagram to send on socket ``port`` (0 = the main one) to ``addr``; ``messages`` packets in it,
    counted in the socket's ``sent`` unless ``counted`` is False (the tick protocol's own). On a TCP port
    ``addr`` names the connection."""

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


class Outbox:
    """What the protocol core has to send and to print, in order, until the node takes it; ``codec`` encodes."""

    def __init__(self, codec: MavCodec):
        self.codec = codec
        self.sends: "list[Send]" = []
        self.notices: "list[Notice]" = []
        self._warned: "set[str]" = set()

    def send(self, port: int, addr: Address, msgs: list, counted: bool = True) -> None:
        """``msgs`` encoded into one datagram to ``addr`` on ``port``."""
        self.sends.append(Send(port, addr, self.codec.encode_many(msgs), len(msgs), counted))

    def say(self, text: str) -> None:
        """A console line on stdout (a setting applied or refused, traffic injected)."""
        self.notices.append(Notice("stdout", text))

    def warn(self, text: str) -> None:
        """A warning line on stderr (``daa-vehicle:`` in front)."""
        self.notices.append(Notice("stderr", text))

    def warn_once(self, key: str, text: str) -> None:
        if key not in self._warned:
            self._warned.add(key)
            self.warn(f"warning: {text}")

    def take_sends(self) -> "list[Send]":
        out, self.sends = self.sends, []
        return out

    def take_notices(self) -> "list[Notice]":
        out, self.notices = self.notices, []
        return out


class Port:
    """One socket of the vehicle: where it binds, its receiving rules, and ``transport`` ``"udp"`` (a
    datagram socket) or ``"tcp"`` (a server whose connections the core tells apart by address)."""

    def __init__(self, bind: Address, intake: Intake, transport: str = UDP):
        self.bind, self.intake, self.transport = bind, intake, transport


class OutputLink:
    """An output while the vehicle runs: its spec, the port serving it (the main one, or a listening
    output's own) and its ground stations (see the module docstring). ``addr``: the ground station heard
    last (fixed: the address given; None before one spoke)."""

    def __init__(self, spec: OutputSpec, port: int, intake: Intake, dt: float):
        self.spec, self.port, self.intake, self.dt = spec, port, intake, float(dt)
        self.peers: "dict[Address, Peer]" = {}
        self.heard: "dict[Address, float]" = {}  #: wall time (s) each listening peer was last heard
        self.refused = 0  #: datagrams from new ground stations refused: every slot taken by a live one
        self.expired = 0  #: ground stations dropped after PEER_TIMEOUT_S of silence (udpin:)
        if not spec.listens:
            self.peers[spec.addr] = Peer(spec.name, dt)

    @property
    def name(self) -> str:
        return self.spec.name

    @property
    def listens(self) -> bool:
        return self.spec.listens

    @property
    def addr(self) -> "Address | None":
        if not self.listens:
            return self.spec.addr
        return max(self.heard, key=self.heard.get) if self.heard else None

    @property
    def peer(self) -> "Peer | None":
        """The peer at :attr:`addr` (the one heard last)."""
        a = self.addr
        return self.peers.get(a) if a is not None else None

    def addrs(self) -> "list[Address]":
        """Every ground station answered now."""
        return list(self.peers)

    def peer_at(self, addr: Address) -> "Peer | None":
        return self.peers.get((addr[0], addr[1]))

    def has_room(self, addr: Address, now: float) -> bool:
        """May ``addr`` be served (known, or a free slot once the silent ones are dropped)?"""
        a = (addr[0], addr[1])
        if a in self.peers or not self.listens:
            return a in self.peers
        if len(self.peers) >= MAX_PEERS:
            self.expire(now)
        return len(self.peers) < MAX_PEERS

    def heard_from(self, addr: Address, now: float) -> "Peer | None":
        """A good message from ``addr`` at wall ``now`` (s): its peer, made if new and there is room."""
        a = (addr[0], addr[1])
        if not self.listens:
            return self.peers.get(a)
        peer = self.peers.get(a)
        if peer is None:
            if not self.has_room(a, now):
                return None
            peer = self.peers[a] = Peer(self.spec.name, self.dt)
        self.heard[a] = float(now)
        return peer

    def expire(self, now: float) -> "list[Address]":
        """Drop the ``udpin:`` ground stations silent for PEER_TIMEOUT_S at wall ``now`` (s), all but the one
        heard last; returns their addresses. (A TCP connection lasts until it is closed.)"""
        if not self.listens or self.spec.tcp or len(self.peers) <= 1:
            return []
        newest = self.addr
        gone = [a for a, t in self.heard.items() if a != newest and now - t > PEER_TIMEOUT_S]
        for a in gone:
            self.drop(a)
        self.expired += len(gone)
        return gone

    def drop(self, addr: Address) -> bool:
        """Forget the ground station at ``addr`` (its queues too); False if it was not served."""
        a = (addr[0], addr[1])
        self.heard.pop(a, None)
        return self.peers.pop(a, None) is not None


def open_ports(specs: "list[OutputSpec]", listen: Address, codec: MavCodec, guard: MessageGuard,
               dt: float) -> "tuple[list[Port], list[OutputLink]]":
    """The main port (the first output's socket if it is ``udpin:``, else a UDP socket at ``listen``) and one
    per further listening output (``udpin:`` / ``tcpin:``; a ``tcpin:`` first output gets its own too), with
    the receiving rules of each; and the outputs on them."""
    primary = specs[0]
    fixed = [s.addr for s in specs if not s.listens]
    common = dict(name="daa-vehicle", guard=guard)

    def listening(s: OutputSpec) -> Intake:  # anyone may speak; the output decides whom it serves
        return Intake(codec, peer=None, learn_peer=False, peer_label=f"{s.name} ({s.conn.text})",
                      drop_hint=f"{s.name} serves at most {MAX_PEERS} ground stations at once", **common)

    if primary.listens and not primary.tcp:  # --out udpin:HOST:PORT: the main socket listens there
        ports = [Port(primary.addr, listening(primary))]
    else:
        ports = [Port(listen, Intake(codec, peer=None, learn_peer=False, allow_peers=fixed, peer_label="--out / --tap",
                                     drop_hint="if that is your GCS or shim, give its address as --out (commands are "
                                               "taken only from the first --out)", **common))]
    outputs = []
    for s in specs:
        port = MAIN
        if s.listens and not (s is primary and not s.tcp):
            ports.append(Port(s.addr, listening(s), TCP if s.tcp else UDP))
            port = len(ports) - 1
        outputs.append(OutputLink(s, port, ports[port].intake, dt))
    return ports, outputs


def queue_summary(outputs: "list[OutputLink]", dropped_queue: int, shed: int) -> "str | None":
    """One line on what the ground stations' queues dropped, what their reply budget held back and what the
    listening outputs refused (None if nothing); ``dropped_queue`` / ``shed``: the vehicle's totals."""
    parts = []
    for o in outputs:
        for p in o.peers.values():
            c = p.counters
            if c.dropped_queue or c.coalesced or c.deferred_steps:
                parts.append(f"{o.name}: {c.dropped_queue} dropped, {c.coalesced} parameter lists coalesced, "
                             f"replies held back for budget in {c.deferred_steps} steps")
        if o.refused:
            parts.append(f"{o.name}: {o.refused} datagrams from more ground stations than it serves refused")
    if dropped_queue or shed:
        parts.insert(0, f"{dropped_queue} messages past a queue's budget, {shed} more not decoded")
    return ("queues: " + "; ".join(parts)) if parts else None
