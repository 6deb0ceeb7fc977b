"""A TCP server for ground stations (``tcpin:HOST:PORT``, as ArduPilot SITL's 5760): only the socket.

:class:`TcpServer` accepts connections and hands everything to its owner's protocol core, which owns
the MAVLink side (framing, decoding, peers): ``on_connect(addr, now) -> bool`` when a client connects
(False: the core serves enough clients; the connection is closed at once and counted ``refused``),
``on_data(addr, data, now)`` for each piece of the stream, ``on_close(addr)`` when it ends. A client
may reconnect (it is a new connection, from a new address) and several may be connected at once.

Bounded: a client that does not read its telemetry fills its send buffer; past
:data:`MAX_CLIENT_BUFFER` bytes waiting, what the core sends it is dropped and counted
(``dropped_slow``) instead of growing the buffer. What a client sends is read as it comes (the core
keeps at most one unfinished packet per connection: :class:`daa_sil.link.framing.StreamFramer`).
Binds 127.0.0.1 by default; a taken port is a one-line :class:`UsageError`.
"""

from __future__ import annotations

import asyncio
import os
import socket
import time
from dataclasses import dataclass
from typing import Callable

from daa_sil.errors import UsageError
from daa_sil.sil.intake import Address

#: bytes waiting to be sent to one client past which what it is sent is dropped (a client that does not read)
MAX_CLIENT_BUFFER = 256 * 1024


@dataclass
class TcpCounters:
    connections: int = 0  #: clients accepted
    refused: int = 0  #: clients closed at once (the core serves enough)
    closed: int = 0  #: connections that ended
    bytes_in: int = 0
    bytes_out: int = 0
    sends: int = 0  #: datagrams' worth of bytes written
    dropped_slow: int = 0  #: sends dropped: the client's send buffer was past MAX_CLIENT_BUFFER
    send_no_client: int = 0  #: sends to a connection that had closed


class _Client(asyncio.Protocol):
    def __init__(self, server: "TcpServer"):
        self.server = server
        self.addr: "Address | None" = None
        self.transport: "asyncio.Transport | None" = None

    def connection_made(self, transport) -> None:
        self.transport = transport
        peer = transport.get_extra_info("peername")
        self.addr = (str(peer[0]), int(peer[1]))
        sock = transport.get_extra_info("socket")
        if sock is not None:
            try:
                sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)  # telemetry, not bulk: no Nagle delay
            except OSError:
                pass
        self.server.accepted(self)

    def data_received(self, data: bytes) -> None:
        self.server.received(self, data)

    def connection_lost(self, exc) -> None:
        self.server.lost(self)


class TcpServer:
    """One listening TCP socket and its clients (see the module docstring)."""

    def __init__(self, on_connect: "Callable[[Address, float], bool]",
                 on_data: "Callable[[Address, bytes, float], None]", on_close: "Callable[[Address], None]",
                 max_buffer: int = MAX_CLIENT_BUFFER, clock: "Callable[[], float]" = time.monotonic):
        self.on_connect, self.on_data, self.on_close = on_connect, on_data, on_close
        self.max_buffer, self.clock = int(max_buffer), clock
        self.clients: "dict[Address, _Client]" = {}
        self.counters = TcpCounters()
        self.server: "asyncio.AbstractServer | None" = None

    async def start(self, bind: Address) -> None:
        """Listen on ``bind`` ``(host, port)`` (port 0: OS-chosen)."""
        loop = asyncio.get_running_loop()
        try:
            self.server = await loop.create_server(lambda: _Client(self), bind[0], bind[1], reuse_address=True)
        except OSError as exc:
            h = f"[{bind[0]}]" if ":" in bind[0] else bind[0]
            why = os.strerror(exc.errno) if exc.errno else str(exc)
            raise UsageError(f"cannot listen on tcpin:{h}:{bind[1]}: {why}") from None

    @property
    def local_address(self) -> Address:
        a = self.server.sockets[0].getsockname()
        return a[0], a[1]

    # -- from the clients ----------------------------------------------------------------------
    def accepted(self, c: _Client) -> None:
        if not self.on_connect(c.addr, self.clock()):
            self.counters.refused += 1
            c.transport.close()
            c.addr = None  # its connection_lost must not end a served client's connection
            return
        self.counters.connections += 1
        self.clients[c.addr] = c

    def received(self, c: _Client, data: bytes) -> None:
        if c.addr is None or c.addr not in self.clients:
            return
        self.counters.bytes_in += len(data)
        self.on_data(c.addr, data, self.clock())

    def lost(self, c: _Client) -> None:
        if c.addr is not None and self.clients.get(c.addr) is c:
            del self.clients[c.addr]
            self.counters.closed += 1
            self.on_close(c.addr)

    # -- to the clients ------------------------------------------------------------------------
    def send(self, addr: Address, data: bytes) -> bool:
        """Write ``data`` to the client at ``addr``; False if it is gone or its send buffer is full (counted)."""
        c = self.clients.get((addr[0], addr[1]))
        if c is None or c.transport is None or c.transport.is_closing():
            self.counters.send_no_client += 1
            return False
        if c.transport.get_write_buffer_size() + len(data) > self.max_buffer:
            self.counters.dropped_slow += 1
            return False
        c.transport.write(data)
        self.counters.bytes_out += len(data)
        self.counters.sends += 1
        return True

    def close(self) -> None:
        """Stop listening and close every connection (idempotent)."""
        if self.server is not None:
            self.server.close()
        for c in list(self.clients.values()):
            if c.transport is not None:
                c.transport.close()
