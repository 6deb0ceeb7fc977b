"""asyncio UDP endpoint around :class:`daa_sil.link.codec.MavCodec`, and address parsing.

One ``asyncio.DatagramProtocol`` per endpoint (no ``mavutil``: it blocks the loop). Each received
datagram is decoded on its own (parser reset per datagram); good messages go to an async inbox
as :class:`Received` tuples. Everything hostile is counted and dropped:

* packets from addresses outside ``allow_peers``: they are still decoded, *without changing any
  signing state* (``MavCodec.decode(..., commit=False)``), so each is counted once under its codec
  reason (unsigned, bad signature, replayed, stale, bad CRC, ...) or, if it is a good packet, as
  ``rejected_peer``; ``datagrams_rejected_peer`` counts their datagrams. Not committing matters:
  an early copy of a genuine signed packet sent from another port must not advance the stream's
  replay window and so turn the genuine packet (arriving later through the shim) into a "replay";
* messages whose source system id is outside ``allow_sysids`` (``rejected_sysid``);
* codec rejections (bad CRC, prefix, truncated, unknown, malformed, unsigned, bad signature,
  replayed, stale);
* messages arriving while the inbox is full (``inbox_overflow``; the inbox is bounded).

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

Handling: each good message goes to ``on_message`` (if given) under the endpoint's
:class:`daa_sil.sil.msgguard.MessageGuard` (an exception there counts the message as malformed,
``malformed_content``, drops it, and the next message of the datagram is still handled), then to the inbox;
consumers of the inbox run their handling under the same guard (``ep.guard.run(handler, r)``).
Binds 127.0.0.1 by default and asks for a 4 MB receive buffer (the default 212 KB overflows on
bursts: a lockstep step delivers every delayed packet of both
directions at once).
"""

from __future__ import annotations

import asyncio
import ipaddress
import socket
import time
from collections import Counter
from dataclasses import dataclass
from typing import Callable, Iterable, NamedTuple

from daa_sil.errors import UsageError
from daa_sil.link.codec import MavCodec, MAVLinkMessage
from daa_sil.sil.msgguard import MessageGuard, stderr_line

Address = tuple[str, int]
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


def format_udp_address(addr: Address) -> str:
    """``("127.0.0.1", 14601)`` -> ``"udp:127.0.0.1:14601"``."""
    host = addr[0]
    return f"udp:[{host}]:{addr[1]}" if ":" in host else f"udp:{host}:{addr[1]}"


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


class DropReporter:
    """Warn once per unexpected sender, then periodically with counts, while its datagrams are dropped.

    ``note(addr, what)`` counts one dropped datagram from ``addr`` (``what``: e.g. ``"HEARTBEAT from
    system 1"``, or ""). The first drop from each of up to ``max_named`` distinct addresses is
    reported at once; after that one summary line at most every ``every_s`` seconds (``clock``
    seconds) while drops continue: how many in the interval and in all, per address (top 3).
    Lines go to ``emit`` (default: stderr) as ``"{who}: warning: ..."``. ``expected()`` names the
    peer that is accepted (called when a line is made, so a learned peer shows up).
    """

    def __init__(self, who: str, expected: "Callable[[], str]", *, hint: str = "",
                 emit: "Callable[[str], None] | None" = None, every_s: float = 10.0,
                 clock: "Callable[[], float]" = time.monotonic, max_named: int = 8):
        self.who, self.expected, self.hint = who, expected, hint
        self.emit = emit or stderr_line
        self.every_s, self.clock, self.max_named = float(every_s), clock, int(max_named)
        self.by_addr: Counter = Counter()
        self.total = 0
        self.lines = 0
        self._since = 0
        self._next: "float | None" = None

    def note(self, addr: "Address", what: str = "") -> None:
        """Count one dropped datagram from ``addr``; maybe emit a line."""
        addr = (addr[0], addr[1])
        new = addr not in self.by_addr
        self.by_addr[addr] += 1
        self.total += 1
        self._since += 1
        now = self.clock()
        if new and len(self.by_addr) <= self.max_named:
            self._say(f"dropping datagrams from {format_udp_address(addr)}"
                      f"{f' ({what})' if what else ''}: not the expected peer {self.expected()}"
                      f"{'; ' + self.hint if self.hint else ''}")
            self._since = 0
            if self._next is None:
                self._next = now + self.every_s
        elif self._next is None or now >= self._next:
            top = ", ".join(f"{format_udp_address(a)}: {n}" for a, n in self.by_addr.most_common(3))
            more = f" and {len(self.by_addr) - 3} more" if len(self.by_addr) > 3 else ""
            self._say(f"still dropping datagrams from unexpected peers: {self._since} in the last "
                      f"{self.every_s:g} s, {self.total} in all ({top}{more}); expected {self.expected()}")
            self._since = 0
            self._next = now + self.every_s

    def _say(self, text: str) -> None:
        self.lines += 1
        self.emit(f"{self.who}: warning: {text}")

    def summary(self) -> "str | None":
        """One line with the totals (None if nothing was dropped), e.g. for a process's last words."""
        if not self.total:
            return None
        top = ", ".join(f"{format_udp_address(a)}: {n}" for a, n in self.by_addr.most_common(3))
        return f"dropped {self.total} datagrams from unexpected peers ({top}); expected {self.expected()}"


class Received(NamedTuple):
    """One good message: monotonic arrival time (s), sender address, the message."""

    t: float
    addr: Address
    msg: MAVLinkMessage


@dataclass
class EndpointCounters:
    """Transport-level counts (codec-level ones are merged in :meth:`MavEndpoint.stats`)."""

    sent: int = 0  # messages sent
    datagrams_sent: int = 0
    send_no_peer: int = 0  # send attempts before a peer was known
    received: int = 0  # good messages delivered to the inbox
    datagrams_received: int = 0
    rejected_peer: int = 0  # good packets from an address outside allow_peers (bad ones: codec reasons)
    datagrams_rejected_peer: int = 0  # datagrams from an address outside allow_peers
    rejected_sysid: int = 0
    inbox_overflow: int = 0
    socket_errors: int = 0
    refused: int = 0  # ICMP port unreachable: nothing listens where we send (part of socket_errors)


class MavEndpoint(asyncio.DatagramProtocol):
    """A MAVLink endpoint on one UDP socket. Create with :func:`open_endpoint`."""

    def __init__(self, codec: MavCodec, *, peer: "Address | None" = None, learn_peer: "bool | None" = None,
                 allow_peers: "Iterable[Address | str] | None" = None, allow_sysids: "Iterable[int] | None" = None,
                 inbox_size: int = 10_000, on_message: "Callable[[Received], None] | None" = None,
                 name: str = "daa-sil", peer_label: str = "", drop_hint: str = "",
                 drop_warn_every_s: float = 10.0, warn: "Callable[[str], None] | None" = None,
                 lock_peer: bool = False, guard: "MessageGuard | None" = None):
        self.codec = codec
        self.peer = peer
        self.learn_peer = (peer is None) if learn_peer is None else bool(learn_peer)
        self.lock_peer = bool(lock_peer)
        #: every message's handling runs under it (shared with the node that owns the endpoint)
        self.guard = guard if guard is not None else MessageGuard(name, emit=warn)
        self._allow_hosts: "set[str] | None" = None
        self._allow_addrs: "set[Address] | None" = None
        if allow_peers is not None:
            self._allow_hosts, self._allow_addrs = set(), set()
            for a in allow_peers:
                if isinstance(a, str):
                    self._allow_hosts.add(norm_host(a))
                else:
                    self._allow_addrs.add((norm_host(a[0]), int(a[1])))
        self.allow_sysids = None if allow_sysids is None else frozenset(int(s) for s in allow_sysids)
        self.inbox: "asyncio.Queue[Received]" = asyncio.Queue(maxsize=inbox_size)
        self.on_message = on_message
        self.counters = EndpointCounters()
        self.transport: "asyncio.DatagramTransport | None" = None
        self._closed: "asyncio.Future | None" = None
        self.last_refused: "float | None" = None  #: time.monotonic() of the last ICMP port unreachable
        self.peer_label = peer_label
        self.drops = DropReporter(name, self._expected_text, hint=drop_hint, emit=warn, every_s=drop_warn_every_s)

    def _expected_text(self) -> str:
        addrs = sorted(self._allow_addrs or ())
        if self.peer is not None and (not addrs or self.lock_peer) and tuple(self.peer) not in addrs:
            addrs = [tuple(self.peer)] + addrs
        who = ", ".join(format_udp_address(a) for a in addrs) if addrs else "(none yet)"
        return who + (f" ({self.peer_label})" if self.peer_label else "")

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

    def _listed(self, addr: Address) -> bool:
        return self._allow_hosts is not None and (addr[0] in self._allow_hosts or (addr[0], addr[1]) in self._allow_addrs)

    def _peer_allowed(self, addr: Address) -> bool:
        if self.lock_peer:  # the learned peer (or, before one is learned, anyone) and the allowed list
            return self._listed(addr) or self.peer is None or (addr[0], addr[1]) == tuple(self.peer)
        if self._allow_hosts is None:
            return True
        return self._listed(addr)

    def datagram_received(self, data: bytes, addr) -> None:
        c = self.counters
        c.datagrams_received += 1
        addr = (addr[0], addr[1])
        if not self._peer_allowed(addr):
            c.datagrams_rejected_peer += 1
            good = self.codec.decode(data, commit=False)
            c.rejected_peer += len(good)
            what = f"{good[0].get_type()} from system {good[0].get_srcSystem()}" if good else "no valid MAVLink"
            self.drops.note(addr, what)
            return
        msgs = self.codec.decode(data)
        if not msgs:
            return
        if self.allow_sysids is not None:
            keep = [m for m in msgs if m.get_srcSystem() in self.allow_sysids]
            c.rejected_sysid += len(msgs) - len(keep)
            msgs = keep
            if not msgs:
                return
        if self.peer is None and self.learn_peer and not (self.lock_peer and self._listed(addr)):
            self.peer = addr
        now = time.monotonic()
        for m in msgs:
            item = Received(now, addr, m)
            if self.on_message is not None and not self.guard.run(self.on_message, item):
                continue  # malformed (counted, reported): dropped; the datagram's other messages go on
            try:
                self.inbox.put_nowait(item)
                c.received += 1
            except asyncio.QueueFull:
                c.inbox_overflow += 1

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
        d = dict(self.codec.counters.as_dict())
        d.update(self.counters.__dict__)
        d["malformed_content"] = self.guard.total  # decoded, but its handling raised (msgguard)
        d["dropped"] = (self.codec.counters.dropped + self.counters.rejected_peer + self.counters.rejected_sysid
                        + self.counters.inbox_overflow + self.guard.total)
        return d

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
