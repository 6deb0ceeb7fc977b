"""asyncio UDP endpoint around :class:`daa_sil.link.codec.MavCodec`, and address parsing.

One ``asyncio.DatagramProtocol`` per endpoint (no ``mavutil``: it blocks the loop). What it takes in
is decided by its sans-IO :class:`daa_sil.sil.intake.Intake` (which senders, decoding, counts; read
its docstring): each datagram is decoded on its own (parser reset per datagram), packets from
addresses outside ``allow_peers`` are decoded without changing any signing state and counted,
messages from system ids outside ``allow_sysids`` are dropped, and every codec rejection is
counted. Good messages go to a bounded async inbox as :class:`Received` tuples (``inbox_overflow``
past it), after ``on_message`` if given. With ``on_datagram`` the endpoint is only the socket and
hands each datagram to its owner's protocol core (the vehicle's and the GCS's nodes).

Dropping a peer is never silent: a :class:`DropReporter` prints one warning line (stderr) the first
time datagrams from an address outside ``allow_peers`` are dropped, naming that address, what it
sent and the expected peer, and then at most every ``drop_warn_every_s`` seconds while drops go on,
with counts (``daa-gcs: warning: dropping datagrams from udp:127.0.0.1:40112 (HEARTBEAT from
system 1): not the expected peer udp:127.0.0.1:14600 (--vehicle) ...``). ICMP "port unreachable"
errors on the socket (nothing listening at the address we send to) are counted as ``refused``.

Peer: a fixed ``peer`` address, or (``learn_peer=True``, default when no peer is given) the
sender of the first datagram that contained a good message -- garbage cannot claim the link. With
``lock_peer=True`` (``udpin:`` connections of the vehicle and the GCS) datagrams from any other
address than the learned peer (and ``allow_peers``) are then dropped and reported like those of an
unexpected peer; an address in ``allow_peers`` is never learned as the peer.

Handling: each message's handling runs under the :class:`daa_sil.sil.msgguard.MessageGuard` (an
exception counts the message as malformed, ``malformed_content``, drops it, and the next message of
the datagram is still handled); consumers of the inbox run theirs under the same guard
(``ep.guard.run(handler, r)``). Binds 127.0.0.1 by default and asks for a 4 MB receive buffer (the
default 212 KB overflows on bursts: a lockstep step delivers every delayed packet of both
directions at once).
"""

from __future__ import annotations

import asyncio
import ipaddress
import socket
import time
from typing import Callable, Iterable

from daa_sil.errors import UsageError
from daa_sil.link.codec import MavCodec, MAVLinkMessage
from daa_sil.sil.intake import (Address, DropReporter, EndpointCounters, Intake, Received,  # noqa: F401 (this
                                format_udp_address)  # module's interface since before they moved to intake)
from daa_sil.sil.msgguard import MessageGuard
DEFAULT_HOST = "127.0.0.1"
RCVBUF_BYTES = 4 * 1024 * 1024
_SCHEMES = ("udp", "udpin", "udpout")


def parse_udp_address(text: str, name: str = "address", allow_port_zero: bool = True) -> Address:
    """Parse ``udp:HOST:PORT`` (also ``udpin:``/``udpout:``, or bare ``HOST:PORT``) -> ``(host, port)``.

    HOST is an IPv4 address or a host name (IPv6 as ``[::1]``); PORT is 0-65535 (0 = OS-chosen,
    only for local addresses). Raises a one-line UsageError naming ``name``.
    """
    s = str(text).strip()
    scheme, sep, rest = s.partition(":")
    if sep and scheme.lower() in _SCHEMES:
        s = rest
    elif sep and scheme.lower() in ("tcp", "tcpin", "serial", "ws", "mcast", "udpbcast"):
        raise UsageError(f"{name}: only UDP is supported (udp:HOST:PORT, udpin:HOST:PORT or udpout:HOST:PORT), "
                         f"got {text!r}")
    if s.startswith("["):
        host, _, port_s = s[1:].partition("]")
        port_s = port_s[1:] if port_s.startswith(":") else ""
    else:
        host, _, port_s = s.rpartition(":")
    if not host or not port_s:
        raise UsageError(f"{name} must look like udp:HOST:PORT (e.g. udp:127.0.0.1:14601), got {text!r}")
    if ":" in host and not s.startswith("["):
        raise UsageError(f"{name}: write IPv6 hosts in brackets (udp:[::1]:PORT), got {text!r}")
    try:
        port = int(port_s)
    except ValueError:
        raise UsageError(f"{name}: port must be an integer 0-65535, got {port_s!r}") from None
    lo = 0 if allow_port_zero else 1
    if not lo <= port <= 65535:
        raise UsageError(f"{name}: port must be within [{lo}, 65535], got {port}")
    return host, port


def norm_host(host: str) -> str:
    """``host`` as a numeric address (``"localhost"`` -> ``"127.0.0.1"``), so it compares equal to a sender's."""
    try:
        return str(ipaddress.ip_address(host))
    except ValueError:
        try:
            return socket.gethostbyname(host)
        except OSError:
            raise UsageError(f"cannot resolve host {host!r}") from None


def set_rcvbuf(transport: asyncio.BaseTransport, size: int = RCVBUF_BYTES) -> None:
    """Ask the kernel for a larger receive buffer (best effort; capped by net.core.rmem_max)."""
    sock = transport.get_extra_info("socket")
    if sock is not None:
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, size)
        except OSError:
            pass


class MavEndpoint(asyncio.DatagramProtocol):
    """A MAVLink endpoint on one UDP socket. Create with :func:`open_endpoint`.

    Its receiving rules are an :class:`daa_sil.sil.intake.Intake` (``intake``: given, e.g. a
    protocol core's, or made from the keyword arguments). By default each good message goes to
    ``on_message`` (if given) under the guard, then to the bounded ``inbox``. With ``on_datagram``
    the endpoint is only the socket: each datagram goes to ``on_datagram(data, addr, now)`` as it
    arrives (the caller's core decodes it with the same intake)."""

    def __init__(self, codec: MavCodec, *, peer: "Address | None" = None, learn_peer: "bool | None" = None,
                 allow_peers: "Iterable[Address | str] | None" = None, allow_sysids: "Iterable[int] | None" = None,
                 inbox_size: int = 10_000, on_message: "Callable[[Received], None] | None" = None,
                 name: str = "daa-sil", peer_label: str = "", drop_hint: str = "",
                 drop_warn_every_s: float = 10.0, warn: "Callable[[str], None] | None" = None,
                 lock_peer: bool = False, guard: "MessageGuard | None" = None, intake: "Intake | None" = None,
                 on_datagram: "Callable[[bytes, Address, float], None] | None" = None):
        if intake is None:
            allowed = None
            if allow_peers is not None:
                allowed = [norm_host(a) if isinstance(a, str) else (norm_host(a[0]), int(a[1])) for a in allow_peers]
            intake = Intake(codec, peer=peer, learn_peer=learn_peer, allow_peers=allowed, allow_sysids=allow_sysids,
                            lock_peer=lock_peer, name=name, peer_label=peer_label, drop_hint=drop_hint,
                            drop_warn_every_s=drop_warn_every_s, warn=warn, guard=guard)
        self.intake = intake
        self.codec = intake.codec
        self.inbox: "asyncio.Queue[Received]" = asyncio.Queue(maxsize=inbox_size)
        self.on_message = on_message
        self.on_datagram = on_datagram
        self.transport: "asyncio.DatagramTransport | None" = None
        self._closed: "asyncio.Future | None" = None
        self.last_refused: "float | None" = None  #: time.monotonic() of the last ICMP port unreachable

    @property
    def peer(self) -> "Address | None":
        """The peer: fixed, or learned from the first good datagram (None before that)."""
        return self.intake.peer

    @peer.setter
    def peer(self, addr: "Address | None") -> None:
        self.intake.peer = addr

    @property
    def counters(self) -> EndpointCounters:
        return self.intake.counters

    @property
    def guard(self) -> MessageGuard:
        return self.intake.guard

    @property
    def drops(self) -> DropReporter:
        return self.intake.drops

    # -- asyncio protocol ----------------------------------------------------------------------
    def connection_made(self, transport) -> None:
        self.transport = transport
        set_rcvbuf(transport)
        self._closed = asyncio.get_running_loop().create_future()

    def connection_lost(self, exc) -> None:
        if self._closed is not None and not self._closed.done():
            self._closed.set_result(None)

    def error_received(self, exc) -> None:  # e.g. ICMP port unreachable on loopback
        self.counters.socket_errors += 1
        if isinstance(exc, ConnectionRefusedError):
            self.counters.refused += 1
            self.last_refused = time.monotonic()

    def datagram_received(self, data: bytes, addr) -> None:
        now = time.monotonic()
        if self.on_datagram is not None:
            self.on_datagram(data, (addr[0], addr[1]), now)
            return
        c = self.counters
        for item in self.intake.receive(data, addr, now):
            if self.on_message is not None and not self.guard.run(self.on_message, item):
                continue  # malformed (counted, reported): dropped; the datagram's other messages go on
            try:
                self.inbox.put_nowait(item)
                c.received += 1
            except asyncio.QueueFull:
                c.inbox_overflow += 1

    def send_datagram(self, data: bytes, addr: Address, messages: int = 1) -> bool:
        """Send encoded bytes (``messages`` packets) to ``addr``; False if the socket is closed."""
        if self.transport is None or self.transport.is_closing():
            self.counters.send_no_peer += 1
            return False
        self.transport.sendto(data, addr)
        self.counters.sent += messages
        self.counters.datagrams_sent += 1
        return True

    # -- API -------------------------------------------------------------------------------------
    @property
    def local_address(self) -> Address:
        """The bound ``(host, port)`` (the OS-chosen port if bound to port 0)."""
        if self.transport is None:
            raise RuntimeError("endpoint is not open")
        a = self.transport.get_extra_info("sockname")
        return a[0], a[1]

    def send(self, msg: MAVLinkMessage, addr: "Address | None" = None, link_id: "int | None" = None) -> bool:
        """Encode and send one message to ``addr`` (default: the peer). False if no peer yet.

        ``link_id``: signing stream override, e.g. ``CONTROL_LINK_ID`` for SIM_TICK / SIM_TICK_ACK.
        """
        return self.send_many([msg], addr, link_id)

    def send_many(self, msgs: "list[MAVLinkMessage]", addr: "Address | None" = None,
                  link_id: "int | None" = None) -> bool:
        """Encode several messages into one datagram and send it. False if no peer yet."""
        dest = addr or self.peer
        if dest is None or self.transport is None or self.transport.is_closing():
            self.counters.send_no_peer += 1
            return False
        data = self.codec.encode_many(msgs, link_id)
        self.transport.sendto(data, dest)
        self.counters.sent += len(msgs)
        self.counters.datagrams_sent += 1
        return True

    async def recv(self, timeout: "float | None" = None) -> Received:
        """Next good message (waits up to ``timeout`` s; raises ``asyncio.TimeoutError``)."""
        if timeout is None:
            return await self.inbox.get()
        return await asyncio.wait_for(self.inbox.get(), timeout)

    async def recv_match(self, msg_type: str, timeout: float) -> Received:
        """Next message of type ``msg_type`` (e.g. ``"HEARTBEAT"``) within ``timeout`` s; others are skipped."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout
        while True:
            left = deadline - loop.time()
            if left <= 0:
                raise asyncio.TimeoutError(f"no {msg_type} within {timeout} s")
            r = await self.recv(left)
            if r.msg.get_type() == msg_type:
                return r

    def stats(self) -> dict:
        """Transport and codec counters in one dict (``dropped`` = every rejected packet)."""
        return self.intake.stats()

    def close(self) -> None:
        """Close the socket (idempotent)."""
        if self.transport is not None and not self.transport.is_closing():
            self.transport.close()

    async def wait_closed(self) -> None:
        if self._closed is not None:
            await self._closed

    async def __aenter__(self) -> "MavEndpoint":
        return self

    async def __aexit__(self, *exc) -> None:
        self.close()
        await self.wait_closed()


async def open_endpoint(codec: MavCodec, local: "str | Address" = f"udp:{DEFAULT_HOST}:0", *,
                        peer: "str | Address | None" = None, **kwargs) -> MavEndpoint:
    """Bind a :class:`MavEndpoint` at ``local`` (default ``udp:127.0.0.1:0``), optionally with a fixed peer.

    ``kwargs`` go to :class:`MavEndpoint` (``learn_peer``, ``allow_peers``, ``allow_sysids``,
    ``inbox_size``, ``on_message``). Use as ``async with await open_endpoint(...) as ep:``.
    """
    laddr = parse_udp_address(local, "local address") if isinstance(local, str) else local
    paddr = parse_udp_address(peer, "peer address", allow_port_zero=False) if isinstance(peer, str) else peer
    if paddr is not None:
        paddr = (norm_host(paddr[0]), paddr[1])
    loop = asyncio.get_running_loop()
    try:
        _, proto = await loop.create_datagram_endpoint(lambda: MavEndpoint(codec, peer=paddr, **kwargs),
                                                       local_addr=laddr)
    except OSError as exc:
        raise UsageError(f"cannot bind {format_udp_address(laddr)}: {exc.strerror or exc}") from None
    return proto
