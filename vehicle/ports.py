"""The vehicle's sockets and outputs as the protocol core sees them (sans-IO): where each socket binds,
its receiving rules, which output an address is on, and what the core hands back to the node."""

from __future__ import annotations

from typing import NamedTuple

from daa_sil.link.codec import MavCodec
from daa_sil.sil.intake import Address, Intake
from daa_sil.sil.msgguard import MessageGuard
from daa_sil.sil.outputs import OutputSpec

from .peers import Peer

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
    """One socket of the vehicle: where it binds and its receiving rules."""

    def __init__(self, bind: Address, intake: Intake):
        self.bind, self.intake = bind, intake


class OutputLink:
    """An output while the vehicle runs: its spec, the port serving it (the main one, or a ``udpin:``
    output's own) and its :class:`vehicle.peers.Peer` (rates, queues, reply budget). ``addr``: where its
    datagrams go (fixed, or a ``udpin:`` port's first sender; None before one spoke)."""

    def __init__(self, spec: OutputSpec, port: int, intake: Intake, dt: float):
        self.spec, self.port, self.intake = spec, port, intake
        self.peer = Peer(spec.name, dt)

    @property
    def name(self) -> str:
        return self.spec.name

    @property
    def addr(self) -> "Address | None":
        if self.spec.listens:
            return tuple(self.intake.peer) if self.intake.peer is not None else None
        return self.spec.addr


def open_ports(specs: "list[OutputSpec]", listen: Address, codec: MavCodec, guard: MessageGuard,
               dt: float) -> "tuple[list[Port], list[OutputLink]]":
    """The main port (the first output's socket if it listens, else ``listen``) and one per further
    ``udpin:`` output, with the receiving rules of each; and the outputs on them."""
    primary, rest = specs[0], specs[1:]
    fixed = [s.addr for s in rest if not s.listens]
    common = dict(name="daa-vehicle", guard=guard)
    if primary.listens:  # --out udpin:HOST:PORT: listen there, answer the first GCS that sends
        main = Intake(codec, peer=None, learn_peer=True, lock_peer=True, allow_peers=fixed,
                      peer_label="--out udpin: the first GCS that sent",
                      drop_hint=f"the vehicle answers only the first GCS that sent to {primary.conn.text}", **common)
        ports = [Port(primary.addr, main)]
    else:
        main = Intake(codec, peer=primary.addr, learn_peer=False, allow_peers=[primary.addr] + fixed,
                      peer_label="--out / --tap",
                      drop_hint="if that is your GCS or shim, give its address as --out (commands are taken "
                                "only from the first --out)", **common)
        ports = [Port(listen, main)]
    outputs = [OutputLink(primary, MAIN, main, dt)]
    for s in rest:
        port = MAIN
        if s.listens:
            ports.append(Port(s.addr, Intake(codec, peer=None, learn_peer=True, lock_peer=True,
                                              peer_label=f"{s.name}: the first sender",
                                              drop_hint=f"{s.name} ({s.conn.text}) answers only its first sender",
                                              **common)))
            port = len(ports) - 1
        outputs.append(OutputLink(s, port, ports[port].intake, dt))
    return ports, outputs
