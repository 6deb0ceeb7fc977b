"""Well-clear geometry against hand-worked encounters (numbers derived in the comments)."""

import math

import numpy as np
import pytest

from daa_sil.geometry import penetration as pen
from daa_sil.geometry import wellclear as wc
from daa_sil.geometry.thresholds import DO365, PAPER, get_thresholds
from daa_sil.errors import UsageError

D = 4000 * 0.3048  # 1219.2 m
H = 450 * 0.3048  # 137.16 m


def rel(own, intr):
    own, intr = np.asarray(own, float), np.asarray(intr, float)
    return wc.relative(own[:3], own[3:], intr[:3], intr[3:])


def test_presets_values():
    assert DO365.dthr == pytest.approx(1219.2)
    assert DO365.zthr == pytest.approx(137.16)
    assert DO365.nmac_h == pytest.approx(152.4) and DO365.nmac_v == pytest.approx(30.48)
    assert PAPER.dthr == 1220.0 and PAPER.zthr == 122.0
    assert PAPER.nmac_v == pytest.approx(120 * 0.3048)
    with pytest.raises(UsageError, match="allowed: do365, paper"):
        get_thresholds("nope")


def test_head_on_co_altitude():
    # own north 55 m/s, intruder 6 km north heading south at 100 m/s: closure 155 m/s
    s, v = rel([0, 0, 1000, 0, 55, 0], [0, 6000, 1000, 0, -100, 0])
    assert wc.horizontal_range(s) == pytest.approx(6000)
    assert wc.range_rate(s, v) == pytest.approx(-155)
    assert wc.t_cpa(s, v) == pytest.approx(6000 / 155)
    assert wc.hmd(s, v) == pytest.approx(0, abs=1e-9)
    # tau_mod = (D^2 - r^2)/(r * rdot)
    assert wc.tau_mod(s, v, D) == pytest.approx((D * D - 6000 ** 2) / (6000 * -155))
    # entry: r^2 - 35*155*r - D^2 = 0 ; exit: r = -D (after passing), r = 6000 - 155 t
    r_in = (35 * 155 + math.sqrt((35 * 155) ** 2 + 4 * D * D)) / 2
    t_in, t_out = wc.violation_interval(s, v, DO365, 0, 180)
    assert t_in == pytest.approx((6000 - r_in) / 155, abs=1e-9)
    assert t_out == pytest.approx((6000 + D) / 155, abs=1e-9)
    assert not wc.wcv(s, v)
    assert wc.wcv(s + 3.0 * v, v)  # t = 3 s is inside [2.02, 46.6]


def test_crossing_from_right():
    # own north 50 m/s at origin; intruder at (4000, 4000) heading west 50 m/s -> collision at t=80
    s, v = rel([0, 0, 0, 0, 50, 0], [4000, 4000, 0, -50, 0, 0])
    assert wc.t_cpa(s, v) == pytest.approx(80)
    assert wc.d_cpa(s, v) == pytest.approx(0, abs=1e-9)
    # with u = 4000 - 50 t: r = sqrt(2) u, s.v = -100 u ; entry: 2u^2 - 3500 u - D^2 = 0
    u = (3500 + math.sqrt(3500 ** 2 + 8 * D * D)) / 4
    t_in, t_out = wc.violation_interval(s, v, DO365, 0, 180)
    assert t_in == pytest.approx((4000 - u) / 50, abs=1e-9)
    assert t_out == pytest.approx((4000 + D / math.sqrt(2)) / 50, abs=1e-9)


def test_overtaking():
    # intruder 3 km behind at 100 m/s, own 50 m/s, both north: closure 50 m/s
    s, v = rel([0, 0, 0, 0, 50, 0], [0, -3000, 0, 0, 100, 0])
    assert wc.tau_mod(s, v, D) == pytest.approx((3000 ** 2 - D * D) / (3000 * 50))
    r_in = (35 * 50 + math.sqrt((35 * 50) ** 2 + 4 * D * D)) / 2
    t_in, t_out = wc.violation_interval(s, v, DO365, 0, 180)
    assert t_in == pytest.approx((3000 - r_in) / 50, abs=1e-9)
    assert t_out == pytest.approx((3000 + D) / 50, abs=1e-9)


def test_vertical_conflict_only():
    # intruder directly overhead 300 m, descending 10 m/s: horizontal always violated, vertical
    # window |-300 + 10 t| <= 137.16
    s, v = rel([0, 0, 0, 0, 0, 0], [0, 0, 300, 0, 0, -10])
    t_in, t_out = wc.violation_interval(s, v, DO365, 0, 180)
    assert t_in == pytest.approx((300 - H) / 10)
    assert t_out == pytest.approx((300 + H) / 10)
    assert np.isnan(wc.t_coa(np.array([0, 0, 300.0]), np.array([0, 0, 10.0])))  # diverging
    assert wc.t_coa(s, v) == pytest.approx(30)


def test_level_but_vertically_separated_never_violates():
    s, v = rel([0, 0, 0, 0, 55, 0], [0, 5000, 200, 0, -100, 0])  # 200 m > ZTHR, level
    t_in, t_out = wc.violation_interval(s, v, DO365, 0, 180)
    assert np.isinf(t_in) and t_in > 0 and np.isinf(t_out) and t_out < 0
    # but with the paper preset (ZTHR 122 m) still none; with a 130 m offset do365 violates, paper not
    s2, v2 = rel([0, 0, 0, 0, 55, 0], [0, 5000, 130, 0, -100, 0])
    assert np.isfinite(wc.time_to_violation(s2, v2, DO365))
    assert np.isinf(wc.time_to_violation(s2, v2, PAPER))


def test_inside_dmod_and_diverging():
    # 1000 m apart (inside DMOD), co-altitude, moving apart at 10 m/s: violated now until r = D
    s, v = rel([0, 0, 0, 0, 0, 0], [0, 1000, 0, 0, 10, 0])
    assert wc.wcv(s, v)
    assert wc.tau_mod(s, v, D) == 0.0
    t_in, t_out = wc.violation_interval(s, v, DO365, 0, 180)
    assert t_in == 0.0
    assert t_out == pytest.approx((D - 1000) / 10)


def test_diverging_outside_is_clear_and_tau_undefined():
    s, v = rel([0, 0, 0, 0, 55, 0], [0, -5000, 0, 0, -100, 0])
    assert np.isnan(wc.tau_mod(s, v, D))
    assert wc.hmd(s, v) == pytest.approx(5000)  # diverging: HMD = current range
    assert not wc.wcv(s, v)
    assert np.isinf(wc.time_to_violation(s, v))


def test_hmd_lookahead_clips_cpa():
    # crossing with CPA at 40 s: a 10 s look-ahead gives the range at t = 10
    s, v = rel([0, 0, 0, 0, 50, 0], [2000, 2000, 0, -50, 0, 0])
    assert wc.hmd(s, v, 10.0) == pytest.approx(math.sqrt(2) * (2000 - 500))


def test_nmac_between_samples():
    # samples 200 m either side of the intruder, passing straight through it in between
    s0, s1 = np.array([-200.0, 0, 0]), np.array([200.0, 0, 0])
    assert not wc.nmac(s0) and not wc.nmac(s1)
    lowc, nm = wc.segment_events(s0, s1, 1.0)
    assert nm and lowc
    # a 160 m miss distance (> 152.4 m) is not an NMAC
    _, nm = wc.segment_events(np.array([-200.0, 160, 0]), np.array([200.0, 160, 0]), 1.0)
    assert not nm
    # horizontal and vertical conditions both occur in the segment, but at different times:
    # |z| <= 30.48 only for t <= 0.0762 s, horizontal <= 152.4 m only for t >= 0.119 s
    _, nm = wc.segment_events(np.array([-200.0, 0, 0]), np.array([200.0, 0, 400.0]), 1.0)
    assert not nm
    # shift the vertical crossing to overlap the horizontal window -> NMAC
    _, nm = wc.segment_events(np.array([-200.0, 0, -200.0]), np.array([200.0, 0, 200.0]), 1.0)
    assert nm


def test_lowc_only_inside_segment():
    # DO-365B non-cooperative volume (2200 ft, TTHR = 0): the relative track clips the circle
    # only between the samples (ends at 771.8 m, chord minimum 660 m < 670.56 m)
    nc = DO365.with_(name="noncoop", dthr=2200 * 0.3048, tthr=0.0)
    s0, s1 = np.array([-400.0, 660, 0]), np.array([400.0, 660, 0])
    assert not wc.wcv(s0, s1 - s0, nc) and not wc.wcv(s1, s1 - s0, nc)
    lowc, nm = wc.segment_events(s0, s1, 1.0, nc)
    assert lowc and not nm
    # vertical: overhead, passing through the +-ZTHR slab between samples
    s0, s1 = np.array([0.0, 0, -150]), np.array([0.0, 0, 150])
    assert not wc.wcv(s0, s1 - s0) and not wc.wcv(s1, s1 - s0)
    assert wc.segment_events(s0, s1, 1.0)[0]


def test_penetration_integral_bounds_and_zero_outside():
    s, v = rel([0, 0, 0, 0, 55, 0], [0, 6000, 0, 0, -95, 0])  # closure 150 m/s: collision at t = 40
    t = np.arange(0, 80.0)
    ss = s + t[:, None] * v
    rate = pen.penetration_rate(ss, np.broadcast_to(v, ss.shape))
    inside = wc.wcv(ss, np.broadcast_to(v, ss.shape))
    assert np.all(rate[~inside] == 0)
    assert np.all((rate >= 0) & (rate <= 1))
    pi = pen.penetration_integral(ss, np.broadcast_to(v, ss.shape), 1.0)
    assert 0 < pi <= inside.sum()
    # at the collision point (HMD 0, dz 0, tau 0) the integrand is exactly 1
    k = int(np.argmin(wc.horizontal_range(ss)))
    assert wc.horizontal_range(ss[k]) < 1e-9
    assert rate[k] == pytest.approx(1.0)


def test_vectorised_matches_scalar_calls():
    rng = np.random.default_rng(3)
    s = rng.uniform(-8000, 8000, (500, 3)) * [1, 1, 0.05]
    v = rng.uniform(-250, 250, (500, 3)) * [1, 1, 0.05]
    t_in, t_out = wc.violation_interval(s, v, DO365, 0, 180)
    for i in range(0, 500, 25):
        a, b = wc.violation_interval(s[i], v[i], DO365, 0, 180)
        assert a == t_in[i] and b == t_out[i]
