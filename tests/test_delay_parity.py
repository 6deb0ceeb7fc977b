"""Fast-time's array link and the SIL shim's DelayLine apply the same delay rule (docs/architecture.md,
"One delay rule").

What is shared: the draws (``BatchedDelay`` row i == ``DelayProcess(model, seed_i)``, both from
``draw_block``) and the FIFO rule ``release_k = max(t_k + d(t_k), release_{k-1})``
(``fifo_release``, which fast-time calls once per step with ``prev_release``; ``DelayLine.push``
applies the same max per packet). What differs is only the bookkeeping: fast-time keeps one release
slot per step and advances a pointer (``_release_pointer``), the shim keeps a heap and pops what is
due. This test drives both, lane by lane, with the calls fast-time makes, and requires identical
release times and identical deliveries at every integer tick.

Population: the paper's Gaussian(5, 3) s delay truncated to [0.2, 10] s and constant 4 s, 10 s epochs,
240 one-second steps, 64 lanes (encounter seeds 0..63). The delay falls at some epoch boundaries,
so the FIFO clamp is exercised (asserted, per population).
"""

from __future__ import annotations

import numpy as np
import pytest

from daa_sil.link.delayline import DelayLine, fifo_release
from daa_sil.models.delay_process import BatchedDelay, DelayProcess
from daa_sil.models.latency import Constant, TruncatedGaussian
from daa_sil.study.simulation.fasttime import STREAM_UP, _release_pointer, encounter_streams

N, STEPS, EPOCH = 64, 240, 10.0


def fast_time_link(model, seeds):
    """Release times (N, STEPS) and per-tick delivered counts as fast-time computes them."""
    up = BatchedDelay(model, seeds, EPOCH, STEPS + 1.0)
    rel = np.full((N, STEPS), np.inf)
    last = np.full(N, -np.inf)
    ptr = np.zeros(N, np.int64)
    delivered = []
    for k in range(STEPS):
        t = float(k)
        r = fifo_release(np.full((N, 1), t), up.delay_at(t)[:, None], prev_release=last)[:, 0]
        last = r
        rel[:, k] = r
        ptr = _release_pointer(ptr, rel, k + 1, t)
        delivered.append(ptr.copy())
    return rel, np.array(delivered)


def shim_link(model, seeds):
    """The same through one DelayLine per lane (the shim's object), popped at every integer tick."""
    rel = np.full((N, STEPS), np.inf)
    delivered = np.zeros((STEPS, N), np.int64)
    clamped = 0
    for i, ss in enumerate(seeds):
        line = DelayLine(DelayProcess(model, ss, epoch_s=EPOCH))
        count = 0
        for k in range(STEPS):
            t = float(k)
            (rec,) = line.push(t, k)
            rel[i, k] = rec.t_out
            count += len(line.pop_due(t))
            delivered[k, i] = count
        clamped += line.counters.clamped
    return rel, delivered, clamped


@pytest.mark.parametrize("model", [TruncatedGaussian(5.0, 3.0), Constant(4.0)], ids=["gauss-5-3", "const-4"])
def test_fast_time_and_shim_release_the_same_packets(model):
    seeds = [encounter_streams(s)[STREAM_UP] for s in range(N)]
    rel_ft, got_ft = fast_time_link(model, seeds)
    rel_sh, got_sh, clamped = shim_link(model, seeds)
    assert np.array_equal(rel_ft, rel_sh)
    assert np.array_equal(got_ft, got_sh)
    # the probes are not trivial: packets are in flight at most ticks, and with a varying delay the
    # FIFO clamp holds some back (a constant delay never clamps)
    in_flight = (np.arange(1, STEPS + 1)[:, None] - got_ft).mean()
    assert in_flight > 3.0
    if isinstance(model, Constant):
        assert clamped == 0
    else:
        assert clamped > 0
        raw = np.array([[DelayProcess(model, ss, epoch_s=EPOCH).delay(float(k)) for k in range(STEPS)] for ss in seeds])
        assert np.any(rel_ft > np.arange(STEPS)[None, :] + raw)  # held back by the clamp


def test_the_check_can_fail():
    """A one-step offset in the shim's send times is caught (the comparison is not vacuous)."""
    model = TruncatedGaussian(5.0, 3.0)
    seeds = [encounter_streams(s)[STREAM_UP] for s in range(N)]
    rel_ft, _ = fast_time_link(model, seeds)
    line = DelayLine(DelayProcess(model, seeds[0], epoch_s=EPOCH))
    shifted = [line.push(k + 0.5, k)[0].t_out for k in range(STEPS)]
    assert not np.array_equal(rel_ft[0], np.array(shifted))
