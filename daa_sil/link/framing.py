"""MAVLink over a byte stream (TCP), sans-IO: cut the stream into whole packets for the datagram codec.

A TCP connection delivers bytes in arbitrary pieces: a packet may be split over two reads, and one read
may hold many packets. :class:`StreamFramer` keeps what it has not yet seen whole and returns, for each
piece fed, the bytes up to the end of the last whole packet; :meth:`daa_sil.link.codec.MavCodec.decode`
then treats those bytes as it treats a datagram (every packet checked on its own, bad ones counted and
dropped). The cut follows the codec's header walk: bytes before a start marker (``0xFD`` MAVLink 2,
``0xFE`` MAVLink 1) are passed on (the codec counts them as ``bad_prefix``), a packet's size is read
from its header (length, and the signature flag of MAVLink 2).

Bounded: what is kept between pieces is at most one unfinished packet, :data:`MAX_PACKET` bytes, whatever
the sender does. A garbage start marker may make the framer wait for up to that many bytes and pass them
on as one bad packet; the walk then goes on from the next byte after it, as the codec's does.
"""

from __future__ import annotations

#: longest MAVLink packet: MAVLink 2 header 10 + payload 255 + CRC 2 + signature 13
MAX_PACKET = 280
STX_V2, STX_V1 = 0xFD, 0xFE


def packet_size(buf: "bytes | bytearray", i: int) -> "int | None":
    """Size (bytes) of the packet starting with a start marker at ``buf[i]``; None if its header is not all in."""
    left = len(buf) - i
    if buf[i] == STX_V2:
        return buf[i + 1] + 12 + (13 if buf[i + 2] & 1 else 0) if left >= 3 else None
    return buf[i + 1] + 8 if left >= 2 else None


class StreamFramer:
    """Whole packets out of a byte stream (see the module docstring). ``pending`` bytes are kept between
    calls (at most :data:`MAX_PACKET`)."""

    def __init__(self) -> None:
        self._buf = bytearray()
        self.bytes_in = 0

    @property
    def pending(self) -> int:
        return len(self._buf)

    def feed(self, data: "bytes | bytearray | memoryview") -> bytes:
        """Take the next piece of the stream; returns the bytes up to the end of the last whole packet (may be
        ``b""``), to decode as one datagram."""
        self.bytes_in += len(data)
        buf = self._buf
        buf += data
        n = len(buf)
        i = done = 0
        while i < n:
            b = buf[i]
            if b != STX_V2 and b != STX_V1:  # garbage up to the next start marker: passed on, counted by the codec
                j1, j2 = buf.find(b"\xfd", i + 1), buf.find(b"\xfe", i + 1)
                i = done = min(j for j in (j1, j2, n) if j >= 0)
                continue
            size = packet_size(buf, i)
            if size is None or i + size > n:
                break
            i = done = i + size
        out = bytes(buf[:done])
        del buf[:done]
        return out
