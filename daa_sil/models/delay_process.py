"""Delay processes: a delay model drawn once per epoch from its own seeded stream, as a function of
send time (s). :class:`DelayProcess` serves one link (the shim, N = 1); :class:`BatchedDelay` makes
the same draws for N encounters at once (fast-time): the same seed gives the same values.

:func:`link_delay_processes` (SIL) and :func:`batched_link_delays` (fast-time) build both links'
processes from :class:`daa_sil.models.link_rule.LinkLegs`: under the ``round-trip`` rule the downlink
reads the uplink's seed stream, so both links see the same epoch grid (``t0 + e * epoch_s``) and
the same draw per epoch, halved: uplink + downlink delay of any epoch = that epoch's round trip."""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from daa_sil.config.settings import DURATION
from daa_sil.errors import UsageError
from daa_sil.models.latency import BLOCK, DEFAULT_EPOCH_S, DelayModel, Trace
from daa_sil.models.link_rule import LinkLegs


def as_seed_sequence(seed: "int | np.random.SeedSequence | None") -> np.random.SeedSequence:
    """An ``int`` (>= 0), a ``SeedSequence`` (used as is) or None (fresh OS entropy)."""
    if isinstance(seed, np.random.SeedSequence):
        return seed
    if seed is None:
        return np.random.SeedSequence()
    try:
        s = int(seed)
    except (TypeError, ValueError):
        raise UsageError(f"seed must be a non-negative integer, got {seed!r}") from None
    if s < 0 or s != seed:
        raise UsageError(f"seed must be a non-negative integer, got {seed!r}")
    return np.random.SeedSequence(s)


def child_seed(seed: "int | np.random.SeedSequence", i: int) -> np.random.SeedSequence:
    """Child ``i`` of ``seed``, equal to ``SeedSequence(seed).spawn(i + 1)[i]`` on a fresh object.

    Unlike ``SeedSequence.spawn`` it does not mutate ``seed``, so deriving twice gives the same child.
    """
    ss = as_seed_sequence(seed)
    return np.random.SeedSequence(ss.entropy, spawn_key=tuple(ss.spawn_key) + (int(i),), pool_size=ss.pool_size)


def _block_rng(ss: np.random.SeedSequence, block: int) -> np.random.Generator:
    return np.random.default_rng(child_seed(ss, block))


def draw_block(model: DelayModel, ss: np.random.SeedSequence, block: int, epoch_s: float,
               t0: float = 0.0) -> np.ndarray:
    """Delays (s) of epochs ``block*BLOCK ... block*BLOCK+BLOCK-1`` for one seed.

    This is *the* definition of the delay sequence: :class:`DelayProcess` and
    :class:`BatchedDelay` both call it, so they agree draw for draw. Epoch ``e`` starts at
    ``t0 + e*epoch_s`` (for a :class:`Trace`, the delay at that instant).
    """
    idx = np.arange(block * BLOCK, (block + 1) * BLOCK, dtype=float)
    # a model that draws nothing (constant, trace) needs no generator: making one per block and
    # encounter was most of a constant link's cost in fast-time
    return model.sample(_block_rng(ss, block) if model.draws else None, t0 + idx * epoch_s)


class DelayProcess:
    """Delay over time for one link direction, piecewise-constant per epoch, reproducible.

    ``delay(t)`` (s) is the draw of epoch ``floor((t - t0) / epoch_s)`` (t before ``t0`` counts
    as epoch 0). With ``epoch_s = 0`` every packet gets its own draw: call ``delay(t, index)``
    with the packet index (0, 1, 2, ...). A :class:`Trace` model is sampled at ``t`` itself
    whatever ``epoch_s`` is (the trace is already a process).
    """

    def __init__(self, model: DelayModel, seed: "int | np.random.SeedSequence | None" = None,
                 epoch_s: float = DEFAULT_EPOCH_S, t0: float = 0.0):
        if not isinstance(model, DelayModel):
            raise UsageError(f"delay model expected, got {model!r}")
        if not (math.isfinite(epoch_s) and epoch_s >= 0):
            raise UsageError(f"epoch_s must be >= 0 s (0 = per-packet draws), got {epoch_s!r}")
        self.model, self.epoch_s, self.t0 = model, float(epoch_s), float(t0)
        self.seed_seq = as_seed_sequence(seed)
        self._blocks: dict[int, np.ndarray] = {}

    def _epoch_value(self, e: int) -> float:
        b, i = divmod(e, BLOCK)
        blk = self._blocks.get(b)
        if blk is None:
            if len(self._blocks) > 64:  # long runs: keep memory bounded
                self._blocks.clear()
            blk = self._blocks[b] = draw_block(self.model, self.seed_seq, b, self.epoch_s or 0.0, self.t0)
        return float(blk[i])

    def epoch_of(self, t: float) -> int:
        """Epoch index of sim time ``t`` (s)."""
        if self.epoch_s == 0:
            raise UsageError("epoch_s = 0 (per-packet draws) has no epochs; pass the packet index")
        return max(0, int(math.floor((t - self.t0) / self.epoch_s)))

    def delay(self, t: float, index: "int | None" = None) -> float:
        """Delay (s) for a packet entering the link at sim time ``t`` (s), ``index`` = packet number."""
        if isinstance(self.model, Trace):
            return float(self.model.sample(None, t))
        if self.epoch_s == 0:
            if index is None or index < 0:
                raise UsageError("per-packet delay draws (epoch_s = 0) need the packet index")
            return self._epoch_value(int(index))
        return self._epoch_value(self.epoch_of(t))

    def describe(self) -> dict:
        """Parameters for logs and result files."""
        return {"model": self.model.to_dict(), "epoch_s": self.epoch_s, "t0": self.t0,
                "seed_entropy": self.seed_seq.entropy, "spawn_key": list(self.seed_seq.spawn_key)}


class BatchedDelay:
    """Delay processes of N encounters at once, for fast-time: ``delay_at(t) -> (N,)`` seconds.

    ``seeds`` is a sequence of N ints or ``SeedSequence`` objects (e.g.
    ``SeedSequence(campaign_seed).spawn(N)`` children, one per encounter and direction). The
    epoch table for ``[t0, t0 + duration_s]`` is drawn up front; row ``n`` equals
    ``DelayProcess(model, seeds[n], epoch_s, t0)`` draw for draw. ``epoch_s`` must be > 0 here
    (per-step draws in fast-time: ``epoch_s = dt``).
    """

    def __init__(self, model: DelayModel, seeds: Sequence, epoch_s: float = DEFAULT_EPOCH_S,
                 duration_s: float = DURATION.default, t0: float = 0.0):
        if not (math.isfinite(epoch_s) and epoch_s > 0):
            raise UsageError(f"BatchedDelay needs epoch_s > 0 s, got {epoch_s!r}")
        if not (math.isfinite(duration_s) and duration_s >= 0):
            raise UsageError(f"duration_s must be >= 0 s, got {duration_s!r}")
        self.model, self.epoch_s, self.t0, self.duration_s = model, float(epoch_s), float(t0), float(duration_s)
        sss = [as_seed_sequence(s) for s in seeds]
        self.n = len(sss)
        n_epochs = int(math.floor(duration_s / epoch_s)) + 1
        n_blocks = (n_epochs + BLOCK - 1) // BLOCK
        if isinstance(model, Trace):
            self.table = None  # the trace is sampled at t directly
        else:
            rows = [np.concatenate([draw_block(model, ss, b, self.epoch_s, self.t0) for b in range(n_blocks)])
                    [:n_epochs] for ss in sss]
            self.table = np.array(rows, dtype=float).reshape(self.n, n_epochs)
        self.n_epochs = n_epochs

    def delay_at(self, t: "float | np.ndarray") -> np.ndarray:
        """Delays (s) at sim time ``t``: scalar ``t`` -> ``(N,)``; array ``t`` of shape ``(N,)`` -> ``(N,)``."""
        t_arr = np.asarray(t, dtype=float)
        if isinstance(self.model, Trace):
            return np.broadcast_to(self.model.sample(None, t_arr), (self.n,)).astype(float)
        e = np.floor((t_arr - self.t0) / self.epoch_s).astype(np.int64)
        if np.any(e >= self.n_epochs):
            raise UsageError(f"t={float(np.max(t_arr)):g} s is beyond the drawn duration "
                             f"{self.duration_s:g} s; build BatchedDelay with a longer duration_s")
        e = np.clip(e, 0, None)
        if e.ndim == 0:
            return self.table[:, int(e)].copy()
        return self.table[np.arange(self.n), np.broadcast_to(e, (self.n,))]


def link_delay_processes(legs: LinkLegs, up_seed, down_seed, epoch_s: float = DEFAULT_EPOCH_S,
                         t0: float = 0.0) -> dict:
    """``{"up": DelayProcess, "down": DelayProcess}`` of one link pair (the SIL shim and vehicle).

    ``up_seed`` / ``down_seed`` are the two links' streams; with ``legs.shared`` (the round-trip
    rule) the downlink reads ``up_seed`` too, so each epoch's two delays are halves of one draw.
    """
    up = DelayProcess(legs.up, up_seed, epoch_s=epoch_s, t0=t0)
    down = DelayProcess(legs.down, up_seed if legs.shared else down_seed, epoch_s=epoch_s, t0=t0)
    return {"up": up, "down": down}


def batched_link_delays(legs: LinkLegs, up_seeds: Sequence, down_seeds: Sequence,
                        epoch_s: float = DEFAULT_EPOCH_S, duration_s: float = DURATION.default,
                        t0: float = 0.0) -> "tuple[BatchedDelay, BatchedDelay]":
    """``(uplink, downlink)`` :class:`BatchedDelay` of N encounters (fast-time); see
    :func:`link_delay_processes` for the streams. Row ``n`` equals its ``DelayProcess`` draw for draw."""
    up = BatchedDelay(legs.up, up_seeds, epoch_s, duration_s, t0)
    if legs.shared and legs.down == legs.up:
        return up, up
    down = BatchedDelay(legs.down, up_seeds if legs.shared else down_seeds, epoch_s, duration_s, t0)
    return up, down
