"""Alerting, ProjL, bands and SM(u) against hand-worked geometry and a brute-force oracle."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from daa_sil.geometry import wellclear as wc
from daa_sil.daa import (AXIS_HORIZONTAL, REGION_MID, REGION_NEAR, REGION_NONE, DaaConfig, alert_levels,
                         compute_bands, proj_lowc, safety_metric)
from daa_sil.daa.axis_paths import candidate_counts, maneuver_paths
from daa_sil.geometry.kinematics import Command, advance
from daa_sil.geometry.units import DEG, FT

from daa_helpers import brute_first_lowc, intruders, own_state

CFG = DaaConfig()
D = CFG.th.dthr


def head_on(rng_m, closing_intr=55.0, dz=0.0, lateral=0.0):
    own = own_state()
    intr = intruders([[[lateral, rng_m, 1000.0 + dz, closing_intr, np.pi, 0.0]]])
    return own, intr


def test_alert_levels_head_on_hand_worked():
    # closure 110 m/s co-altitude: tau_mod = 35 s at r* = (35*110 + sqrt((35*110)^2 + 4 D^2)) / 2;
    # the warning (25 s) is raised when r* is reached within 25 s, i.e. r0 < r* + 25*110.
    r_star = (35 * 110 + np.sqrt((35 * 110) ** 2 + 4 * D * D)) / 2
    cases = [(r_star + 10 * 110, 3), (r_star + 40 * 110, 2), (r_star + 70 * 110, 0)]
    for r0, want in cases:
        own, intr = head_on(r0)
        assert alert_levels(own, intr, CFG)[0, 0] == want, r0
    # 180 m above (between ZTHR 450 ft and the preventive 700 ft): preventive only
    own, intr = head_on(r_star + 10 * 110, dz=180.0)
    assert 450 * FT < 180.0 < 700 * FT
    assert alert_levels(own, intr, CFG)[0, 0] == 1


def test_proj_lowc_exact_boundary():
    r_star = (35 * 110 + np.sqrt((35 * 110) ** 2 + 4 * D * D)) / 2
    own, intr = head_on(r_star + 20 * 110)  # LoWC starts at t = 20 s exactly
    assert proj_lowc(own, intr, CFG, 20.5)[0, 0]
    assert not proj_lowc(own, intr, CFG, 19.5)[0, 0]


def test_head_on_bands_hand_worked():
    own, intr = head_on(6000.0, lateral=500.0)  # intruder passes 500 m to the right: conflict
    b = compute_bands(own, intr, CFG)
    k0 = int(np.nonzero(b.trk.side == 0)[0][0])
    assert b.trk.region[0, k0] in (REGION_MID, REGION_NEAR)
    # turning 90 deg right flies across the intruder's path; 90 deg left flies away from it
    left90 = np.argmin(np.abs(b.trk.delta[0] + 90 * DEG))
    assert b.trk.region[0, left90] == REGION_NONE
    assert np.isfinite(b.trk.res_lo[0])
    # the left resolution is the first NONE candidate scanning left from the current track
    lo_side = np.nonzero(b.trk.side == -1)[0][::-1]  # -5, -10, ... deg
    first = next(k for k in lo_side if b.trk.region[0, k] == REGION_NONE)
    assert b.trk.res_lo[0] == pytest.approx(b.trk.values[0, first])
    assert all(b.trk.region[0, k] != REGION_NONE for k in lo_side if k > first)
    # climbing or descending at the 6000 fpm limit clears 450 ft long before the ~17 s to tau_mod = 35 s
    assert b.vs.region[0, -1] == REGION_NONE and b.vs.region[0, 0] == REGION_NONE
    # intervals cover every candidate value in order
    iv = b.trk.intervals(0)
    assert iv[0][0] == pytest.approx(b.trk.values[0, 0]) and iv[-1][1] == pytest.approx(b.trk.values[0, -1])


def test_fast_paths_match_core_kinematics():
    own = own_state(3, gs=[55.0, 80.0, 30.0], trk=[0.3, 2.0, 5.5], vs=[0.0, 3.0, -2.0])
    for axis, kw in ((1, "turn_rate"), (2, "vertical_accel"), (3, "accel")):
        j = max(candidate_counts(own, axis, CFG))
        paths, _ = maneuver_paths(own, axis, CFG, j)
        pos, vel = paths.stacked()
        t = paths.knot_times()[0, 0]
        perf = CFG.performance()
        rate = {1: CFG.turn_rate, 2: CFG.vertical_accel, 3: CFG.horizontal_accel}[axis]
        ref = advance(own[:, None, None], dt=t, perf=perf, **{kw: np.array([[-rate], [rate]])})
        np.testing.assert_allclose(pos, ref.position(), atol=1e-6)
        np.testing.assert_allclose(vel, ref.velocity(), atol=1e-9)


def test_safety_metric_sign_and_range():
    own, intr = head_on(6000.0, lateral=500.0)
    hold = Command.hold(own)
    sm_hold = safety_metric(own, intr, hold, CFG)
    sm_left = safety_metric(own, intr, Command(np.array([-90 * DEG % (2 * np.pi)])), CFG)
    assert sm_hold[0] <= 0 < sm_left[0] <= CFG.sm_margin_s
    # violating now -> SM = -horizon
    own, intr = head_on(800.0)
    assert safety_metric(own, intr, hold, CFG, horizon_s=40.0)[0] == pytest.approx(-40.0)


case = st.tuples(st.floats(2500, 9000), st.floats(-0.7, 0.7), st.floats(-3.14, 3.14), st.floats(40, 200),
                 st.floats(-150, 150), st.floats(-8, 8))


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(case)
def test_bands_agree_with_brute_force(c):
    rng_m, bearing, itrk, igs, dz, ivs = c
    own = own_state()
    intr = intruders([[[rng_m * np.sin(bearing), rng_m * np.cos(bearing), 1000 + dz, igs, itrk, ivs]]])
    b = compute_bands(own, intr, CFG)
    h = 40.0
    th = CFG.th
    small, big = th.with_(dthr=th.dthr * 0.95, zthr=th.zthr - 5, tthr=th.tthr - 2), \
        th.with_(dthr=th.dthr * 1.05, zthr=th.zthr + 5, tthr=th.tthr + 2)
    for ab in b.axes():
        keep = np.arange(0, ab.values.shape[1], 3)
        vals = ab.values[0, keep]
        n = len(keep)
        o = own_state(n)
        it = intruders([[list(intr.as_array()[0, 0])]] * n)
        if ab.axis == AXIS_HORIZONTAL:
            cmd = Command(vals, np.zeros(n), np.full(n, 55.0))
        elif ab.axis == 2:
            cmd = Command(np.zeros(n), vals, np.full(n, 55.0))
        else:
            cmd = Command(np.zeros(n), np.zeros(n), vals)
        # turn in the candidate's own direction: the band's left -180 candidate is the only ambiguous one
        ok = np.abs(np.abs(ab.delta[0, keep]) - np.pi) > 1e-6
        ours = ab.t_in[0, keep] <= h
        hit_small = brute_first_lowc(o, it, cmd, CFG.performance(), small, h) <= h
        hit_big = brute_first_lowc(o, it, cmd, CFG.performance(), big, h) <= h
        assert np.all(~ok | ~hit_small | ours), (ab.name, vals[hit_small & ~ours])
        assert np.all(~ok | ~ours | hit_big), (ab.name, vals[ours & ~hit_big])


@settings(max_examples=10, deadline=None)
@given(case)
def test_safety_metric_matches_brute_force(c):
    rng_m, bearing, itrk, igs, dz, ivs = c
    own = own_state()
    intr = intruders([[[rng_m * np.sin(bearing), rng_m * np.cos(bearing), 1000 + dz, igs, itrk, ivs]]])
    cmd = Command(np.array([(bearing + 1.0) % (2 * np.pi)]), np.array([5.0]), np.array([60.0]))  # multi-axis
    h = 30.0
    sm = safety_metric(own, intr, cmd, CFG, horizon_s=h)[0]
    th = CFG.th
    small = th.with_(dthr=th.dthr * 0.95, zthr=th.zthr - 5, tthr=th.tthr - 2)
    big = th.with_(dthr=th.dthr * 1.05, zthr=th.zthr + 5, tthr=th.tthr + 2)
    if brute_first_lowc(own, intr, cmd, CFG.performance(), small, h)[0] <= h:
        assert sm <= 0
    if brute_first_lowc(own, intr, cmd, CFG.performance(), big, h)[0] > h:
        assert sm > 0


def _random_encounters(seed: int, n: int, half_width_m: float, dz_m: float):
    """``n`` ownships and one intruder each, at random within ``half_width_m`` (m) and ``dz_m`` (m) of 1000 m."""
    rng = np.random.default_rng(seed)
    own = own_state(n, gs=rng.uniform(30, 90, n), trk=rng.uniform(0, 6.28, n), vs=rng.uniform(-5, 5, n))
    rows = np.stack([rng.uniform(-half_width_m, half_width_m, n), rng.uniform(-half_width_m, half_width_m, n),
                     1000 + rng.uniform(-dz_m, dz_m, n), rng.uniform(40, 200, n), rng.uniform(0, 6.28, n),
                     rng.uniform(-5, 5, n)], -1)[:, None, :]
    return own, intruders(rows)


def test_batch_independence_of_bands():
    own, intr = _random_encounters(3, 40, 5000.0, 200.0)
    b = compute_bands(own, intr, CFG)
    for i in (0, 17, 39):
        bi = compute_bands(own[i:i + 1], intr[i:i + 1], CFG)
        for a, ai in zip(b.axes(), bi.axes()):
            assert a.intervals(i) == ai.intervals(0)
            assert np.array_equal(a.res_lo[i:i + 1], ai.res_lo, equal_nan=True)
            assert np.array_equal(a.res_hi[i:i + 1], ai.res_hi, equal_nan=True)


def test_bands_read_the_states_as_given_without_changing_or_holding_them():
    """compute_bands takes the states of one chunk as they are (no copy): it must not write them, and no
    array of the bands it returns may share memory with them (a caller may change either afterwards)."""
    from dataclasses import fields

    own, intr = _random_encounters(11, 9, 4000.0, 100.0)
    names = ("x", "y", "z", "gs", "trk", "vs")
    before = [getattr(st_, f).copy() for st_ in (own, intr) for f in names]
    b = compute_bands(own, intr, CFG)
    assert all(np.array_equal(a, getattr(st_, f)) for a, (st_, f) in
               zip(before, [(st_, f) for st_ in (own, intr) for f in names]))
    assert any(ab.region.max() > REGION_NONE for ab in b.axes())  # (some conflict: the work was done)
    for ab in b.axes():
        for f in fields(ab):
            got = getattr(ab, f.name)
            if isinstance(got, np.ndarray):
                assert not any(np.shares_memory(got, getattr(st_, g)) for st_ in (own, intr) for g in names), f.name


def test_rows_select_lazily_what_an_eager_copy_selects():
    # Bands[idx] selects each field when it is read; sub / pick select from the original's fields. Every
    # way of reading must give the eager copy's arrays, for index arrays, masks, nested rows, and a field
    # set on a rows object must be the one read after.
    from dataclasses import fields

    rng = np.random.default_rng(3)
    n = 12
    own = own_state(n=n)
    bear = rng.uniform(-0.5, 0.5, n)
    rng_m = rng.uniform(3000, 9000, n)
    intr = intruders([[[r * np.sin(b), r * np.cos(b), 1000.0, 60.0, np.pi + b, 0.0]] for r, b in zip(rng_m, bear)])
    b = compute_bands(own, intr, CFG)
    mask = rng.random(n) < 0.6
    for idx in (np.array([7, 2, 2, 9]), mask, np.flatnonzero(mask), slice(3, 8), [4, 1]):
        sub = b[idx]
        inner = np.arange(n)[idx]
        for ab, ab_sub in zip(b.axes(), sub.axes()):
            j = np.array([1, 0])
            for f in fields(ab):
                want = getattr(ab, f.name)
                if f.name in ("axis", "side") or want is None:
                    assert getattr(ab_sub, f.name) is want or np.array_equal(getattr(ab_sub, f.name), want)
                    continue
                assert np.array_equal(ab_sub.sub(f.name, j), want[inner][j], equal_nan=True), f.name
                if want.ndim == 2:
                    assert np.array_equal(ab_sub.pick(f.name, j, np.array([0, 1])), want[inner][j, [0, 1]],
                                          equal_nan=True)
                nested = ab_sub.rows(j)
                assert np.array_equal(getattr(nested, f.name), want[inner][j], equal_nan=True), f.name
                assert np.array_equal(getattr(ab_sub, f.name), want[inner], equal_nan=True), f.name
    sub = b.trk.rows(np.array([0, 1, 2]))
    sub.t_in = np.full_like(sub.t_in, 123.0)
    assert np.all(sub.sub("t_in", np.array([1])) == 123.0)
    assert np.all(sub.rows(np.array([2])).t_in == 123.0)
