"""Delay models, spec parsing and the seeded delay process (daa_sil.models.latency)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from daa_sil.errors import FileFormatError, UsageError
from daa_sil.models.delay_spec import delay_model_from_dict, parse_delay_spec
from daa_sil.models.latency import Constant, Trace, TruncatedGaussian, Uniform
from daa_sil.models.delay_process import BatchedDelay, DelayProcess


def test_truncated_gaussian_statistics_match_truncnorm():
    g = TruncatedGaussian(5.0, 3.0)  # paper B-2 / ID-2
    x = g.sample(np.random.default_rng(1), np.zeros(200_000))
    assert x.min() >= 0.2 and x.max() <= 10.0
    oracle = stats.truncnorm((0.2 - 5) / 3, (10 - 5) / 3, loc=5, scale=3)
    assert abs(x.mean() - oracle.mean()) < 0.02
    assert abs(x.std() - oracle.std()) < 0.02
    assert abs(oracle.std() - 2.34) < 0.03  # the truncated sd is not 3 s
    assert g.mean() == pytest.approx(oracle.mean(), abs=1e-9)
    assert g.std() == pytest.approx(oracle.std(), abs=1e-9)
    # rejection, not clipping: no pile-up of mass at the bounds
    assert np.mean(x < 0.25) < 0.01 and np.mean(x > 9.95) < 0.01
    assert stats.kstest(x[:20_000], oracle.cdf).pvalue > 1e-3


def test_uniform_and_constant_are_exact():
    rng = np.random.default_rng(2)
    c = Constant(4).sample(rng, np.zeros(10))
    assert np.all(c == 4.0)
    u = Uniform(1, 8).sample(rng, np.zeros(100_000))
    assert u.min() >= 1 and u.max() <= 8
    assert abs(u.mean() - 4.5) < 0.03 and Uniform(1, 8).mean() == 4.5


def test_trace_is_zero_order_hold(tmp_path):
    p = tmp_path / "trace.csv"
    p.write_text("t,delay\n0,1.0\n10,2.5\n20,0.5\n")
    tr = parse_delay_spec(f"trace:{p}")
    assert isinstance(tr, Trace)
    got = tr.sample(None, np.array([-5.0, 0.0, 9.99, 10.0, 15.0, 25.0]))
    assert got.tolist() == [1.0, 1.0, 1.0, 2.5, 2.5, 0.5]
    proc = DelayProcess(tr, seed=0)
    assert proc.delay(12.0) == 2.5


@pytest.mark.parametrize("spec,expected", [
    ("const:4", Constant(4)),
    ("gauss:5,3", TruncatedGaussian(5, 3, 0.2, 10)),
    ("gauss:5,3,1,9", TruncatedGaussian(5, 3, 1, 9)),
    ("uniform:1,8", Uniform(1, 8)),
])
def test_parse_delay_spec(spec, expected):
    m = parse_delay_spec(spec)
    assert m == expected
    assert parse_delay_spec(m.spec()) == m  # spec() round-trips


@pytest.mark.parametrize("spec", ["const:0.05", "const:11", "gauss:5", "gauss:5,0", "uniform:8,1", "nope:1",
                                  "const", "const:x", "gauss:50,1", ""])
def test_bad_delay_spec_is_one_line_usage_error(spec):
    with pytest.raises(UsageError) as ei:
        parse_delay_spec(spec)
    assert "\n" not in str(ei.value) and str(ei.value)


def test_trace_file_errors(tmp_path):
    with pytest.raises(FileFormatError, match="cannot read"):
        parse_delay_spec(f"trace:{tmp_path / 'missing.csv'}")
    bad = tmp_path / "bad.csv"
    bad.write_text("0,1\n5,20\n")
    with pytest.raises(FileFormatError, match="t=5"):
        parse_delay_spec(f"trace:{bad}")
    bad.write_text("0,1\n0,2\n")
    with pytest.raises(FileFormatError, match="increasing"):
        parse_delay_spec(f"trace:{bad}")


def test_model_from_paper_yaml_form():
    assert delay_model_from_dict({"type": "constant", "seconds": 4}) == Constant(4)
    g = delay_model_from_dict({"type": "gaussian", "mean_s": 5, "sd_s": 3})
    assert g == TruncatedGaussian(5, 3)
    assert delay_model_from_dict(g.to_dict()) == g
    with pytest.raises(UsageError, match="unknown key"):
        delay_model_from_dict({"type": "constant", "seconds": 4, "mean_s": 1})
    with pytest.raises(UsageError, match="missing sd_s"):
        delay_model_from_dict({"type": "gaussian", "mean_s": 5})
    with pytest.raises(UsageError, match="type"):
        delay_model_from_dict({"type": "poisson"})


def test_delay_process_piecewise_constant_and_independent_of_query_order():
    g = TruncatedGaussian(5, 3)
    a = DelayProcess(g, seed=42, epoch_s=10.0)
    b = DelayProcess(g, seed=42, epoch_s=10.0)
    ts = np.arange(0.0, 600.0, 0.1)
    da = np.array([a.delay(t) for t in ts])
    db = np.array([b.delay(t) for t in ts[::-1]])[::-1]  # reversed query order
    assert np.array_equal(da, db)
    # constant within each epoch, changes between epochs
    epochs = (ts // 10).astype(int)
    for e in (0, 7, 59):
        assert np.ptp(da[epochs == e]) == 0
    assert len(np.unique(da)) == 60
    c = DelayProcess(g, seed=43, epoch_s=10.0)
    assert c.delay(5.0) != a.delay(5.0)


def test_per_packet_draws_need_index():
    p = DelayProcess(Uniform(1, 8), seed=1, epoch_s=0)
    d = [p.delay(0.0, i) for i in range(1000)]
    assert len(set(d)) == 1000
    assert d[300] == DelayProcess(Uniform(1, 8), seed=1, epoch_s=0).delay(99.0, 300)
    with pytest.raises(UsageError):
        p.delay(1.0)


def test_batched_delay_equals_per_encounter_process():
    g = TruncatedGaussian(5, 3)
    seeds = np.random.SeedSequence(2024).spawn(50)
    bd = BatchedDelay(g, seeds, epoch_s=1.0, duration_s=600.0)  # > one 256-epoch block
    for t in (0.0, 0.5, 255.9, 256.0, 599.0):
        row = bd.delay_at(t)
        assert row.shape == (50,)
        ref = [DelayProcess(g, s, epoch_s=1.0).delay(t) for s in seeds[:5]]
        assert np.array_equal(row[:5], ref)
    per = bd.delay_at(np.linspace(0, 500, 50))
    assert per[3] == DelayProcess(g, seeds[3], epoch_s=1.0).delay(np.linspace(0, 500, 50)[3])
    with pytest.raises(UsageError, match="duration"):
        bd.delay_at(700.0)


def test_iid_fifo_inflation_vs_piecewise_constant():
    """Why the default is piecewise constant (docs/models.md, "Link delay"): an i.i.d. draw per packet of a
    10 Hz stream over 600 s, kept FIFO, inflates a 5 s Gaussian delay to about 8 s."""
    from daa_sil.link.delayline import fifo_release

    g = TruncatedGaussian(5, 3)
    t = np.arange(0.0, 600.0, 0.1)
    iid = DelayProcess(g, seed=42, epoch_s=0)
    d_iid = np.array([iid.delay(x, i) for i, x in enumerate(t)])
    eff_iid = fifo_release(t, d_iid) - t
    assert np.mean(np.diff(t + d_iid) < 0) > 0.4  # about half of adjacent pairs invert
    assert eff_iid.mean() > 7.5  # FIFO clamp inflates 5 s to ~8.3 s
    pc = DelayProcess(g, seed=42, epoch_s=20.0)
    d_pc = np.array([pc.delay(x) for x in t])
    eff_pc = fifo_release(t, d_pc) - t
    assert abs(eff_pc.mean() - d_pc.mean()) < 0.2


@pytest.mark.parametrize("spec, draws", [("const:4", False), ("spike:1,6,10,5,30", False), ("uniform:1,8", True),
                                         ("gauss:5,3", True)])
def test_the_draws_flag_says_whether_sample_reads_its_generator(spec, draws):
    """A model that declares it draws nothing gets no generator (fast-time skips making one per
    encounter and block); one that draws gives other delays from other generators. Also through the
    half-round-trip rule, which answers for its round trip."""
    from daa_sil.models.link_rule import HalfRoundTrip

    t = np.arange(64, dtype=float)
    for model in (parse_delay_spec(spec), HalfRoundTrip(parse_delay_spec(spec))):
        assert model.draws is draws
        a = model.sample(np.random.default_rng(1), t)
        b = model.sample(np.random.default_rng(2), t)
        if draws:
            assert not np.array_equal(a, b)
        else:
            assert np.array_equal(a, b) and np.array_equal(model.sample(None, t), a)
            # the batched table is the per-encounter process, draw for draw, without any generator
            bd = BatchedDelay(model, [7, 8], epoch_s=1.0, duration_s=63.0)
            for i, seed in enumerate((7, 8)):
                p = DelayProcess(model, seed, epoch_s=1.0)
                assert np.array_equal([bd.delay_at(x)[i] for x in t], [p.delay(x) for x in t])
