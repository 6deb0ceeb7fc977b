"""DelayLine: FIFO rule, loss, duplication, reordering, outages, determinism."""

from __future__ import annotations

import numpy as np
import pytest

from daa_sil.errors import UsageError
from daa_sil.models.latency import Constant, TruncatedGaussian, Uniform
from daa_sil.models.delay_process import DelayProcess
from daa_sil.link.delayline import DelayLine, delay_seed, fifo_release


def test_fifo_release_pure_function():
    t = np.array([0.0, 1.0, 2.0, 3.0])
    d = np.array([5.0, 2.0, 6.0, 1.0])
    assert fifo_release(t, d).tolist() == [5.0, 5.0, 8.0, 8.0]
    keep = np.array([True, False, True, True])
    assert fifo_release(t, d, keep).tolist() == [5.0, np.inf, 8.0, 8.0]
    assert fifo_release(t, d, prev_release=9.0).tolist() == [9.0, 9.0, 9.0, 9.0]
    batch = fifo_release(np.stack([t, t]), np.stack([d, d[::-1]]))  # (N, K)
    assert batch.shape == (2, 4) and batch[1].tolist() == [1.0, 7.0, 7.0, 8.0]


def test_constant_delay_exact_and_in_order():
    line = DelayLine(Constant(2.0), seed=1)
    for i in range(20):
        line.push(i * 0.1, i)
    assert line.next_release() == pytest.approx(2.0)
    assert line.pop_due(1.99) == []
    got = line.pop_due(10.0)
    assert got == list(range(20))
    assert all(r.t_out - r.t_in == pytest.approx(2.0) for r in line.log)
    assert line.next_release() is None and line.counters.released == 20


def test_fifo_matches_pure_function_with_per_packet_draws():
    g = TruncatedGaussian(5, 3)
    line = DelayLine(g, seed=3, epoch_s=0)
    t = np.arange(0, 100, 0.1)
    for i, x in enumerate(t):
        line.push(x, i)
    samp = np.array([r.delay for r in line.log])
    t_out = np.array([r.t_out for r in line.log])
    assert np.array_equal(t_out, fifo_release(t, samp))
    assert line.counters.clamped > 0
    released = line.pop_due(1e9)
    assert released == sorted(released)  # FIFO: release order == send order
    # the line's delay process is reproducible from delay_seed(seed)
    ref = DelayProcess(g, delay_seed(3), epoch_s=0)
    assert samp[17] == ref.delay(t[17], 17)


def test_loss_dup_statistics_and_determinism():
    def run(seed):
        line = DelayLine(Uniform(0.2, 1.0), seed=seed, loss=0.2, dup=0.1)
        for i in range(5000):
            line.push(i * 0.02, i)
        return line, line.pop_due(1e9)

    line, out = run(7)
    c = line.counters
    assert 0.18 < c.dropped_loss / 5000 < 0.22
    assert 0.08 < c.duplicated / (5000 - c.dropped_loss) < 0.12
    assert len(out) == 5000 - c.dropped_loss + c.duplicated
    line2, out2 = run(7)
    assert out2 == out
    _, out3 = run(8)
    assert out3 != out


def test_impairment_draws_do_not_shift_when_a_knob_changes():
    lines = [DelayLine(Constant(1.0), seed=5, loss=0.3, dup=d) for d in (0.0, 0.5)]
    for line in lines:
        for i in range(400):
            line.push(i * 0.1, i)
    lost = [{r.seq for r in line.log if r.dropped} for line in lines]
    assert lost[0] == lost[1]


def test_reorder_jumps_queue():
    line = DelayLine(Constant(4.0), seed=11, reorder=0.2)
    for i in range(1000):
        line.push(i * 0.1, i)
    out = line.pop_due(1e9)
    inversions = sum(1 for a, b in zip(out, out[1:]) if b < a)
    assert 0.15 < line.counters.reordered / 1000 < 0.25
    assert inversions > 100
    jumped = [r for r in line.log if r.reordered]
    assert all(r.t_out - r.t_in == pytest.approx(2.0) for r in jumped)


def test_outage_windows_drop_everything_sent_inside():
    line = DelayLine(Constant(1.0), seed=0, outages=[(10.0, 20.0), (30.0, 31.0)])
    for i in range(400):
        line.push(i * 0.1, i)
    dropped = [r for r in line.log if r.dropped == "outage"]
    assert len(dropped) == 110
    assert all(10.0 <= r.t_in < 20.0 or 30.0 <= r.t_in < 31.0 for r in dropped)
    out = line.pop_due(1e9)
    assert len(out) == 290
    with pytest.raises(UsageError):
        DelayLine(Constant(1.0), outages=[(5, 2)])


def test_no_fifo_lets_packets_overtake():
    line = DelayLine(Uniform(0.2, 10.0), seed=2, epoch_s=0, fifo=False)
    for i in range(200):
        line.push(i * 0.1, i)
    assert line.counters.clamped == 0
    assert line.pop_due(1e9) != list(range(200))


def test_max_queue_and_bad_probabilities():
    line = DelayLine(Constant(1.0), seed=0, max_queue=5)
    for i in range(10):
        line.push(0.0, i)
    assert line.counters.dropped_queue == 5 and len(line) == 5
    with pytest.raises(UsageError, match="loss"):
        DelayLine(Constant(1.0), loss=1.5)


def test_stats_report_effective_delay():
    line = DelayLine(Constant(3.0), seed=0)
    for i in range(10):
        line.push(float(i), i)
    s = line.stats()
    assert s["delay_effective_mean_s"] == pytest.approx(3.0)
    assert s["pushed"] == 10 and s["in_flight"] == 10


from hypothesis import given, settings, strategies as st  # noqa: E402


@settings(max_examples=30, deadline=None)
@given(gaps=st.lists(st.floats(0.0, 5.0), min_size=1, max_size=60), seed=st.integers(0, 2**32 - 1),
       loss=st.sampled_from([0.0, 0.3]))
def test_property_line_equals_pure_rule_and_never_early(gaps, seed, loss):
    line = DelayLine(Uniform(0.2, 10.0), seed=seed, epoch_s=0, loss=loss)
    t = np.cumsum(gaps)
    for i, x in enumerate(t):
        line.push(float(x), i)
    recs = line.log
    keep = np.array([not r.dropped for r in recs])
    ref = fifo_release(t, np.array([r.delay for r in recs]), keep)
    got = np.array([r.t_out if not r.dropped else np.inf for r in recs])
    assert np.array_equal(got, ref)
    assert np.all(got[keep] >= t[keep] + 0.2)
    out = line.pop_due(float(t[-1]) + 20.0)
    assert out == [i for i in range(len(t)) if keep[i]]  # FIFO, nothing lost but the dropped


def test_keyed_impairment_draws_are_skipped_only_on_a_line_without_impairments(monkeypatch):
    """Keyed pushes (the shim's) on a line with no loss, duplication or reordering draw nothing: every uniform
    would be compared with a zero rate. Their records and releases are those of the same line pushed from its
    sequential stream (which the rates do not read either). With any rate the keyed draw is made per packet."""
    calls = []
    real = DelayLine.fault_uniforms
    monkeypatch.setattr(DelayLine, "fault_uniforms", lambda self, key: calls.append(key) or real(self, key))
    times = np.arange(0.0, 30.0, 0.7)
    keyed, plain = (DelayLine(TruncatedGaussian(4, 2), seed=5, epoch_s=0, outages=[(10.0, 12.0)]) for _ in range(2))
    for i, t in enumerate(times):
        keyed.push(float(t), i, key=(2, i, 0))
        plain.push(float(t), i)
    assert calls == []
    fields = lambda r: (r.seq, r.t_in, r.delay, r.t_out, r.dropped, r.copy, r.reordered)  # noqa: E731
    assert [fields(r) for r in keyed.log] == [fields(r) for r in plain.log]
    assert any(r.dropped == "outage" for r in keyed.log)  # the outage is still applied
    assert keyed.pop_due(1e9) == plain.pop_due(1e9) and keyed.counters == plain.counters
    for rates in ({"loss": 0.2}, {"dup": 0.2}, {"reorder": 0.2}):
        calls.clear()
        line = DelayLine(Constant(4.0), seed=5, **rates)
        for i, t in enumerate(times):
            line.push(float(t), i, key=(2, i, 0))
        assert calls == [(2, i, 0) for i in range(times.size)], rates
