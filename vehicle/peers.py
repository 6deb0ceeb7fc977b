"""What the vehicle keeps per ground station (a *peer*), sans-IO, and the bounds that keep a flood from
taking the vehicle: its stream rates, the settings and reads it sent that wait for the step boundary,
its parameter-list cursor and its reply budget.

* **Replies are paced**: a peer's answers to reads (and to its settings) go out within
  :data:`REPLY_BYTES_PER_STEP` bytes per sim step; what does not fit waits for the next step, in
  order. A parameter list is answered one PARAM_VALUE at a time from a cursor, and at most one list
  is in flight per peer: a PARAM_REQUEST_LIST while one is queued or in flight is dropped
  (``coalesced``; the list being sent answers it). So the bytes out for a flood of reads stay a small
  fraction of the bytes in (docs/reliability.md has the figures).
* **Every queue has a byte budget** (wire bytes of the messages in it): reads
  :data:`REQUEST_QUEUE_BYTES`, settings :data:`SETTING_QUEUE_BYTES` per peer (the pilot's commands
  have their own queue in :class:`vehicle.protocol.VehicleProtocol`, so requests never starve them).
  A message past the budget is dropped and counted (``dropped_queue``). Reads past it are not even
  decoded: :meth:`Peer.admit` refuses them during the codec's header walk (``shed``).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Callable

from daa_sil.link.codec import MavCodec
from daa_sil.link.codec import mavlink as M
from daa_sil.sil.intake import Received
from daa_sil.sil.msgguard import MessageGuard

from .services import READ_TYPES, GcsServices
from .streams import StreamRates

#: reply bytes a peer may get per sim step (a full parameter list is about 300 B, AUTOPILOT_VERSION 90 B)
REPLY_BYTES_PER_STEP = 4096
#: wire bytes of a peer's reads waiting for an answer (about 1,000 small requests)
REQUEST_QUEUE_BYTES = 16 * 1024
#: wire bytes of a peer's settings (PARAM_SET, modes) and observer commands waiting for the step boundary
SETTING_QUEUE_BYTES = 16 * 1024
#: replies (to settings, announcements) waiting for reply budget; encoded only when sent, so a signed one
#: never goes out behind a newer packet of its stream
REPLY_QUEUE_MESSAGES = 512
#: PARAM_REQUEST_LIST decoded per datagram while a list is busy (the rest are not decoded; a GCS sends one)
LIST_REQUESTS_DECODED = 8
#: message ids that only read: a peer's queue for them decides whether they are decoded at all
READ_ONLY_IDS = frozenset(getattr(M, f"MAVLINK_MSG_ID_{t}") for t in READ_TYPES)
PARAM_REQUEST_LIST_ID = M.MAVLINK_MSG_ID_PARAM_REQUEST_LIST
#: what an offered read became
QUEUED, COALESCED, FULL = "queued", "coalesced", "full"


def wire_size(msg) -> int:
    """A decoded message's size on the wire (bytes)."""
    buf = msg.get_msgbuf()
    return len(buf) if buf is not None else 0


@dataclass
class PeerCounters:
    """What happened to one peer's reads and replies."""

    requests: int = 0  #: reads queued
    answered: int = 0  #: reads answered (a parameter list counts once)
    coalesced: int = 0  #: PARAM_REQUEST_LIST dropped while a list was queued or in flight
    dropped_queue: int = 0  #: reads and settings dropped (and reads shed undecoded) past their queue's budget
    reply_bytes: int = 0  #: bytes of replies sent
    deferred_steps: int = 0  #: steps that ended with replies still waiting for budget


class Peer:
    """One ground station: ``link`` the output it is on (``gcs``, ``tap``, ``out2``, ...); ``dt`` the sim step."""

    def __init__(self, link: str, dt: float):
        self.link = link
        self.rates = StreamRates(dt)
        self.requests: "deque[tuple[Received, int]]" = deque()  #: reads and their wire sizes
        self.request_bytes = 0
        self.settings: "deque[tuple[Received, int, float | None]]" = deque()  #: (message, size, sent stamp)
        self.setting_bytes = 0
        self.replies: "deque[list]" = deque()  #: replies waiting for budget (message lists, one datagram each)
        self.reply_messages = 0
        self.list_cursor: "int | None" = None  #: the next PARAM_VALUE index of the list in flight
        self.list_queued = False
        self.allowance = REPLY_BYTES_PER_STEP
        self.counters = PeerCounters()

    @property
    def list_busy(self) -> bool:
        return self.list_cursor is not None or self.list_queued

    def new_step(self) -> None:
        """A sim step began: the reply budget is full again."""
        if self.requests or self.replies or self.list_cursor is not None:
            self.counters.deferred_steps += 1
        self.allowance = REPLY_BYTES_PER_STEP

    def pending(self) -> bool:
        """Is something waiting that the next :meth:`pump` (or the step boundary, settings) would handle?"""
        waiting = self.requests or self.replies or self.list_cursor is not None
        return bool(self.settings) or (self.allowance > 0 and bool(waiting))

    # -- in --------------------------------------------------------------------------------------
    def admit(self) -> "Callable[[int, int], bool]":
        """The codec's admission for one datagram from this peer: reads only while their queue has room
        (counting those admitted earlier in the datagram), and at most :data:`LIST_REQUESTS_DECODED`
        PARAM_REQUEST_LIST (a list answers them all)."""
        room = [REQUEST_QUEUE_BYTES - self.request_bytes, LIST_REQUESTS_DECODED]

        def admit(msg_id: int, size: int) -> bool:
            if msg_id not in READ_ONLY_IDS:
                return True
            if msg_id == PARAM_REQUEST_LIST_ID:
                if room[1] <= 0:
                    self.counters.coalesced += 1
                    return False
                room[1] -= 1
            if size > room[0]:
                self.counters.dropped_queue += 1
                return False
            room[0] -= size
            return True

        return admit

    def offer_request(self, r: Received) -> str:
        """Queue a read: :data:`QUEUED`, :data:`COALESCED` (a list is busy) or :data:`FULL` (dropped)."""
        if GcsServices.is_param_list(r.msg):
            if self.list_busy:
                self.counters.coalesced += 1
                return COALESCED
        size = wire_size(r.msg)
        if self.request_bytes + size > REQUEST_QUEUE_BYTES:
            self.counters.dropped_queue += 1
            return FULL
        if GcsServices.is_param_list(r.msg):
            self.list_queued = True
        self.requests.append((r, size))
        self.request_bytes += size
        self.counters.requests += 1
        return QUEUED

    def offer_setting(self, r: Received, t_sent: "float | None") -> bool:
        """Queue a setting (or an observer's command) for the step boundary; False: dropped (budget)."""
        size = wire_size(r.msg)
        if self.setting_bytes + size > SETTING_QUEUE_BYTES:
            self.counters.dropped_queue += 1
            return False
        self.settings.append((r, size, t_sent))
        self.setting_bytes += size
        return True

    def take_settings(self) -> "list[tuple[Received, float | None]]":
        out = [(r, t_sent) for r, _, t_sent in self.settings]
        self.settings.clear()
        self.setting_bytes = 0
        return out

    # -- out -------------------------------------------------------------------------------------
    def queue_reply(self, msgs: list) -> bool:
        """A reply (one datagram's messages) to send within the budget, after those already waiting; False:
        dropped (too many waiting)."""
        if self.reply_messages + len(msgs) > REPLY_QUEUE_MESSAGES:
            self.counters.dropped_queue += 1
            return False
        self.replies.append(msgs)
        self.reply_messages += len(msgs)
        return True

    def charge(self, n_bytes: int) -> None:
        """Replies of ``n_bytes`` went out."""
        self.allowance -= n_bytes
        self.counters.reply_bytes += n_bytes

    def pump(self, services: GcsServices, codec: MavCodec, now: float, latest: dict,
             guard: MessageGuard) -> "list[tuple[bytes, int]]":
        """Answer waiting reads in order while this step's budget lasts (a started parameter list first);
        returns the datagrams ``(bytes, messages)``. A read whose handling raises is counted by ``guard``."""
        out: "list[tuple[bytes, int]]" = []
        values: list = []  # PARAM_VALUEs of the list, one datagram per pump

        def flush_values() -> None:
            out.append((b"".join(values), len(values)))
            codec.counters.datagrams_out -= len(values) - 1  # one datagram, encoded a message at a time
            values.clear()

        while self.allowance > 0:
            if self.replies:
                if values:
                    flush_values()
                msgs = self.replies.popleft()
                self.reply_messages -= len(msgs)
                data = codec.encode_many(msgs)
                out.append((data, len(msgs)))
                self.charge(len(data))
                continue
            if self.list_cursor is not None:
                data = codec.encode(services.param_value(self.list_cursor))
                values.append(data)
                self.charge(len(data))
                self.list_cursor += 1
                if self.list_cursor >= len(services.params):
                    self.list_cursor = None
                continue
            if not self.requests:
                break
            if values:
                flush_values()
            r, size = self.requests.popleft()
            self.request_bytes -= size
            if GcsServices.is_param_list(r.msg):
                self.list_queued = False
                self.list_cursor = 0
                self.counters.answered += 1
                continue
            got: list = []
            if guard.call(lambda: got.extend(services.read(r.msg, self.rates, now, latest)), what=r.msg.get_type(),
                          source=r.addr) and got:
                data = codec.encode_many(got)
                out.append((data, len(got)))
                self.charge(len(data))
                self.counters.answered += 1
        if values:
            flush_values()
        return out
