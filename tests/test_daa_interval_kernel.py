"""The bands' fast kernel (``intervals.interval_soa``) equals ``wellclear.violation_interval``
element for element, edge cases included (level flight, inside DMOD / ZTHR now, a single-instant
vertical window, zero relative velocity, zero length)."""

import numpy as np
import pytest

from daa_sil.geometry import wellclear as wc
from daa_sil.daa import intervals as T
from daa_sil.geometry.thresholds import get_thresholds


def _edge_cases(th):
    H = th.zthr
    s = np.array([[3000.0, 0, 0], [100.0, 50, 10], [5000, 0, H + 100], [2000, 100, -50], [0, 0, 0],
                  [1500, -200, H], [800, 0, 2 * H]])
    v = np.array([[-100.0, 0, 0], [0, 0, 0], [-150, 0, -5], [-80, 0, 0], [0, 0, 0], [-60, 10, 3], [-40, 0, -2 * H]])
    length = np.array([180.0, 50, 120, 0.0, 10, 60, 0.5])
    return s, v, length


@pytest.mark.parametrize("preset", ["do365", "paper"])
def test_kernel_matches_reference_closed_form(preset):
    th = get_thresholds(preset)
    rng = np.random.default_rng(7)
    n = 20000
    s = np.column_stack([rng.uniform(-8000, 8000, n), rng.uniform(-8000, 8000, n), rng.uniform(-400, 400, n)])
    v = np.column_stack([rng.uniform(-250, 250, n), rng.uniform(-250, 250, n),
                         np.where(rng.random(n) < 0.3, 0.0, rng.uniform(-15, 15, n))])
    length = np.where(rng.random(n) < 0.5, rng.uniform(0, 3, n), rng.uniform(0, 180, n))
    es, ev, el = _edge_cases(th)
    s, v, length = np.vstack([s, es]), np.vstack([v, ev]), np.concatenate([length, el])
    ref_in, ref_out = wc.violation_interval(s, v, th, 0.0, length)
    got_in, got_out = T.interval_soa(*(np.ascontiguousarray(a[:, i]) for a in (s, v) for i in range(3)), length, th)
    np.testing.assert_array_equal(got_in, ref_in)
    np.testing.assert_array_equal(got_out, ref_out)
    # the sample exercises both outcomes, so the equality above is not vacuous
    assert 200 < np.isfinite(ref_in).sum() < n - 200


def test_filtered_interval_broadcasts_like_the_reference():
    th = get_thresholds("do365")
    s = np.array([[[4000.0, 0, 0]], [[3000.0, 500, 30]]])  # (2, 1, 3)
    v = np.array([[-120.0, 0, 0], [-100, -10, 0], [-90, 5, -1]])  # (3, 3) -> broadcast (2, 3)
    got = T.filtered_interval(s, v, th, 120.0)
    ref = wc.violation_interval(s, v, th, 0.0, 120.0)
    assert got[0].shape == (2, 3)
    np.testing.assert_array_equal(got[0], ref[0])
    np.testing.assert_array_equal(got[1], ref[1])
    assert np.isfinite(got[0]).any()
