"""The wait-map oracles themselves can fail: hand-made maps that break each property are caught."""

import numpy as np
import pytest

from daa_sil.waitmap import MdpParams, WaitMap, WaitMapFamily, paper_grid
from daa_sil.waitmap import oracles


def _map(wait_fn, turn=0.0, p=0.5):
    """A WaitMap on the paper grid whose wait is ``wait_fn(nodes)`` (s); nothing is evade or LoWC."""
    g = paper_grid()
    nodes = g.nodes()
    w = np.asarray(wait_fn(nodes), float)
    one = np.ones(g.shape)
    return WaitMap(grid=g, params=MdpParams(), turn_rate_deg=turn, wait_s=w, p_lowc=p * one, t_lowc=p * w,
                   q_wait=one, lowc=np.zeros(g.shape, bool), stats={})


def _dist(n):
    return np.hypot(n[..., 0], n[..., 1])


def test_head_on_vs_overtaking_holds_fails_and_refuses_an_empty_population():
    closing = lambda n: np.where(np.cos(n[..., 5]) < 0, 0.004, 0.008) * _dist(n)  # noqa: E731
    good = oracles.head_on_vs_overtaking(_map(closing))
    assert good.n >= 20 and good.holds
    bad = oracles.head_on_vs_overtaking(_map(lambda n: 0.012 * _dist(n) - closing(n)))
    assert bad.n >= 20 and bad.held == 0 and not bad.holds and bad.failures
    zeros = oracles.head_on_vs_overtaking(_map(lambda n: 0.0 * n[..., 0]))
    assert zeros.n == 0 and not zeros.holds  # all-zero maps cannot pass


def test_converging_lines_catch_a_wait_that_grows_as_the_intruder_closes():
    good = oracles.converging_lines(_map(lambda n: 0.01 * _dist(n) + 1.0))
    assert good.n >= 10 and good.holds
    bad = oracles.converging_lines(_map(lambda n: 40.0 - 0.01 * _dist(n)))
    assert bad.n >= 10 and not bad.holds


def test_mirror_error_sees_a_broken_pair():
    left = lambda n: 10 + 0.003 * (n[..., 1] + 2000) * (1 + np.sin(n[..., 5]))  # noqa: E731
    mirrored = lambda n: left(np.stack([n[..., 0], -n[..., 1], n[..., 2], n[..., 3], n[..., 4], -n[..., 5]], -1))  # noqa: E731
    sym = lambda n: 10 + 0.003 * np.abs(n[..., 1])  # noqa: E731
    fam = WaitMapFamily([_map(mirrored, -5.0), _map(sym, 0.0), _map(left, 5.0)])
    m = oracles.mirror_error(fam)
    assert m["zero_map"] < 1e-5 and m["pairs"]["+5"]["mirror_error_s"] < 1e-4
    assert m["pairs"]["+5"]["plain_difference_s"] > 1
    broken = WaitMapFamily([_map(left, -5.0), _map(left, 0.0), _map(left, 5.0)])
    mb = oracles.mirror_error(broken)
    assert mb["zero_map"] > 1 and mb["pairs"]["+5"]["mirror_error_s"] > 1


def test_histogram_shape_rule():
    fast = WaitMapFamily([_map(lambda n: 1.0 + 0.002 * _dist(n))])  # 1 .. ~5 s: bulk below 5 s
    h = oracles.histogram(fast)
    assert h["min_s"] == pytest.approx(1.0 + 0.002 * _dist(paper_grid().nodes()).min(), rel=1e-5)
    assert not oracles.paper_shape(h)  # the range starts at 1 s, but most states lie below 5 s
    slow = WaitMapFamily([_map(lambda n: 20.0 + 0.004 * _dist(n))])  # bulk far above 10 s
    assert not oracles.paper_shape(oracles.histogram(slow))
    calm = WaitMapFamily([_map(lambda n: 5.0 + 0 * n[..., 0], p=1e-4)])  # below p_min: no threat
    assert oracles.histogram(calm)["n"] == 0 and not oracles.paper_shape(oracles.histogram(calm))


def _sample(parts) -> np.ndarray:
    """Waits (s) spread evenly over each (lo, hi, count) part."""
    return np.concatenate([np.linspace(lo, hi, n) for lo, hi, n in parts])


def test_shape_rules_pass_the_papers_description_and_fail_each_departure():
    """The paper's Fig. 3 text: min 1 s, max 40 s, most states 5-10 s, left skewed. A hand-made sample
    with all four passes; moving one feature at a time fails exactly that rule."""
    paper_like = _sample([(1.0, 8.5, 350), (8.5, 10.0, 600), (10.0, 40.0, 50)])
    h = oracles.histogram_of(paper_like, 40.0)
    assert h["share_5_10"] > 0.7 and h["quartile_skew"] < 0
    assert all(oracles.shape_checks(h).values()) and oracles.paper_shape(h)
    # bulk at 0-5 s and a tail toward 40 s (the shape of our paper-grid maps): "most" and "left skewed" fail
    right = oracles.histogram_of(_sample([(1.0, 5.0, 550), (5.0, 10.0, 380), (10.0, 38.0, 70)]), 40.0)
    failed = {k for k, ok in oracles.shape_checks(right).items() if not ok}
    assert failed == {"most states within 5-10 s (> 50 %)", "left skewed (quartile skewness < 0)"}
    assert not oracles.paper_shape(right)
    short = oracles.histogram_of(_sample([(1.0, 8.5, 350), (8.5, 10.0, 600), (10.0, 28.0, 50)]), 40.0)
    assert [k for k, ok in oracles.shape_checks(short).items() if not ok] == ["max about 40 s (35-45 s)"]
    late = oracles.histogram_of(_sample([(3.0, 8.5, 350), (8.5, 10.0, 600), (10.0, 40.0, 50)]), 40.0)
    assert [k for k, ok in oracles.shape_checks(late).items() if not ok] == ["min about 1 s (<= 2 s)"]
    assert not any(oracles.shape_checks(oracles.histogram_of(np.array([]), 40.0)).values())


def test_speed_trend_shares():
    slower_waits_longer = _map(lambda n: 50.0 - 0.1 * n[..., 3])
    t = oracles.speed_trend(slower_waits_longer)
    assert t["lines"] > 0 and t["decreasing"] == 1.0 and t["increasing"] == 0.0
    t2 = oracles.speed_trend(_map(lambda n: 1.0 + 0.1 * n[..., 3]))
    assert t2["increasing"] == 1.0
