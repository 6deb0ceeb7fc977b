"""Hypothesis properties of the well-clear geometry: invariances and agreement with dense sampling."""

import numpy as np
from hypothesis import given, settings, strategies as st

from daa_sil.geometry import wellclear as wc
from daa_sil.geometry.thresholds import DO365, PAPER

coord = st.floats(-6000, 6000, allow_nan=False)
alt = st.floats(-400, 400, allow_nan=False)
speed = st.floats(-200, 200, allow_nan=False)
vspeed = st.floats(-15, 15, allow_nan=False)
vec_s = st.tuples(coord, coord, alt).map(np.array)
vec_v = st.tuples(speed, speed, vspeed).map(np.array)
angle = st.floats(0, 2 * np.pi, allow_nan=False)
preset = st.sampled_from([DO365, PAPER, DO365.with_(name="buffered", tcoa=20.0),
                          DO365.with_(name="noncoop", dthr=670.56, tthr=0.0)])


def rotz(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


@settings(max_examples=150, deadline=None)
@given(vec_s, vec_v, vec_s, vec_v, vec_s, angle)
def test_translation_and_rotation_invariance(p_o, v_o, p_i, v_i, offset, a):
    s, v = wc.relative(p_o, v_o, p_i, v_i)
    R = rotz(a)
    s2, v2 = wc.relative(R @ (p_o + offset), R @ v_o, R @ (p_i + offset), R @ v_i)
    np.testing.assert_allclose(wc.horizontal_range(s2), wc.horizontal_range(s), rtol=1e-9, atol=1e-6)
    np.testing.assert_allclose(wc.hmd(s2, v2, 180), wc.hmd(s, v, 180), rtol=1e-7, atol=1e-5)
    t_in, t_out = wc.violation_interval(s, v, DO365)
    t_in2, t_out2 = wc.violation_interval(s2, v2, DO365)
    # equal up to rounding: compare finite endpoints with a tolerance, infinities exactly
    for a1, a2 in ((t_in, t_in2), (t_out, t_out2)):
        if np.isfinite(a1) and np.isfinite(a2):
            assert abs(a1 - a2) < 1e-5
        else:
            # a tangent graze may round differently; only allow that when the interval is tiny
            assert a1 == a2 or abs(t_out - t_in) < 1e-3 or abs(t_out2 - t_in2) < 1e-3


@settings(max_examples=150, deadline=None)
@given(vec_s, vec_v, preset)
def test_swap_symmetry(s, v, th):
    a = wc.violation_interval(s, v, th)
    b = wc.violation_interval(-s, -v, th)
    assert a == b
    assert wc.wcv(s, v, th) == wc.wcv(-s, -v, th)
    assert np.array_equal(np.isnan(wc.tau_mod(s, v, th.dthr)), np.isnan(wc.tau_mod(-s, -v, th.dthr)))


@settings(max_examples=60, deadline=None)
@given(vec_s, vec_v, preset)
def test_interval_matches_dense_1ms_sampling(s, v, th):
    T = 60.0
    t = np.arange(0, T + 1e-9, 1e-3)
    ss = s + t[:, None] * v
    inside = wc.wcv(ss, np.broadcast_to(v, ss.shape), th)
    t_in, t_out = wc.violation_interval(s, v, th, 0.0, T)
    tol = 2e-3
    if np.isfinite(t_in):
        assert t_in <= t_out
        core = (t > t_in + tol) & (t < t_out - tol)
        assert inside[core].all()
        outside = (t < t_in - tol) | (t > t_out + tol)
        assert not inside[outside].any()
    else:
        # no interval: at most a grazing contact shorter than the tolerance
        assert inside.sum() <= 2


@settings(max_examples=200, deadline=None)
@given(st.tuples(st.floats(-400, 400), st.floats(-400, 400), st.floats(-80, 80)).map(np.array),
       st.tuples(st.floats(-400, 400), st.floats(-400, 400), st.floats(-80, 80)).map(np.array))
def test_nmac_in_segment_never_missed(s0, s1):
    t = np.linspace(0, 1, 20001)
    path = s0 + t[:, None] * (s1 - s0)
    dense = wc.nmac(path, DO365)
    _, nm = wc.segment_events(s0, s1, 1.0, DO365)
    if dense.any():
        assert nm
    if nm and not dense.any():
        # only a contact thinner than the sampling step may be missed by the samples
        lo, hi = wc.nmac_interval(s0, s1 - s0, DO365, 1.0)
        assert hi - lo < 1e-3
