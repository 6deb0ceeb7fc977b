"""The encounter-level statistics engine: reproducibility, exact results by hand, and coverage on
clustered data with a known answer (where the old per-step Poisson intervals are too narrow)."""

import math

import numpy as np
import pytest
from scipy import stats as sps

from daa_sil.study.analysis import metrics as M
from daa_sil.study.analysis import stats as S
from daa_sil.errors import UsageError


def test_weights_are_resamples_and_reproducible():
    b = S.ClusterBootstrap(37, replicates=600, seed=5)
    blocks = list(b.weight_blocks())
    assert [w.shape for w in blocks] == [(250, 37), (250, 37), (100, 37)]
    w = np.vstack(blocks)
    assert np.all(w.sum(axis=1) == 37) and np.all(w >= 0) and np.all(w == np.rint(w))
    assert w.mean() == pytest.approx(1.0)
    # each encounter's weight is Binomial(37, 1/37): variance 36/37
    assert w.var() == pytest.approx(36 / 37, rel=0.05)
    again = np.vstack(list(S.ClusterBootstrap(37, 600, 5).weight_blocks()))
    other = np.vstack(list(S.ClusterBootstrap(37, 600, 6).weight_blocks()))
    assert np.array_equal(w, again) and not np.array_equal(w, other)
    # columns summed together or one at a time see the same resamples (pairing)
    x = np.random.default_rng(0).poisson(2.0, (37, 3))
    both = b.sums(x)
    assert np.array_equal(both[:, 1], b.sums(x[:, 1])[:, 0])
    assert np.allclose(both, w @ x)


def test_sample_arithmetic_and_undefined_resamples():
    b = S.ClusterBootstrap(5, replicates=400, seed=1)
    s = b.sample_sums({"y": [1, 0, 0, 0, 0], "x": [1, 1, 0, 0, 0]})
    r = s["y"] / s["x"]
    assert r.value == 0.5
    assert r.undefined > 0  # resamples drawing none of the first two encounters
    assert np.all(np.isnan(r.reps[(s["x"].reps == 0)]))
    lo, hi = r.interval()
    assert 0.0 <= lo <= 0.5 <= hi <= 1.0
    d = 1 - r * 2
    assert d.value == 0.0 and np.allclose(d.reps[np.isfinite(r.reps)], 1 - 2 * r.reps[np.isfinite(r.reps)])


def test_exact_results_by_hand():
    one, two = S.zero_upper_bounds(10_000)
    assert one == pytest.approx(1 - 0.05 ** 1e-4) and one == pytest.approx(2.9953e-4, rel=1e-4)
    assert two == pytest.approx(1 - 0.025 ** 1e-4) and two == pytest.approx(3.6883e-4, rel=1e-4)
    # 7 encounters with LoWC only under a, 1 only under b: p = 2 * P(X <= 1 | Bin(8, 1/2)) = 18/256
    a = np.r_[np.ones(7, bool), np.zeros(1, bool), np.ones(3, bool), np.zeros(89, bool)]
    b = np.r_[np.zeros(7, bool), np.ones(1, bool), np.ones(3, bool), np.zeros(89, bool)]
    m = S.mcnemar_exact(a, b)
    assert (m.a_only, m.b_only, m.both, m.n) == (7, 1, 3, 100)
    assert m.p_value == pytest.approx(18 / 256)
    assert m.difference == pytest.approx(0.06)
    assert S.mcnemar_exact(a, a).p_value == 1.0
    lo, hi = S.clopper_pearson(3, 10)
    assert lo == pytest.approx(sps.beta.ppf(0.025, 3, 8)) and hi == pytest.approx(sps.beta.ppf(0.975, 4, 7))
    with pytest.raises(UsageError):
        S.ClusterBootstrap(0)
    with pytest.raises(UsageError):
        S.mcnemar_exact(a, b[:5])


def test_bootstrap_agrees_with_the_linearised_ratio_estimator():
    """Large sample: the bootstrap interval of a ratio of sums has the width of the analytic
    delta-method interval (two independent computations)."""
    rng = np.random.default_rng(3)
    n = 5000
    x = rng.poisson(3.0, n) * (rng.random(n) < 0.3)
    y = rng.binomial(x, rng.beta(2, 3, n))
    s = S.ClusterBootstrap(n, 2000, 9).sample_sums({"y": y, "x": x})
    r = s["y"] / s["x"]
    lo, hi = r.interval()
    R, llo, lhi = S.ratio_linearized(y, x)
    assert r.value == pytest.approx(R)
    assert (hi - lo) == pytest.approx(lhi - llo, rel=0.1)
    assert (lo + hi) / 2 == pytest.approx(R, abs=0.1 * (lhi - llo))


def _clustered(rng, n, rho, shared=True):
    """Encounters like the campaign's: 15 % active for 1 + Poisson(30) steps; each active encounter
    has its own step probability p_i ~ Beta(2, 3) (the clustering). Group b counts Bin(A_i, p_i),
    group g flies the same encounters (same A_i) and counts Bin(A_i, rho q_i), with q_i = p_i
    (``shared``: the groups' counts move together) or an independent Beta(2, 3) draw. Truths: mean
    per encounter of b = 0.15 * 31 * 0.4 = 1.86; ratio g/b = rho; step share of g = 0.4 rho."""
    active = rng.random(n) < 0.15
    steps = np.where(active, 1 + rng.poisson(30.0, n), 0)
    p = rng.beta(2.0, 3.0, n)
    q = p if shared else rng.beta(2.0, 3.0, n)
    return steps, rng.binomial(steps, p), rng.binomial(steps, rho * q)


@pytest.mark.parametrize("shared", [True, False])
def test_coverage_on_clustered_data_with_a_known_answer(shared):
    """400 campaigns of 600 encounters: the encounter bootstrap covers the true values about 95 % of
    the time (within 3 binomial standard errors: [0.917, 0.983]); the old per-step Poisson intervals
    (Garwood for the total, conditional binomial for the rate ratio) do not: the total's is far too
    narrow; the ratio's is too narrow when the groups' per-encounter rates are independent and too
    wide when they move together (it ignores both the clustering and the pairing)."""
    rng = np.random.default_rng(2024 + shared)
    n, rho, reps = 600, 0.3, 400
    true_mean, true_share = 0.15 * 31 * 0.4, rho * 0.4
    hit = {"mean": 0, "ratio": 0, "share": 0, "mean_poisson": 0, "ratio_poisson": 0}
    width = {"mean": [], "mean_poisson": [], "ratio": [], "ratio_poisson": []}
    for k in range(reps):
        steps, yb, yg = _clustered(rng, n, rho, shared)
        s = S.ClusterBootstrap(n, 1000, seed=k).sample_sums({"b": yb, "g": yg, "steps": steps})
        mean = s["b"] / n
        ratio = s["g"] / s["b"]
        share = s["g"] / s["steps"]
        for name, st, truth in (("mean", mean, true_mean), ("ratio", ratio, rho), ("share", share, true_share)):
            lo, hi = st.interval()
            hit[name] += lo <= truth <= hi
            if name in width:
                width[name].append(hi - lo)
        plo, phi = M.poisson_exact(yb.sum())
        hit["mean_poisson"] += plo / n <= true_mean <= phi / n
        width["mean_poisson"].append((phi - plo) / n)
        _, rlo, rhi = M.rate_ratio(yg.sum(), n, yb.sum(), n)
        hit["ratio_poisson"] += rlo <= rho <= rhi
        width["ratio_poisson"].append(rhi - rlo)
    cov = {k: v / reps for k, v in hit.items()}
    se = math.sqrt(0.95 * 0.05 / reps)
    for name in ("mean", "ratio", "share"):
        assert 0.95 - 3 * se <= cov[name] <= 0.95 + 3 * se, (name, cov)
    assert cov["mean_poisson"] < 0.95 - 10 * se, cov
    assert np.median(width["mean"]) > 2 * np.median(width["mean_poisson"])
    if shared:  # pairing: the paired bootstrap is narrower than the unpaired conditional interval
        assert np.median(width["ratio"]) < np.median(width["ratio_poisson"])
    else:
        assert cov["ratio_poisson"] < 0.95 - 10 * se, cov
        assert np.median(width["ratio"]) > 1.2 * np.median(width["ratio_poisson"])


def test_pairing_narrows_a_change_without_losing_coverage():
    """The same weights for both groups (paired) against independent weights (unpaired) on the same
    data: the paired interval of the ratio is narrower; both cover rho."""
    rng = np.random.default_rng(8)
    n, rho = 2000, 0.3
    steps, yb, yg = _clustered(rng, n, rho)
    paired = S.ClusterBootstrap(n, 2000, 1).sample_sums({"b": yb, "g": yg})
    rb = S.ClusterBootstrap(n, 2000, 2).sample_sums({"b": yb})["b"]
    rg = S.ClusterBootstrap(n, 2000, 3).sample_sums({"g": yg})["g"]
    lo_p, hi_p = (paired["g"] / paired["b"]).interval()
    lo_u, hi_u = S.Sample(rg.value / rb.value, rg.reps / rb.reps).interval()
    assert hi_p - lo_p < 0.8 * (hi_u - lo_u)
    assert lo_p <= yg.sum() / yb.sum() <= hi_p


def test_independent_difference_of_two_campaigns():
    """Two independent campaigns of different sizes with the same mean: the difference's interval
    covers 0 and is about sqrt(2) times one campaign's; jackknife values of different encounter sets
    are never combined."""
    rng = np.random.default_rng(4)
    a = S.ClusterBootstrap(3000, 2000, 1).sample_sums({"x": rng.poisson(2.0, 3000)})["x"] / 3000
    b = S.ClusterBootstrap(2000, 2000, 1).sample_sums({"x": rng.poisson(2.0, 2000)})["x"] / 2000
    assert (a - b).jack is None  # 3000 vs 2000 leave-one-out values: not paired
    d = S.independent_difference(a, b)
    lo, hi = d.interval()
    assert lo < 0 < hi
    sd_a, sd_b = a.reps.std(), b.reps.std()
    assert d.reps.std() == pytest.approx(math.hypot(sd_a, sd_b), rel=0.1)
