"""Penetration integral on the continuous LoWC segment (issue 14 item 5): hand-worked tents, a dense
independent quadrature, the paper's constants, and a LoWC strictly between two samples."""

import numpy as np
import pytest

from daa_sil.geometry import wellclear as wc
from daa_sil.geometry import penetration as pen
from daa_sil.agent.memory import PilotInput
from daa_sil.config.groups import policy_for_group
from daa_sil.daa import DaaConfig
from daa_sil.daa.alerting import relative_state
from daa_sil.geometry.kinematics import AircraftState, Performance
from daa_sil.onboard import OnboardCore
from daa_sil.geometry.thresholds import PAPER
from daa_sil.geometry.units import FT

PRESET = pen.pi_constants(PAPER)


def _segment_pi(s0, s1, constants=PRESET, th=PAPER, dt=1.0):
    s0, s1 = np.asarray(s0, float), np.asarray(s1, float)
    v = (s1 - s0) / dt
    t_in, t_out = wc.violation_interval(s0, v, th, 0.0, dt)
    return pen.segment_penetration(s0, v, t_in, t_out, constants), t_in, t_out


def test_constants_are_the_papers_and_the_presets():
    assert pen.PAPER_PI_CONSTANTS == pytest.approx((1219.2, 137.16, 35.0))
    assert PRESET == (1220.0, 122.0, 35.0)
    # a point straight above at 61 m inside DMOD: 1 - 61/122 = 0.5 (preset), 1 - 61/137.16 (paper Eq.)
    s, v = np.array([0.0, 0.0, 61.0]), np.array([0.0, 0.0, 0.0])
    assert pen.penetration_depth(s, v, *PRESET) == pytest.approx(0.5)
    assert pen.penetration_depth(s, v, *pen.PAPER_PI_CONSTANTS) == pytest.approx(1 - 61 / 137.16)


def test_vertical_pass_between_samples_is_a_tent():
    """Overhead (r = 0) at +150 m, then -150 m one second later: both samples are outside the
    122 m slab, so the sampled PI is 0, but the segment is in LoWC for 244/300 s with the integrand
    1 - |z|/122 rising to 1 and back: the tent's area is 244/600 s."""
    s0, s1 = np.array([0.0, 0.0, 150.0]), np.array([0.0, 0.0, -150.0])
    v = s1 - s0
    assert pen.penetration_rate(s0, v, PAPER) == 0 and pen.penetration_rate(s1, v, PAPER) == 0
    pi, t_in, t_out = _segment_pi(s0, s1)
    assert t_in == pytest.approx(28 / 300) and t_out == pytest.approx(272 / 300)
    assert pi == pytest.approx(244 / 600, rel=1e-9)  # midpoint rule is exact on this tent
    # the paper's constants: 1 - |z|/137.16 over the same interval |z| <= 122 m
    half = 122 / 300
    expect = 2 * (half - 300 * half ** 2 / (2 * 137.16))
    pi_p, _, _ = _segment_pi(s0, s1, pen.PAPER_PI_CONSTANTS)
    assert pi_p == pytest.approx(expect, rel=1e-9)
    assert pi_p > pi  # a larger vertical scale means a deeper penetration


def _dense_reference(s0, v, dt=1.0, th=PAPER, nodes=200_001):
    """Trapezoid over [0, dt] of the *instantaneous* masked integrand (penetration_rate: WCV test
    per node, no violation interval involved)."""
    t = np.linspace(0.0, dt, nodes)
    pts = s0[..., None, :] + t[:, None] * v[..., None, :]
    f = pen.penetration_rate(pts, np.broadcast_to(v[..., None, :], pts.shape), th)
    return np.trapezoid(f, t, axis=-1)


def test_random_segments_agree_with_dense_quadrature():
    """Population: 4000 random 1 s segments of relative motion within +-2.5 km / +-250 m at up to
    300 m/s; tested on every one of them (most are outside LoWC, where both must be 0)."""
    rng = np.random.default_rng(11)
    n = 4000
    s0 = rng.uniform(-1, 1, (n, 3)) * [2500, 2500, 250]
    v = rng.uniform(-1, 1, (n, 3)) * [300, 300, 150]
    t_in, t_out = wc.violation_interval(s0, v, PAPER, 0.0, 1.0)
    pi = pen.segment_penetration(s0, v, t_in, t_out, PRESET)
    inside = np.isfinite(t_in)
    assert inside.sum() > 200 and (pi > 0.05).sum() > 100  # a non-trivial population
    ref = np.zeros(n)
    for i in np.flatnonzero(inside):
        ref[i] = _dense_reference(s0[i], v[i], nodes=20_001)
    assert np.all(pi[~inside] == 0)
    assert np.abs(pi - ref).max() < 2e-3
    # bounded by the time in LoWC on the segment
    dur = np.where(inside, t_out - t_in, 0.0)
    assert np.all(pi <= dur + 1e-12)
    # every segment with a LoWC of positive duration has a positive PI
    assert np.all(pi[dur > 1e-9] > 0)


def test_lowc_strictly_between_samples_gets_a_positive_pi_in_the_core():
    """The core's PI comes from the segment: an intruder straight overhead descending through the
    slab within one step (sampled rate 0 at both ends) must give PI > 0 and equal the tent area of
    the realised chord."""
    own = AircraftState([0.0], [0.0], [1000.0], [55.0], [0.0], [0.0])
    intr = AircraftState([[0.0]], [[0.0]], [[1150.0]], [[55.0]], [[0.0]], [[-300.0]])
    zero = np.zeros((1, 1))
    core = OnboardCore(own, intr, lambda t: (zero, zero, zero), policy_for_group("B-1"),
                       DaaConfig(thresholds="paper"), intruder_perf=Performance(max_vs=400.0))
    out = core.step(0.0, PilotInput.nothing(1, 0.0))
    s0 = out.own.position()[:, None] - out.intruders.position()
    s1 = core.own.position()[:, None] - core.intruders.position()
    v = s1 - s0
    assert pen.penetration_rate(s0, v, PAPER)[0, 0] == 0 and pen.penetration_rate(s1, v, PAPER)[0, 0] == 0
    # what the old sample-based PI summed: the penetration rate of the sampled state and velocity
    assert pen.penetration_rate(*relative_state(out.own, out.intruders), PAPER).max() == 0
    assert out.lowc[0] and out.pi_s[0] > 0.3 and out.pi_paper_s[0] > out.pi_s[0]
    z0, z1 = -s0[0, 0, 2], -s1[0, 0, 2]  # intruder above the ownship: +150 then about -150
    slope = abs(z1 - z0)
    half = 122.0 / slope
    assert out.pi_s[0] == pytest.approx(half, rel=1e-2)  # tent of half-base 122/|dz|, height 1
    assert out.lowc_time_s[0] == pytest.approx(2 * half, rel=1e-6)
    assert out.pi_paper_s[0] == pytest.approx(2 * (half - slope * half ** 2 / (2 * 450 * FT)), rel=1e-2)
