"""Seeded MAVLink datagram fuzzer (sans-IO): hostile datagrams for robustness tests.

:class:`Fuzzer` turns genuine captured datagrams into hostile ones, reproducibly from a seed
(``numpy.random.Generator``; the same seed and corpus give the same byte strings). Kinds:

* ``bitflip``: a genuine datagram with 1-3 random bit flips *in every packet* (CRC-16/X.25 detects
  every error of up to 3 bits in packets this short, so no genuine packet survives intact and
  none turns into another valid one, except by a framing change that a 1-in-65536 CRC match
  accepts);
* ``truncated``: one genuine packet cut at a random byte (at least one byte kept);
* ``oversized``: 281 bytes up to the UDP maximum 65,507 bytes (log-uniform length ``n``): genuine
  packets, each with 1-3 bit flips, back to back and cut at ``n`` (the last packet may be cut: a
  datagram is never longer than :data:`UDP_MAX`, so a relay can always send it on), or random bytes
  behind a MAVLink 2 start marker;
* ``random``: 1-300 uniform random bytes (some start with 0xFD / 0xFE);
* ``splice``: the head of one genuine datagram glued to the tail of another;
* ``empty``: a zero-length datagram;
* ``crafted``: a *well-formed* MAVLink 2 packet with a valid CRC but hostile content (see
  :func:`crafted_packets`): wrong source system id, a message id the dialect does not know, pilot
  commands with NaN / infinite / out-of-range values, a wrong target or a send time far in the
  future. None of them may change the flown command.

The fuzzer only builds bytes; the test decides where they go.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from .codec import MavCodec, mavlink as M

#: largest UDP payload over IPv4 (bytes)
UDP_MAX = 65_507
#: longest MAVLink 2 packet (bytes): 10 header + 255 payload + 2 CRC + 13 signature
MAVLINK_MAX = 280
KINDS = ("bitflip", "truncated", "oversized", "random", "splice", "empty", "crafted")
#: default mix (probabilities, same order as KINDS)
DEFAULT_MIX = (0.40, 0.15, 0.05, 0.15, 0.05, 0.005, 0.195)


def split_packets(datagram: bytes) -> list[bytes]:
    """The MAVLink packets of a (good) datagram by header walk; trailing garbage is dropped."""
    out, i, n = [], 0, len(datagram)
    while i + 3 <= n and datagram[i] in (0xFD, 0xFE):
        size = (datagram[i + 1] + 12 + (13 if datagram[i + 2] & 1 else 0)) if datagram[i] == 0xFD \
            else datagram[i + 1] + 8
        if i + size > n:
            break
        out.append(datagram[i:i + size])
        i += size
    return out


def crafted_packets(kind: str, t_now_s: float, rng: np.random.Generator) -> bytes:
    """One well-formed, valid-CRC packet of hostile content ``kind`` (see :data:`CRAFTED`).

    ``t_now_s``: the current sim time (s), for send-time stamps. Returns the packet bytes.
    """
    gcs = MavCodec(255, 190)
    nan, inf = math.nan, math.inf
    ms = int(max(0.0, t_now_s) * 1000)
    seq = int(rng.integers(1, 1 << 16))
    if kind == "cmd_nan":  # every field "keep current": not a command
        return gcs.encode(M.MAVLink_pilot_maneuver_message(ms, seq, 1, 1, nan, nan, nan))
    if kind == "cmd_inf":
        return gcs.encode(M.MAVLink_pilot_maneuver_message(ms, seq, 1, 1, inf, 0.0, 55.0))
    if kind == "cmd_range":  # track / gs / vs out of range
        trk, vs, gs = [(720.0, 0.0, 55.0), (90.0, 0.0, 5000.0), (90.0, -900.0, 55.0), (-45.0, 0.0, 55.0),
                       (90.0, 0.0, -10.0)][int(rng.integers(5))]
        return gcs.encode(M.MAVLink_pilot_maneuver_message(ms, seq, 1, 1, trk, vs, gs))
    if kind == "cmd_future":  # stamped far ahead of the vehicle's clock (would lock out the real GCS)
        return gcs.encode(M.MAVLink_pilot_maneuver_message(ms + 3_600_000, seq, 1, 1, 90.0, 0.0, 55.0))
    if kind == "cmd_target":  # addressed to another vehicle
        return gcs.encode(M.MAVLink_pilot_maneuver_message(ms, seq, 42, 1, 90.0, 0.0, 55.0))
    if kind == "setpos_nan":  # stock velocity setpoint with NaN velocities
        return gcs.encode(M.MAVLink_set_position_target_global_int_message(
            ms, 1, 1, 6, 0x0DC7, 0, 0, 0.0, nan, nan, nan, 0, 0, 0, 0, 0))
    if kind == "setpos_mask":  # velocity marked "ignore": not a velocity setpoint
        return gcs.encode(M.MAVLink_set_position_target_global_int_message(
            ms, 1, 1, 6, 0x0FFF, 0, 0, 0.0, 55.0, 0.0, 0.0, 0, 0, 0, 0, 0))
    if kind == "sysid_self":  # claims to be the vehicle itself (sysid 1)
        return MavCodec(1, 1).encode(M.MAVLink_pilot_maneuver_message(ms, seq, 1, 1, 90.0, 0.0, 55.0))
    if kind == "sysid_other":  # telemetry from a stranger system (GCS only accepts sysid 1)
        return MavCodec(int(rng.integers(2, 250)), 1).encode(
            M.MAVLink_local_position_ned_message(ms, nan, inf, -1e9, nan, 0.0, 0.0))
    if kind == "unknown_id":  # valid MAVLink 2 framing and CRC, message id unknown to the dialect
        payload = rng.integers(0, 256, size=int(rng.integers(1, 40)), dtype=np.uint8).tobytes()
        return _raw_v2(payload, 255, 190, 60_000 + int(rng.integers(0, 5000)), crc_extra=int(rng.integers(256)))
    raise ValueError(f"unknown crafted kind {kind!r}")


#: crafted hostile-content kinds (each valid CRC); "vehicle" ones target the vehicle, "gcs" ones the GCS
CRAFTED = {"vehicle": ("cmd_nan", "cmd_inf", "cmd_range", "cmd_future", "cmd_target", "setpos_nan",
                       "setpos_mask", "sysid_self", "unknown_id"),
           "gcs": ("sysid_other", "unknown_id")}


def _raw_v2(payload: bytes, sysid: int, compid: int, msgid: int, crc_extra: int, seq: int = 0) -> bytes:
    """A MAVLink 2 packet with a correct X.25 CRC for ``crc_extra`` (used for unknown ids)."""
    hdr = struct.pack("<BBBBBBBHB", 0xFD, len(payload), 0, 0, seq, sysid, compid, msgid & 0xFFFF, msgid >> 16)
    crc = M.x25crc(hdr[1:] + payload)
    crc.accumulate(bytes([crc_extra]))
    return hdr + payload + struct.pack("<H", crc.crc)


@dataclass
class Fuzzer:
    """Seeded generator of hostile datagrams from a corpus of genuine ones.

    ``corpus``: genuine datagrams (bytes) captured on the link; ``seed``: int; ``mix``: probability
    per kind (:data:`KINDS` order); ``crafted``: the crafted kinds to draw from.
    """

    corpus: Sequence[bytes]
    seed: int = 0
    mix: Sequence[float] = DEFAULT_MIX
    crafted: Sequence[str] = CRAFTED["vehicle"]
    counts: dict = field(default_factory=lambda: {k: 0 for k in KINDS})

    def __post_init__(self):
        if not self.corpus:
            raise ValueError("the fuzzer needs at least one genuine datagram")
        p = np.asarray(self.mix, float)
        if p.shape != (len(KINDS),) or np.any(p < 0) or p.sum() <= 0:
            raise ValueError(f"mix must be {len(KINDS)} non-negative weights")
        self._p = p / p.sum()
        self.rng = np.random.default_rng(self.seed)
        self._packets = [pk for d in self.corpus for pk in split_packets(d)] or list(self.corpus)
        self._genuine = sorted(set(self._packets))

    def _pick(self) -> bytes:
        """One genuine packet."""
        return bytes(self._packets[int(self.rng.integers(len(self._packets)))])

    def _flip_each(self, data: bytes) -> bytes:
        """1-3 bit flips in every packet of a genuine datagram."""
        return b"".join(self._flip(p, int(self.rng.integers(1, 4))) for p in split_packets(data) or [data])

    def _flip(self, data: bytes, n: int) -> bytes:
        b = bytearray(data)
        for pos in self.rng.choice(len(b) * 8, size=min(n, len(b) * 8), replace=False):
            b[pos >> 3] ^= 1 << (pos & 7)
        return bytes(b)

    def next(self, t_now_s: float = 0.0) -> tuple[str, bytes]:
        """One hostile datagram: ``(kind, bytes)``; ``t_now_s`` (s) stamps crafted commands.

        No datagram except ``crafted`` ones contains a genuine packet intact (replays of captured
        packets are the signing tests' business): any that would is corrupted by one more flip.
        """
        kind, data = self._next(t_now_s)
        if kind != "crafted" and data:
            data = self._scrub(data)
        return kind, data

    def _scrub(self, data: bytes) -> bytes:
        b = None
        for p in self._genuine:
            i = data.find(p)
            while i >= 0:
                b = bytearray(data) if b is None else b
                b[i + len(p) - 1] ^= 0x01  # CRC high byte
                data = bytes(b)
                i = data.find(p, i + 1)
        return data

    def _next(self, t_now_s: float) -> tuple[str, bytes]:
        rng = self.rng
        kind = KINDS[int(rng.choice(len(KINDS), p=self._p))]
        self.counts[kind] += 1
        if kind == "bitflip":
            return kind, self._flip_each(bytes(self.corpus[int(rng.integers(len(self.corpus)))]))
        if kind == "truncated":
            d = self._pick()
            return kind, d[:int(rng.integers(1, len(d)))] if len(d) > 1 else d
        if kind == "oversized":
            n = int(math.exp(rng.uniform(math.log(MAVLINK_MAX + 1), math.log(UDP_MAX))))
            if rng.random() < 0.5:
                parts, size = [], 0
                while size < n:
                    parts.append(self._flip(self._pick(), int(rng.integers(1, 4))))
                    size += len(parts[-1])
                return kind, b"".join(parts)[:n]  # n <= UDP_MAX: the whole last packet could overshoot it
            return kind, b"\xfd" + rng.integers(0, 256, size=n - 1, dtype=np.uint8).tobytes()
        if kind == "random":
            d = rng.integers(0, 256, size=int(rng.integers(1, 301)), dtype=np.uint8).tobytes()
            if rng.random() < 0.5:
                d = bytes([0xFD if rng.random() < 0.8 else 0xFE]) + d[1:]
            return kind, d
        if kind == "splice":
            a, b = self._pick(), self._pick()
            i, j = int(rng.integers(1, len(a))), int(rng.integers(1, len(b)))
            if a == b and i == j:  # would rebuild the genuine packet
                j = j + 1 if j + 1 < len(b) else j - 1
            return kind, a[:i] + b[j:]
        if kind == "empty":
            return kind, b""
        return kind, crafted_packets(self.crafted[int(rng.integers(len(self.crafted)))], t_now_s, rng)
