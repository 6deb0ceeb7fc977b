"""What one socket takes in, sans-IO: which senders are accepted, decoding, and the counts of what is dropped.

:class:`Intake` is the part of an endpoint that needs no socket (:class:`daa_sil.sil.endpoint.MavEndpoint`
wraps one around an asyncio socket; the vehicle's and the GCS's protocol cores own theirs, so a test
can drive them with bytes alone). ``receive(data, addr, now)`` returns the good messages of one
datagram as :class:`Received` tuples; everything hostile is counted and dropped:

* datagrams from addresses outside ``allow_peers`` (or, with ``lock_peer``, from anyone but the
  learned peer): decoded *without changing any signing state* (``MavCodec.decode(..., commit=False)``),
  so each packet is counted once under its codec reason or, if good, as ``rejected_peer``;
  ``datagrams_rejected_peer`` counts their datagrams, and a :class:`DropReporter` says so on stderr.
  Not committing matters: an early copy of a genuine signed packet from another port must not
  advance the stream's replay window and so turn the genuine packet into a "replay";
* messages whose source system id is outside ``allow_sysids`` (``rejected_sysid``);
* codec rejections (bad CRC, prefix, truncated, unknown, malformed, unsigned, bad signature,
  replayed, stale: :class:`daa_sil.link.codec.CodecCounters`).

Peer: a fixed ``peer``, or (``learn_peer``, the default without a peer) the sender of the first
datagram that held a good message -- garbage cannot claim the link; an address in ``allow_peers``
is never learned as the peer. Hosts must be given numeric (the endpoint resolves names).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable, Iterable, NamedTuple

from daa_sil.link.codec import MavCodec, MAVLinkMessage
from daa_sil.sil.msgguard import MessageGuard, stderr_line

Address = tuple[str, int]


def format_udp_address(addr: Address) -> str:
    """``("127.0.0.1", 14601)`` -> ``"udp:127.0.0.1:14601"``."""
    host = addr[0]
    return f"udp:[{host}]:{addr[1]}" if ":" in host else f"udp:{host}:{addr[1]}"


class TopCounter:
    """Counts per key, bounded: the ``k`` heaviest keys kept, every other count in ``others``.

    Up to ``2 k`` keys are counted exactly; when a new key comes past that, the lighter half is folded
    into ``others`` (their counts, and ``others_keys`` how many keys they were). Memory stays
    ``O(k)`` whatever the number of distinct keys (spoofed source addresses, say); a key that stays
    heavy is never folded. ``distinct`` is the number of keys seen, counted again if one comes back
    after being folded (so at least the true number).
    """

    def __init__(self, k: int = 64):
        self.k = max(1, int(k))
        self.counts: "dict[object, int]" = {}
        self.others = 0
        self.others_keys = 0
        self.distinct = 0

    def add(self, key, n: int = 1) -> bool:
        """Count ``n`` for ``key``; True if it was not being counted (new, or folded before)."""
        if key in self.counts:
            self.counts[key] += n
            return False
        if len(self.counts) >= 2 * self.k:
            keep = sorted(self.counts.items(), key=lambda kv: -kv[1])
            for _, c in keep[self.k:]:
                self.others += c
            self.others_keys += len(keep) - self.k
            self.counts = dict(keep[: self.k])
        self.counts[key] = n
        self.distinct += 1
        return True

    def __contains__(self, key) -> bool:
        return key in self.counts

    def __len__(self) -> int:
        return len(self.counts)

    def most_common(self, n: int) -> "list[tuple[object, int]]":
        return sorted(self.counts.items(), key=lambda kv: -kv[1])[:n]


class DropReporter:
    """Warn once per unexpected sender, then periodically with counts, while its datagrams are dropped.

    ``note(addr, what, now)`` counts one dropped datagram from ``addr`` (``what``: e.g. ``"HEARTBEAT from
    system 1"``, or ""). The first drop from each of up to ``max_named`` distinct addresses is
    reported at once; after that one summary line at most every ``every_s`` seconds (``now``, or the
    ``clock``'s seconds) while drops continue: how many in the interval and in all, per address
    (top 3). Lines go to ``emit`` (default: stderr) as ``"{who}: warning: ..."``. ``expected()`` names
    the peer that is accepted (called when a line is made, so a learned peer shows up). The counts per
    address are a :class:`TopCounter`: a flood from a million spoofed addresses keeps a few kB.
    """

    def __init__(self, who: str, expected: "Callable[[], str]", *, hint: str = "",
                 emit: "Callable[[str], None] | None" = None, every_s: float = 10.0,
                 clock: "Callable[[], float]" = time.monotonic, max_named: int = 8):
        self.who, self.expected, self.hint = who, expected, hint
        self.emit = emit or stderr_line
        self.every_s, self.clock, self.max_named = float(every_s), clock, int(max_named)
        self.by_addr = TopCounter()
        self.named: "set[Address]" = set()  #: addresses already reported by name (at most max_named)
        self.total = 0
        self.lines = 0
        self._since = 0
        self._next: "float | None" = None

    def note(self, addr: "Address", what: str = "", now: "float | None" = None) -> None:
        """Count one dropped datagram from ``addr`` at ``now`` (s; default the clock's); maybe emit a line."""
        addr = (addr[0], addr[1])
        self.by_addr.add(addr)
        self.total += 1
        self._since += 1
        if now is None:
            now = self.clock()
        if addr not in self.named and len(self.named) < self.max_named:
            self.named.add(addr)
            self._say(f"dropping datagrams from {format_udp_address(addr)}"
                      f"{f' ({what})' if what else ''}: not the expected peer {self.expected()}"
                      f"{'; ' + self.hint if self.hint else ''}")
            self._since = 0
            if self._next is None:
                self._next = now + self.every_s
        elif self._next is None or now >= self._next:
            self._say(f"still dropping datagrams from unexpected peers: {self._since} in the last "
                      f"{self.every_s:g} s, {self.total} in all ({self._top()}); expected {self.expected()}")
            self._since = 0
            self._next = now + self.every_s

    def _say(self, text: str) -> None:
        self.lines += 1
        self.emit(f"{self.who}: warning: {text}")

    def summary(self) -> "str | None":
        """One line with the totals (None if nothing was dropped), e.g. for a process's last words."""
        if not self.total:
            return None
        return f"dropped {self.total} datagrams from unexpected peers ({self._top()}); expected {self.expected()}"

    def _top(self) -> str:
        """The three heaviest senders, and how many more (at least) there were."""
        top = ", ".join(f"{format_udp_address(a)}: {n}" for a, n in self.by_addr.most_common(3))
        more = self.by_addr.distinct - min(3, len(self.by_addr))
        return top + (f" and {more} more addresses" if more > 0 else "")


class Received(NamedTuple):
    """One good message: arrival time (s, the caller's monotonic clock), sender address, the message."""

    t: float
    addr: Address
    msg: MAVLinkMessage


@dataclass
class EndpointCounters:
    """Counts of one socket (codec-level ones are merged in :meth:`Intake.stats`)."""

    sent: int = 0  # messages sent
    datagrams_sent: int = 0
    send_no_peer: int = 0  # send attempts before a peer was known
    received: int = 0  # good messages delivered
    datagrams_received: int = 0
    rejected_peer: int = 0  # good packets from an address outside allow_peers (bad ones: codec reasons)
    datagrams_rejected_peer: int = 0  # datagrams from an address outside allow_peers
    rejected_sysid: int = 0
    inbox_overflow: int = 0
    #: decoded messages dropped because the queue they wait in for the step boundary was full (its byte budget)
    dropped_queue: int = 0
    socket_errors: int = 0
    refused: int = 0  # ICMP port unreachable: nothing listens where we send (part of socket_errors)


class Intake:
    """The receiving rules of one socket (see the module docstring). ``allow_peers``: numeric hosts
    (str: any port of that host) and ``(host, port)`` addresses; None = anyone."""

    def __init__(self, codec: MavCodec, *, peer: "Address | None" = None, learn_peer: "bool | None" = None,
                 allow_peers: "Iterable[Address | str] | None" = None, allow_sysids: "Iterable[int] | None" = None,
                 lock_peer: bool = False, name: str = "daa-sil", peer_label: str = "", drop_hint: str = "",
                 drop_warn_every_s: float = 10.0, warn: "Callable[[str], None] | None" = None,
                 guard: "MessageGuard | None" = None):
        self.codec = codec
        self.peer = None if peer is None else (peer[0], int(peer[1]))
        self.learn_peer = (peer is None) if learn_peer is None else bool(learn_peer)
        self.lock_peer = bool(lock_peer)
        #: every message's handling runs under it (shared with the owner)
        self.guard = guard if guard is not None else MessageGuard(name, emit=warn)
        self.allow_hosts: "set[str] | None" = None
        self.allow_addrs: "set[Address] | None" = None
        if allow_peers is not None:
            self.allow_hosts, self.allow_addrs = set(), set()
            for a in allow_peers:
                if isinstance(a, str):
                    self.allow_hosts.add(a)
                else:
                    self.allow_addrs.add((a[0], int(a[1])))
        self.allow_sysids = None if allow_sysids is None else frozenset(int(s) for s in allow_sysids)
        self.counters = EndpointCounters()
        self.peer_label = peer_label
        self.drops = DropReporter(name, self.expected_text, hint=drop_hint, emit=warn, every_s=drop_warn_every_s)

    def expected_text(self) -> str:
        """Who is accepted, for messages: the allowed addresses (and the peer), with the label."""
        addrs = sorted(self.allow_addrs or ())
        if self.peer is not None and (not addrs or self.lock_peer) and tuple(self.peer) not in addrs:
            addrs = [tuple(self.peer)] + addrs
        who = ", ".join(format_udp_address(a) for a in addrs) if addrs else "(none yet)"
        return who + (f" ({self.peer_label})" if self.peer_label else "")

    def listed(self, addr: Address) -> bool:
        """Is ``addr`` in ``allow_peers`` (by host or by address)?"""
        return self.allow_hosts is not None and (addr[0] in self.allow_hosts or (addr[0], addr[1]) in self.allow_addrs)

    def peer_allowed(self, addr: Address) -> bool:
        """May a datagram from ``addr`` be taken (before decoding it)?"""
        if self.lock_peer:  # the learned peer (or, before one is learned, anyone) and the allowed list
            return self.listed(addr) or self.peer is None or (addr[0], addr[1]) == tuple(self.peer)
        if self.allow_hosts is None:
            return True
        return self.listed(addr)

    def receive(self, data: bytes, addr: Address, now: float,
                admit: "Callable[[int, int], bool] | None" = None) -> "list[Received]":
        """The good messages of one datagram from ``addr`` arriving at ``now`` (s); the rest counted.
        ``admit(msg_id, size)``: a packet it refuses is skipped before decoding (``shed``:
        :meth:`daa_sil.link.codec.MavCodec.decode`)."""
        c = self.counters
        addr = (addr[0], addr[1])
        if not self.peer_allowed(addr):
            return self.reject(data, addr, now)
        c.datagrams_received += 1
        msgs = self.codec.decode(data, admit=admit)
        if not msgs:
            return []
        if self.allow_sysids is not None:
            keep = [m for m in msgs if m.get_srcSystem() in self.allow_sysids]
            c.rejected_sysid += len(msgs) - len(keep)
            msgs = keep
            if not msgs:
                return []
        if self.peer is None and self.learn_peer and not (self.lock_peer and self.listed(addr)):
            self.peer = addr
        return [Received(now, addr, m) for m in msgs]

    def reject(self, data: bytes, addr: Address, now: float) -> "list[Received]":
        """Drop a datagram from ``addr`` that its receiver will not take (a stranger, or one past its room for
        senders): decoded without changing any signing state, counted (``rejected_peer`` for its good
        packets, codec reasons for the rest) and reported; returns ``[]``."""
        c = self.counters
        c.datagrams_received += 1
        c.datagrams_rejected_peer += 1
        addr = (addr[0], addr[1])
        good = self.codec.decode(data, commit=False)
        c.rejected_peer += len(good)
        what = f"{good[0].get_type()} from system {good[0].get_srcSystem()}" if good else "no valid MAVLink"
        self.drops.note(addr, what, now)
        return []

    def stats(self) -> dict:
        """Counters of the socket and of its codec in one dict (``dropped`` = every rejected packet)."""
        d = dict(self.codec.counters.as_dict())
        d.update(self.counters.__dict__)
        d["malformed_content"] = self.guard.total  # decoded, but its handling raised (msgguard)
        c = self.counters
        d["dropped"] = (self.codec.counters.dropped + c.rejected_peer + c.rejected_sysid + c.inbox_overflow
                        + c.dropped_queue + self.guard.total)
        return d
