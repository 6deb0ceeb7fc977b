"""The step log's band summary (one definition for fast-time and the SIL vehicle): the vectorised
merge against a plain loop, one row (the vehicle's, through :func:`daa_sil.steplog.band_row`) and whole
batches (fast-time's)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from daa_sil.daa.config import REGION_NAMES
from daa_sil.onboard import band_intervals
from daa_sil.steplog import band_row


def track_intervals(values, regions):
    """One encounter's band samples ``(K,)`` as its step-log row holds them: (lo, hi, region names)."""
    r = band_row(band_intervals(np.asarray(values, float)[None, :], np.asarray(regions)[None, :]), 0)
    return r["bands_trk_lo_deg"], r["bands_trk_hi_deg"], r["bands_trk_region"]


def _loop(values, regions):
    """The definition, one sample at a time: skip non-finite values and negative regions; a run of
    equal regions among the others is one interval (first value, last value, region name)."""
    out = []
    for v, r in zip(values, regions):
        if not math.isfinite(v) or r < 0:
            continue
        if out and out[-1][2] == REGION_NAMES[r]:
            out[-1][1] = float(v)
        else:
            out.append([float(v), float(v), REGION_NAMES[r]])
    return [x[0] for x in out], [x[1] for x in out], [x[2] for x in out]


@pytest.mark.parametrize("seed", range(40))
def test_track_intervals_match_the_definition(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(0, 80))
    values = np.sort(rng.uniform(0, 360, n))
    values[rng.random(n) < 0.2] = np.nan  # samples with no value
    values[rng.random(n) < 0.05] = np.inf
    regions = rng.choice([-1, 0, 1, 2, 3, 4], n, p=[0.1, 0.3, 0.05, 0.2, 0.25, 0.1]).astype(np.int8)
    got = track_intervals(values, regions)
    assert got == _loop(values, regions)
    assert all(type(x) is float for x in got[0] + got[1])


@pytest.mark.parametrize("seed", range(10))
def test_batched_band_intervals_match_the_definition_row_by_row(seed):
    """Fast-time's (N, K) merge gives every row what the loop gives it, padded to the widest row."""
    rng = np.random.default_rng(100 + seed)
    n, k = int(rng.integers(1, 30)), int(rng.integers(0, 60))
    values = np.sort(rng.uniform(0, 360, (n, k)), axis=1)
    values[rng.random((n, k)) < 0.15] = np.nan
    values[rng.random((n, k)) < 0.05] = -np.inf
    regions = rng.choice([-1, 0, 1, 2, 3, 4], (n, k), p=[0.15, 0.3, 0.05, 0.2, 0.2, 0.1]).astype(np.int8)
    regions[rng.random(n) < 0.2] = -1  # whole rows without bands (inactive encounters)
    b = band_intervals(values, regions)
    for i in range(n):
        lo, hi, names = _loop(values[i], regions[i])
        c = int(b["bands_count"][i])
        assert c == len(lo)
        assert b["bands_trk_lo_deg"][i, :c].tolist() == lo and b["bands_trk_hi_deg"][i, :c].tolist() == hi
        assert [REGION_NAMES[r] for r in b["bands_trk_region"][i, :c]] == names
        assert np.isnan(b["bands_trk_lo_deg"][i, c:]).all() and np.isnan(b["bands_trk_hi_deg"][i, c:]).all()


@pytest.mark.parametrize("n, k", [(1, 72), (5, 10), (3, 0), (0, 4)])
def test_a_batch_without_bands_merges_to_empty_rows(n, k):
    """No sample kept anywhere (inactive rows, nan values): every row has no interval, and the arrays
    have the shapes and types a batch with bands pads to (N, 0) floats / int64 regions, (N,) counts."""
    values = np.full((n, k), np.nan)
    values[:, ::2] = 10.0  # values without a region are left out too
    regions = np.full((n, k), -1, np.int8)
    regions[:, 1::2] = 3  # regions without a value likewise
    b = band_intervals(values, regions)
    assert b["bands_count"].dtype == np.int64 and b["bands_count"].tolist() == [0] * n
    for name, dtype in (("bands_trk_lo_deg", np.float64), ("bands_trk_hi_deg", np.float64),
                        ("bands_trk_region", np.int64)):
        assert b[name].shape == (n, 0) and b[name].dtype == dtype
    if n and k > 1:  # the same types as the general merge gives a batch with one kept sample
        kept = regions.copy()
        kept[0, 0] = 2
        g = band_intervals(values, kept)
        assert g["bands_count"][0] == 1 and all(g[name].dtype == b[name].dtype for name in b)


def test_track_intervals_edge_cases():
    assert track_intervals(np.array([]), np.array([], np.int8)) == ([], [], [])
    assert track_intervals(np.array([np.nan, 5.0]), np.array([2, -1])) == ([], [], [])
    # a skipped sample does not split a run
    assert track_intervals(np.array([1.0, np.nan, 3.0, 4.0]), np.array([2, 3, 2, 3])) == (
        [1.0, 4.0], [3.0, 4.0], [REGION_NAMES[2], REGION_NAMES[3]])
