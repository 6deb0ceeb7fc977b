"""The vehicle's step-log helpers: the vectorised band-interval merge against a plain loop."""

from __future__ import annotations

import math

import numpy as np
import pytest

from daa_sil.daa.config import REGION_NAMES
from vehicle.core import track_intervals


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


def test_track_intervals_edge_cases():
    assert track_intervals(np.array([]), np.array([], np.int8)) == ([], [], [])
    assert track_intervals(np.array([np.nan, 5.0]), np.array([2, -1])) == ([], [], [])
    # a skipped sample does not split a run
    assert track_intervals(np.array([1.0, np.nan, 3.0, 4.0]), np.array([2, 3, 2, 3])) == (
        [1.0, 4.0], [3.0, 4.0], [REGION_NAMES[2], REGION_NAMES[3]])
