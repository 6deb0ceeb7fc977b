"""Sans-IO MAVLink 2 codec for UDP: datagram bytes -> messages, messages -> bytes, optional signing.

Built on the generated :mod:`daa_sil.link.dialect.daa_sil` module (pymavlink mavgen output).
Network input is hostile, so decoding follows these rules (docs/sil.md, "Signing and spoofing"):

* each datagram is split into packets by a header walk and each packet decoded on its own (no
  stream-parser state survives a datagram, the effect of "reset the parser per datagram" without
  its cost): a truncated datagram never corrupts the next one;
* bad CRC, bad prefix, truncated, unknown-id, malformed, unsigned, wrong-key, replayed and stale
  packets are counted (:class:`CodecCounters`) and dropped; ``decode`` only returns good messages
  and never raises on bad input;
* with ``read_ids`` (the ids its owner reads; the GCS reads 7 of the 15 types the vehicle streams), a
  MAVLink 2 packet of another id goes through every check ``decode`` makes -- CRC, signature, replay
  and staleness, with the same signing-state changes (:meth:`SecureMAVLink.verify`) -- and is counted
  as ``unread`` instead of being unpacked into a message nobody reads.

Signing (MAVLink 2, 32-byte secret key): when a key is set, outgoing packets are signed and
incoming ones must carry a valid signature (except message ids listed in ``allow_unsigned``).
pymavlink's own ``check_signature`` records a stream's timestamp *before* comparing the
signature, so one forged packet with a far-future timestamp locks the real stream out. The
:class:`SecureMAVLink` subclass here verifies the signature first and only then applies the
replay (timestamp must increase per ``(link_id, sysid, compid)`` stream) and staleness (a new
stream may be at most 60 s behind our clock) checks, then updates the stream timestamp.
Outgoing signing timestamps follow the wall clock (10 us units since 2015-01-01), so they never
go backwards across restarts.

Key files are read and written by :mod:`daa_sil.link.keys`.
"""

from __future__ import annotations

import hashlib
import time
from dataclasses import dataclass
from typing import Callable, Iterable

from ..errors import UsageError
from .dialect import daa_sil as mavlink
from .keys import KEY_LEN

MAVError = mavlink.MAVError
MAVLinkMessage = mavlink.MAVLink_message

#: signing epoch (2015-01-01 00:00:00 UTC) in UNIX seconds
SIGNING_EPOCH_UNIX = 1420070400
#: a new signed stream may be at most this far behind our timestamp (10 us units) = 60 s
STALE_LIMIT = 6_000_000
#: signing link id for lockstep control messages (see :meth:`MavCodec.encode`)
CONTROL_LINK_ID = 254


def signing_timestamp_now() -> int:
    """Current wall time as a MAVLink signing timestamp (10 us units since 2015-01-01)."""
    return int((time.time() - SIGNING_EPOCH_UNIX) * 100_000)


@dataclass
class CodecCounters:
    """Per-codec counts. ``dropped`` is the sum of every rejection reason."""

    datagrams_in: int = 0
    bytes_in: int = 0
    messages_in: int = 0  # good messages returned by decode
    bad_crc: int = 0
    bad_prefix: int = 0
    truncated: int = 0  # datagrams that ended inside a packet
    unknown: int = 0  # well-formed packets with a message id the dialect does not know
    malformed: int = 0  # bad length, bad flags, unpack failures, anything else
    unsigned: int = 0  # unsigned packets refused because signing is required
    unsigned_accepted: int = 0  # unsigned packets let through by ``allow_unsigned``
    signed_in: int = 0  # good messages that carried a valid signature (of messages_in)
    unread: int = 0  # good packets of an id outside read_ids: verified, not unpacked (not in messages_in)
    shed: int = 0  # packets the caller's ``admit`` refused before any check (its queue for them was full)
    bad_signature: int = 0  # wrong key or forged signature
    replayed: int = 0  # signature timestamp not newer than the stream's last one
    stale: int = 0  # new stream more than 60 s behind our clock
    datagrams_out: int = 0
    messages_out: int = 0
    bytes_out: int = 0

    @property
    def dropped(self) -> int:
        return (self.bad_crc + self.bad_prefix + self.truncated + self.unknown + self.malformed
                + self.unsigned + self.bad_signature + self.replayed + self.stale + self.shed)

    def as_dict(self) -> dict:
        d = dict(self.__dict__)
        d["dropped"] = self.dropped
        return d


class SecureMAVLink(mavlink.MAVLink):
    """The generated ``MAVLink`` class with a signature check that verifies before it updates."""

    _sig_reason: "str | None" = None
    n_unsigned_accepted = 0
    #: False = dry run: check signatures and timestamps but change no stream state (packets from a
    #: sender that will be dropped anyway must not advance the replay window: no pre-play lock-out)
    commit = True

    def decode(self, msgbuf: bytearray) -> MAVLinkMessage:  # noqa: D401 (pymavlink API)
        self._sig_reason = None
        try:
            m = super().decode(msgbuf)
            if self._sig_reason == "unsigned_accepted" and self.commit:
                self.n_unsigned_accepted += 1
            return m
        except MAVError as exc:
            if exc.message == "Invalid signature":
                raise MAVError("signature:" + (self._sig_reason or "unsigned")) from None
            raise

    def check_signature(self, msgbuf: bytearray, srcSystem: int, srcComponent: int) -> bool:
        """Verify the signature, then the timestamp; update stream state only for good packets."""
        signing = self.signing
        h = hashlib.sha256(signing.secret_key)
        h.update(msgbuf[:-6])
        if h.digest()[:6] != bytes(msgbuf[-6:]):
            self._sig_reason = "bad_signature"
            return False
        tlow, thigh = self.mav_sign_unpacker.unpack(msgbuf[-12:-6])
        timestamp = tlow + (thigh << 32)
        stream = (msgbuf[-13], srcSystem, srcComponent)
        last = signing.stream_timestamps.get(stream)
        if last is not None:
            if timestamp <= last:
                self._sig_reason = "replayed"
                return False
        elif timestamp + STALE_LIMIT < signing.timestamp:
            self._sig_reason = "stale"
            return False
        if self.commit:
            signing.stream_timestamps[stream] = timestamp
            if timestamp > signing.timestamp:
                signing.timestamp = timestamp
        return True

    def verify(self, msgbuf: bytearray, msg_id: int) -> "str | None":
        """The checks :meth:`decode` makes on one whole MAVLink 2 packet of id ``msg_id``, without
        unpacking its payload: None if it would decode, else the :class:`CodecCounters` field that counts
        it (``unknown``, ``bad_crc``, ``unsigned``, ``bad_signature``, ``replayed``, ``stale``). The
        signing state changes as :meth:`decode` changes it. (The header walk of
        :meth:`MavCodec.decode` has already cut the packet to its length and refused unknown
        incompatibility flags; a payload that passes these checks always unpacks: a short one is
        zero-filled, a long one cut.)"""
        msgtype = mavlink.mavlink_map.get(msg_id)
        if msgtype is None:  # (before the CRC, as decode: its CRC_EXTRA is unknown)
            return "unknown"
        sig_len = mavlink.MAVLINK_SIGNATURE_BLOCK_LEN if msgbuf[2] & mavlink.MAVLINK_IFLAG_SIGNED else 0
        end = len(msgbuf) - 2 - sig_len
        crc = mavlink.x25crc(msgbuf[1:end])
        crc.accumulate(bytes((msgtype.crc_extra,)))
        if crc.crc != msgbuf[end] | (msgbuf[end + 1] << 8):
            return "bad_crc"
        if self.signing.secret_key is None:
            return None
        self._sig_reason = None
        if sig_len:
            return None if self.check_signature(msgbuf, msgbuf[5], msgbuf[6]) else self._sig_reason
        if not self._unsigned_gate(msg_id):
            return "unsigned"
        if self.commit:
            self.n_unsigned_accepted += 1
        return None

    def _unsigned_gate(self, msg_id: int) -> bool:
        # pymavlink calls allow_unsigned_callback for unsigned packets *and* after a failed
        # signature check; never let the latter through.
        if self._sig_reason is not None:
            return False
        self._sig_reason = "unsigned"
        if msg_id in self._allow_unsigned:
            self._sig_reason = "unsigned_accepted"
            return True
        return False


class _NullFile:
    def write(self, buf) -> None:  # the codec returns bytes instead of writing them
        pass


_REASON_FIELD = {
    "signature:unsigned": "unsigned",
    "signature:bad_signature": "bad_signature",
    "signature:replayed": "replayed",
    "signature:stale": "stale",
    "Bad prefix": "bad_prefix",
}


class MavCodec:
    """Sans-IO MAVLink 2 codec for one endpoint identity (``source_system``, ``source_component``).

    Build messages with the generated constructors, e.g. ``codec.mav.heartbeat_encode(...)`` or
    ``dialect.MAVLink_sim_tick_message(tick, time_ms)``, then ``codec.encode(msg)`` to get bytes
    (sequence numbers increment per message). ``codec.decode(datagram)`` returns the good messages
    of one datagram.

    ``key``: 32-byte secret (see :func:`load_key`); enables signing of outgoing packets
    (``sign_outgoing``, default True with a key) and requires valid signatures on incoming ones.
    ``allow_unsigned``: message ids accepted unsigned even with a key (e.g. ``{0}`` for HEARTBEAT).
    ``link_id``: signing link id (0-255) of this endpoint. ``read_ids``: the message ids the owner reads
    (None: all); a MAVLink 2 packet of another id is verified and counted as ``unread``, not unpacked
    (only in committed decoding: a datagram decoded with ``commit=False`` is decoded whole).
    """

    def __init__(self, source_system: int = 1, source_component: int = 1, *, key: "bytes | None" = None,
                 sign_outgoing: "bool | None" = None, allow_unsigned: Iterable[int] = (), link_id: int = 0,
                 initial_timestamp: "int | None" = None, read_ids: "Iterable[int] | None" = None):
        for name, val, hi in (("source_system", source_system, 255), ("source_component", source_component, 255),
                              ("link_id", link_id, 255)):
            if not isinstance(val, int) or not 0 <= val <= hi:
                raise UsageError(f"{name} must be an integer in [0, {hi}], got {val!r}")
        self.mav = SecureMAVLink(_NullFile(), srcSystem=source_system, srcComponent=source_component)
        self.mav.robust_parsing = True
        self.mav._allow_unsigned = frozenset(int(i) for i in allow_unsigned)
        self.counters = CodecCounters()
        self.read_ids = None if read_ids is None else frozenset(int(i) for i in read_ids)
        self.dialect = mavlink
        self.signed = key is not None
        if key is not None:
            if not isinstance(key, (bytes, bytearray)) or len(key) != KEY_LEN:
                raise UsageError(f"signing key must be {KEY_LEN} bytes, got {len(key) if key else 0}")
            s = self.mav.signing
            s.secret_key = bytes(key)
            s.sign_outgoing = True if sign_outgoing is None else bool(sign_outgoing)
            s.link_id = link_id
            s.timestamp = signing_timestamp_now() if initial_timestamp is None else int(initial_timestamp)
            s.allow_unsigned_callback = lambda mav, msg_id: mav._unsigned_gate(msg_id)

    # -- decoding -----------------------------------------------------------------------------
    def decode(self, datagram: "bytes | bytearray | memoryview", commit: bool = True,
               admit: "Callable[[int, int], bool] | None" = None) -> list[MAVLinkMessage]:
        """Good messages in one datagram (in order); every bad packet is counted and dropped.

        The datagram is split into packets by walking the MAVLink headers (no parser state is
        kept between datagrams, so a truncated datagram cannot corrupt the next one); each packet
        goes through the generated ``decode`` (CRC, length, signature). Bytes before a start
        marker count once as ``bad_prefix``; a packet cut short by the datagram end as
        ``truncated``. Never raises on bad input.

        ``commit=False`` (a datagram the caller will drop anyway, e.g. from an address that is not
        the peer): every check runs and bad packets are counted by reason, but no signing state
        changes (a valid packet does not advance its stream's replay window, so an early copy of a
        genuine packet cannot make the genuine one look like a replay) and the good messages are
        returned without counting them in ``messages_in`` / ``signed_in``.

        ``admit(msg_id, size)`` (committed decoding only): called for each whole packet found by the
        header walk before any check; a packet it refuses is counted as ``shed`` and skipped unchecked
        (a receiver whose queue for such packets is full saves the CRC, signature and unpacking of a
        flood).
        """
        mav = self.mav
        mav.commit = bool(commit)
        try:
            return self._decode(datagram, mav.commit, admit if commit else None)
        finally:
            mav.commit = True

    def _decode(self, datagram, commit: bool, admit=None) -> list[MAVLinkMessage]:
        c = self.counters
        data = bytes(datagram)
        n = len(data)
        c.datagrams_in += 1
        c.bytes_in += n
        dec = self.mav.decode
        read = self.read_ids if commit else None
        good: list[MAVLinkMessage] = []
        i = 0
        while i < n:
            b0 = data[i]
            if b0 != 0xFD and b0 != 0xFE:
                c.bad_prefix += 1
                j1, j2 = data.find(b"\xfd", i + 1), data.find(b"\xfe", i + 1)
                i = min(j for j in (j1, j2, n) if j >= 0)
                continue
            if b0 == 0xFD:
                if n - i < 3:
                    c.truncated += 1
                    break
                flags = data[i + 2]
                size = data[i + 1] + 12 + (13 if flags & 1 else 0)
            else:
                if n - i < 2:
                    c.truncated += 1
                    break
                flags = 0
                size = data[i + 1] + 8
            if i + size > n:
                c.truncated += 1
                break
            pkt = bytearray(data[i:i + size])
            i += size
            if flags & 0xFE:  # unknown incompatibility flag: must not be parsed (MAVLink 2 spec)
                c.malformed += 1
                continue
            if admit is not None and not admit(pkt[7] | (pkt[8] << 8) | (pkt[9] << 16) if b0 == 0xFD else pkt[5],
                                               size):
                c.shed += 1
                continue
            if read is not None and b0 == 0xFD:
                msg_id = pkt[7] | (pkt[8] << 8) | (pkt[9] << 16)
                if msg_id not in read:
                    try:
                        field = self.mav.verify(pkt, msg_id) or "unread"
                    except Exception:  # hostile input must never escape (as for a decoded packet)
                        field = "malformed"
                    setattr(c, field, getattr(c, field) + 1)
                    continue
            try:
                m = dec(pkt)
            except MAVError as exc:
                reason = exc.message
                field = _REASON_FIELD.get(reason)
                if field is None:
                    field = "bad_crc" if reason.startswith("invalid MAVLink CRC") else "malformed"
                setattr(c, field, getattr(c, field) + 1)
                continue
            except Exception:  # hostile input must never escape
                c.malformed += 1
                continue
            if m._type.startswith("UNKNOWN_"):
                c.unknown += 1
                continue
            good.append(m)
        if commit:
            c.unsigned_accepted = self.mav.n_unsigned_accepted
            c.messages_in += len(good)
            c.signed_in += sum(1 for m in good if m._signed)
        return good

    # -- encoding -----------------------------------------------------------------------------
    def encode(self, msg: MAVLinkMessage, link_id: "int | None" = None) -> bytes:
        """Pack one message (signed if a key is set) and advance the sequence number.

        ``link_id`` overrides the signing link id for this packet: lockstep control messages
        (SIM_TICK / SIM_TICK_ACK) bypass the shim's delay line, so with signing they must travel
        on their own signing stream (e.g. :data:`CONTROL_LINK_ID`) or the receiver would reject
        the delayed, older-stamped data packets behind them as replays.
        """
        mav = self.mav
        if mav.signing.sign_outgoing:
            now = signing_timestamp_now()
            if now > mav.signing.timestamp:
                mav.signing.timestamp = now
            if link_id is not None:
                saved, mav.signing.link_id = mav.signing.link_id, link_id
                try:
                    buf = msg.pack(mav)
                finally:
                    mav.signing.link_id = saved
            else:
                buf = msg.pack(mav)
        else:
            buf = msg.pack(mav)
        mav.seq = (mav.seq + 1) & 0xFF
        c = self.counters
        c.messages_out += 1
        c.datagrams_out += 1
        c.bytes_out += len(buf)
        return buf

    def encode_many(self, msgs: Iterable[MAVLinkMessage], link_id: "int | None" = None) -> bytes:
        """Pack several messages into one datagram (legal over UDP; packets are never split)."""
        parts = [self.encode(m, link_id) for m in msgs]
        self.counters.datagrams_out -= max(0, len(parts) - 1)
        return b"".join(parts)
