"""The delay shim's two UDP sockets (vehicle side, GCS side): non-blocking, bound to 127.0.0.1 by
default, with kernel receive timestamps where the platform has them."""

from __future__ import annotations

import asyncio
import socket
from typing import Callable

from daa_sil.sil.endpoint import RCVBUF_BYTES, Address
from daa_sil.sil.rtclock import enable_rx_timestamps, rx_buffer_size, rx_time

#: ``on_datagram(data, addr, t_rx)``: ``t_rx`` the kernel arrival time (loop clock, s) or None
OnDatagram = Callable[[bytes, Address, "float | None"], None]


class ShimSocket:
    """One shim socket, read with ``recvmsg`` from a loop reader (kernel arrival stamps if enabled).

    Each datagram read goes to ``on_datagram``, which must not raise (the shim runs it under its
    message guard). Socket errors are counted here (``socket_errors``, ``send_would_block``).
    """

    #: datagrams read per reader callback before timers get their turn
    BURST = 64

    def __init__(self, loop: asyncio.AbstractEventLoop, sock: socket.socket, stamped: bool,
                 on_datagram: OnDatagram):
        self.loop, self.sock, self.on_datagram = loop, sock, on_datagram
        self.stamped = stamped and enable_rx_timestamps(sock)
        self._anc = rx_buffer_size() if self.stamped else 0
        self.closed = False
        self.socket_errors = 0
        self.send_would_block = 0
        loop.add_reader(sock.fileno(), self._readable)

    @property
    def sockname(self) -> Address:
        a = self.sock.getsockname()
        return a[0], a[1]

    def _readable(self) -> None:
        for _ in range(self.BURST):
            try:
                data, anc, _flags, addr = self.sock.recvmsg(65535, self._anc)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:  # e.g. ICMP port unreachable reported on this socket
                self.socket_errors += 1
                continue
            self.on_datagram(data, (addr[0], addr[1]), rx_time(anc) if self.stamped else None)

    def sendto(self, data: bytes, addr: Address) -> bool:
        """Send one datagram; False (counted) if the socket refused it."""
        try:
            self.sock.sendto(data, addr)
            return True
        except (BlockingIOError, InterruptedError):
            self.send_would_block += 1
        except OSError:
            self.socket_errors += 1
        return False

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            try:
                self.loop.remove_reader(self.sock.fileno())
            except (RuntimeError, ValueError):
                pass
            self.sock.close()


def bind_udp(addr: Address) -> socket.socket:
    """A non-blocking UDP socket bound to ``addr`` with a large receive buffer."""
    family, _, _, _, sockaddr = socket.getaddrinfo(addr[0], addr[1], type=socket.SOCK_DGRAM)[0]
    sock = socket.socket(family, socket.SOCK_DGRAM)
    try:
        sock.setblocking(False)
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RCVBUF_BYTES)
        except OSError:
            pass
        sock.bind(sockaddr)
    except OSError:
        sock.close()
        raise
    return sock
