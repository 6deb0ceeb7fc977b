"""The delay shim's two UDP sockets (vehicle side, GCS side): non-blocking, bound to 127.0.0.1 by
default, with kernel receive timestamps where the platform has them."""

from __future__ import annotations

import socket
from typing import TYPE_CHECKING

from daa_sil.sil.endpoint import RCVBUF_BYTES, Address
from daa_sil.sil.rtclock import enable_rx_timestamps, rx_buffer_size, rx_time

if TYPE_CHECKING:
    from daa_sil.sil.shim import DelayShim


class ShimSocket:
    """One shim socket, read with ``recvmsg`` from a loop reader (kernel arrival stamps if enabled)."""

    #: datagrams read per reader callback before timers get their turn
    BURST = 64

    def __init__(self, shim: "DelayShim", name: str, sock: socket.socket, stamped: bool):
        self.shim, self.name, self.sock = shim, name, sock
        self.stamped = stamped and enable_rx_timestamps(sock)
        self._anc = rx_buffer_size() if self.stamped else 0
        self.closed = False
        shim._loop.add_reader(sock.fileno(), self._readable)

    @property
    def sockname(self) -> Address:
        a = self.sock.getsockname()
        return a[0], a[1]

    def _readable(self) -> None:
        shim, counters = self.shim, self.shim.counters
        for _ in range(self.BURST):
            try:
                data, anc, _flags, addr = self.sock.recvmsg(65535, self._anc)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:  # e.g. ICMP port unreachable reported on this socket
                counters["socket_errors"] += 1
                continue
            # under the guard: a datagram whose handling raises is counted as malformed, the burst goes on
            shim.guard.call(shim._on_datagram, self.name, data, (addr[0], addr[1]),
                            rx_time(anc) if self.stamped else None, what=f"datagram from the {self.name} side",
                            source=addr)

    def sendto(self, data: bytes, addr: Address) -> bool:
        try:
            self.sock.sendto(data, addr)
            return True
        except (BlockingIOError, InterruptedError):
            self.shim.counters["send_would_block"] += 1
        except OSError:
            self.shim.counters["socket_errors"] += 1
        return False

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            try:
                self.shim._loop.remove_reader(self.sock.fileno())
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
