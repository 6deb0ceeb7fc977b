"""Sans-IO delay line: one link direction with delay, loss, duplication, reordering and outages.

Shared by the UDP shim (items are datagrams, times are sim seconds from its clock) and fast-time
code (items are anything). Nothing here reads a clock or touches a socket: the caller passes
times in and asks for what is due.

Release rule (FIFO, the default): ``release_i = max(t_i + d_i, release_{i-1})`` over the packets
that are not dropped, where ``d_i`` is the delay process value at ``t_i``. :func:`fifo_release` is
that rule, batched: fast-time calls it for every encounter at once, :meth:`DelayLine.push` for one
packet, so the SIL shim and fast-time share one definition.

Impairments, each drawn from the line's own seeded generator (three uniforms per pushed packet,
whatever is enabled, so switching one knob does not shift the others' draws). ``push(..., key=K)``
takes the three uniforms from the key instead (:meth:`DelayLine.fault_uniforms`): a pure function
of the line's seed and ``K``, so a packet's fate does not depend on how many packets came before
it (the SIL shim keys each datagram on its simulation step, :mod:`daa_sil.sil.shim_core`).

* ``loss`` P: Bernoulli drop.
* ``outages``: list of ``(t_start, t_end)`` sim-time windows; a packet *entering* the line in
  ``[t_start, t_end)`` is dropped (the link is down when it is sent).
* ``dup`` P: a second copy is released right after the original (same release time).
* ``reorder`` P: netem-style queue jump -- the packet is released after ``reorder_fraction`` of
  its sampled delay (default 0.5), ignoring the FIFO clamp, so it overtakes packets in flight.
  It does not move the clamp for later packets.
* ``fifo=False``: no clamp at all, ``release_i = t_i + d_i`` (reorders if the delay decreases).

Do not combine reordering with MAVLink signing: a signed packet older than one already received
on its stream is rejected as a replay (MAVLink 2 signing keeps a per-stream timestamp window;
docs/sil.md, "Signing and spoofing").
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Sequence

import numpy as np

from ..errors import UsageError
from daa_sil.config.settings import DELAY_EPOCH
from daa_sil.models.latency import DelayModel
from daa_sil.models.delay_process import DelayProcess, as_seed_sequence, child_seed


#: spawn-key branch (below the impairment seed) of the keyed draws; the sequential stream uses the seed itself
KEYED_BRANCH = 1


def fifo_release(t_in: "np.ndarray | Sequence[float]", delay: "np.ndarray | Sequence[float]",
                 keep: "np.ndarray | None" = None, prev_release: "float | np.ndarray" = -np.inf) -> np.ndarray:
    """FIFO release times (s) along the last axis: ``r_i = max(t_i + d_i, r_{i-1})``, the link's one FIFO rule.

    Fast-time calls it with a batch of encounters, :meth:`DelayLine.push` (the SIL shim) with one
    packet. ``t_in``, ``delay``: send times and sampled delays, shape ``(..., K)`` with packets in send
    order. ``keep``: bool mask of packets that survive loss (dropped ones get ``inf`` and do not
    hold later packets back). ``prev_release``: release time of the last packet before this
    batch (scalar or ``(...)``), to continue a line across calls.
    """
    arrive = np.add(t_in, delay, dtype=float)
    if keep is not None:
        arrive = np.where(keep, arrive, -np.inf)
    # max(r_0, a_1, ..., a_i) as max(cummax(a)_i, r_0): the same values, one array op fewer
    out = np.maximum.accumulate(arrive, axis=-1)
    np.maximum(out, np.asarray(prev_release, dtype=float)[..., None], out=out)
    if keep is not None:
        out = np.where(keep, out, np.inf)
    return out


def item_bytes(item: Any) -> int:
    """The bytes an item holds in a line's byte budget: its length if it is bytes, else 0."""
    return len(item) if isinstance(item, (bytes, bytearray, memoryview)) else 0


def delay_seed(seed: "int | np.random.SeedSequence") -> np.random.SeedSequence:
    """The seed a ``DelayLine(model, seed=seed)`` gives its :class:`DelayProcess` (child 0).

    ``BatchedDelay(model, [delay_seed(s) for s in seeds], epoch_s, duration_s)`` reproduces such
    lines. (The shim does not use this: it passes each line the encounter's fast-time delay stream
    as a ready :class:`DelayProcess`; see :func:`daa_sil.sil.shim_config.shim_delay_processes`.)
    """
    return child_seed(seed, 0)


@dataclass
class LinkRecord:
    """One packet through the line: ``seq`` (push order), times in sim s, ``t_out`` nan if dropped."""

    seq: int
    t_in: float
    delay: float  # sampled delay (s)
    t_out: float  # release time (s); effective delay = t_out - t_in
    dropped: str  # "" or "loss" / "outage" / "queue"
    copy: bool = False  # True for a duplicate
    reordered: bool = False


@dataclass
class DelayLineCounters:
    """Packet counts for one direction."""

    pushed: int = 0
    released: int = 0
    dropped_loss: int = 0
    dropped_outage: int = 0
    dropped_queue: int = 0
    duplicated: int = 0
    reordered: int = 0
    clamped: int = 0  # packets held back by the FIFO rule (effective delay > sampled)

    def as_dict(self) -> dict:
        return dict(self.__dict__)


def _check_p(name: str, p: float) -> float:
    try:
        v = float(p)
    except (TypeError, ValueError):
        raise UsageError(f"{name} must be a probability in [0, 1], got {p!r}") from None
    if not (0.0 <= v <= 1.0):
        raise UsageError(f"{name} must be a probability in [0, 1], got {p!r}")
    return v


def check_outages(outages: Iterable[Sequence[float]]) -> list[tuple[float, float]]:
    """Validate ``[(t_start, t_end), ...]`` windows (s, start < end); returns them sorted."""
    out = []
    for w in outages or ():
        try:
            a, b = (float(x) for x in w)
        except (TypeError, ValueError):
            raise UsageError(f"outage window must be (start, end) in seconds, got {w!r}") from None
        if not (math.isfinite(a) and math.isfinite(b)) or b <= a:
            raise UsageError(f"outage window needs finite start < end (s), got {w!r}")
        out.append((a, b))
    return sorted(out)


class DelayLine:
    """A seeded one-direction link. ``push(t, item)``; ``pop_due(t)``; ``next_release()``.

    ``delay``: a :class:`DelayProcess`, a :class:`DelayModel` (wrapped in a DelayProcess with
    ``seed`` and ``epoch_s``), or a callable ``(t_in, index) -> seconds``. ``seed`` seeds both
    the delay process (child 0) and the impairment draws (child 1). ``max_queue``: packets in
    flight beyond this are tail-dropped (None = unbounded); ``max_bytes``: likewise for the bytes of
    the ``bytes`` items in flight (the shim's datagrams; other items count 0). Both drops count as
    ``dropped_queue`` and do not move the FIFO clamp. ``log``: keep a :class:`LinkRecord` per packet
    (bounded by ``max_log``; the oldest records are discarded past it).
    """

    def __init__(self, delay: "DelayProcess | DelayModel | Callable[[float, int], float]", *,
                 seed: "int | np.random.SeedSequence | None" = None, epoch_s: float = DELAY_EPOCH.default,
                 fifo: bool = True, loss: float = 0.0, dup: float = 0.0, reorder: float = 0.0,
                 reorder_fraction: float = 0.5, outages: Iterable[Sequence[float]] = (),
                 max_queue: "int | None" = None, max_bytes: "int | None" = None, log: bool = True,
                 max_log: int = 1_000_000):
        ss = as_seed_sequence(seed)
        d_ss, imp_ss = delay_seed(ss), child_seed(ss, 1)
        if isinstance(delay, DelayModel):
            delay = DelayProcess(delay, d_ss, epoch_s=epoch_s)
        if isinstance(delay, DelayProcess):
            self.process: "DelayProcess | None" = delay
            self._delay = delay.delay
        elif callable(delay):
            self.process, self._delay = None, delay
        else:
            raise UsageError(f"delay must be a DelayProcess, DelayModel or callable, got {delay!r}")
        self.fifo = bool(fifo)
        self.loss, self.dup, self.reorder = _check_p("loss", loss), _check_p("dup", dup), _check_p("reorder", reorder)
        if not (0.0 <= float(reorder_fraction) <= 1.0):
            raise UsageError(f"reorder_fraction must be within [0, 1], got {reorder_fraction!r}")
        self.reorder_fraction = float(reorder_fraction)
        self.outages = check_outages(outages)
        self.max_queue = max_queue
        self.max_bytes = max_bytes
        self.bytes_in_flight = 0  #: bytes of the ``bytes`` items in flight
        self._imp_ss = imp_ss
        self._rng = np.random.default_rng(imp_ss)
        self._heap: list[tuple[float, int, Any]] = []  # (release, order, item)
        self._order = 0
        self._last_release = -math.inf
        self._seq = 0
        self.counters = DelayLineCounters()
        self.log_enabled, self.max_log = bool(log), int(max_log)
        self.log: list[LinkRecord] = []

    # -- input -------------------------------------------------------------------------------
    def in_outage(self, t: float) -> bool:
        """True if sim time ``t`` (s) falls in an outage window."""
        return any(a <= t < b for a, b in self.outages)

    def fault_uniforms(self, key: Sequence[int]) -> tuple[float, float, float]:
        """The (loss, dup, reorder) uniforms in [0, 1) of the packet keyed ``key`` (non-negative ints).

        Each is the top 53 bits of a word of ``SeedSequence(seed entropy, spawn_key=impairment
        spawn key + (KEYED_BRANCH, *key)).generate_state(3)``: independent across keys and of the
        sequential stream, with the same distribution, so the rates stay ``loss`` / ``dup`` / ``reorder``.
        """
        ss = np.random.SeedSequence(self._imp_ss.entropy, pool_size=self._imp_ss.pool_size,
                                    spawn_key=tuple(self._imp_ss.spawn_key) + (KEYED_BRANCH,) + tuple(int(k) for k in key))
        words = ss.generate_state(3, np.uint64) >> np.uint64(11)
        return tuple(float(w) * 2.0 ** -53 for w in words)

    def push(self, t_in: float, item: Any, key: "Sequence[int] | None" = None) -> list[LinkRecord]:
        """Enter ``item`` at sim time ``t_in`` (s); returns the record(s) (two if duplicated).

        ``key``: draw the packet's impairments from :meth:`fault_uniforms` (``key``) instead of the
        line's sequential stream; on a line without loss, duplication or reordering they are not drawn
        (30-40 us a packet in the shim, two or three packets a lockstep step).
        """
        seq = self._seq
        self._seq += 1
        self.counters.pushed += 1
        if key is None:  # the line's sequential stream: drawn whatever the rates (the next packet's draws follow)
            u_loss, u_dup, u_reo = self._rng.random(3)
        elif self.loss or self.dup or self.reorder:
            u_loss, u_dup, u_reo = self.fault_uniforms(key)
        else:  # no rate to compare with (a uniform is never below 0): a keyed draw shifts nothing, so skip it
            u_loss = u_dup = u_reo = 1.0
        d = float(self._delay(t_in, seq))
        drop = ""
        if self.in_outage(t_in):
            drop = "outage"
            self.counters.dropped_outage += 1
        elif u_loss < self.loss:
            drop = "loss"
            self.counters.dropped_loss += 1
        elif (self.max_queue is not None and len(self._heap) >= self.max_queue) or (
                self.max_bytes is not None and self.bytes_in_flight + item_bytes(item) > self.max_bytes):
            drop = "queue"
            self.counters.dropped_queue += 1
        if drop:
            return [self._record(LinkRecord(seq, t_in, d, math.nan, drop))]
        reordered = u_reo < self.reorder
        if reordered:
            t_out = t_in + self.reorder_fraction * d
            self.counters.reordered += 1
        elif self.fifo:
            t_out = float(fifo_release((t_in,), (d,), prev_release=self._last_release)[0])
            if t_out > t_in + d:
                self.counters.clamped += 1
            self._last_release = t_out
        else:
            t_out = t_in + d
        recs = [self._record(LinkRecord(seq, t_in, d, t_out, "", reordered=reordered))]
        self._schedule(t_out, item)
        if u_dup < self.dup:
            self.counters.duplicated += 1
            recs.append(self._record(LinkRecord(seq, t_in, d, t_out, "", copy=True, reordered=reordered)))
            self._schedule(t_out, item)
        return recs

    def _schedule(self, t_out: float, item: Any) -> None:
        heapq.heappush(self._heap, (t_out, self._order, item))
        self._order += 1
        self.bytes_in_flight += item_bytes(item)

    def _record(self, rec: LinkRecord) -> LinkRecord:
        if self.log_enabled:
            if len(self.log) >= self.max_log:
                del self.log[: max(1, self.max_log // 10)]
            self.log.append(rec)
        return rec

    # -- output ------------------------------------------------------------------------------
    def pop_due(self, t_now: float) -> list[Any]:
        """Items with release time <= ``t_now`` (s), in release order (ties: push order)."""
        out = []
        heap = self._heap
        while heap and heap[0][0] <= t_now:
            item = heapq.heappop(heap)[2]
            self.bytes_in_flight -= item_bytes(item)
            out.append(item)
        self.counters.released += len(out)
        return out


    def next_release(self) -> "float | None":
        """Earliest pending release time (s), or None if nothing is in flight."""
        return self._heap[0][0] if self._heap else None

    def __len__(self) -> int:
        """Packets in flight."""
        return len(self._heap)

    def stats(self) -> dict:
        """Counters plus sampled/effective delay summaries (s) over the logged, delivered packets."""
        out = self.counters.as_dict()
        out["in_flight"] = len(self._heap)
        out["bytes_in_flight"] = self.bytes_in_flight
        recs = [r for r in self.log if not r.dropped and not r.copy]
        if recs:
            samp = np.array([r.delay for r in recs])
            eff = np.array([r.t_out - r.t_in for r in recs])
            out["delay_sampled_mean_s"] = float(samp.mean())
            out["delay_effective_mean_s"] = float(eff.mean())
            out["delay_effective_p50_s"] = float(np.percentile(eff, 50))
            out["delay_effective_p99_s"] = float(np.percentile(eff, 99))
        if self.process is not None:
            out["process"] = self.process.describe()
        return out
