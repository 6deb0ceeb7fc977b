"""Aircraft kinematics (exact turns, limits) and frame conversions against hand-worked values."""

import math

import numpy as np
import pytest

from daa_sil.geometry import frames
from daa_sil.geometry import kinematics
from daa_sil.geometry.kinematics import (AircraftState, Command, Performance, advance, advance_reference, fly_command,
                                         fly_command_reference)
from daa_sil.geometry.units import DEG, FPM, G0

PERF = Performance()


def state(x=0.0, y=0.0, z=0.0, gs=55.0, trk=0.0, vs=0.0):
    return AircraftState(x, y, z, gs, trk, vs)


def test_constant_turn_is_exact_for_any_step():
    w = 3 * DEG
    R = 55.0 / w
    one = advance(state(), turn_rate=w, dt=60.0)  # 180 deg right turn from north
    assert one.x == pytest.approx(2 * R, abs=1e-9)
    assert one.y == pytest.approx(0.0, abs=1e-9)
    assert one.trk == pytest.approx(math.pi)
    s = state()
    for _ in range(60):
        s = advance(s, turn_rate=w, dt=1.0)
    assert s.x == pytest.approx(one.x, abs=1e-8) and s.y == pytest.approx(one.y, abs=1e-8)
    # full circle returns to the start
    full = advance(state(), turn_rate=w, dt=120.0)
    assert full.x == pytest.approx(0, abs=1e-8) and full.y == pytest.approx(0, abs=1e-8)


def test_turn_rate_is_limited():
    s = advance(state(), turn_rate=10 * DEG, dt=1.0)
    assert s.trk == pytest.approx(3 * DEG)


def test_accelerating_straight_and_saturation():
    s = advance(state(gs=55.0), accel=2.0, dt=5.0)
    assert s.gs == pytest.approx(65.0)
    assert s.y == pytest.approx(55 * 5 + 0.5 * 2 * 25)
    # saturate at max_gs inside the step
    p = Performance(max_gs=60.0)
    s = advance(state(gs=55.0), accel=2.0, dt=5.0, perf=p)  # reaches 60 after 2.5 s
    assert s.gs == pytest.approx(60.0)
    assert s.y == pytest.approx(55 * 2.5 + 0.5 * 2 * 2.5 ** 2 + 60 * 2.5)


def test_accelerating_turn_matches_fine_integration():
    s0 = state(gs=50.0, trk=0.3)
    exact = advance(s0, turn_rate=2 * DEG, accel=1.5, dt=10.0)
    n = 200000
    t = (np.arange(n) + 0.5) * (10.0 / n)
    v = 50 + 1.5 * t
    psi = 0.3 + 2 * DEG * t
    assert exact.x == pytest.approx(np.sum(v * np.sin(psi)) * 10.0 / n, abs=1e-5)
    assert exact.y == pytest.approx(np.sum(v * np.cos(psi)) * 10.0 / n, abs=1e-5)


def test_vertical_accel_to_limit():
    s = advance(state(vs=0.0), vertical_accel=0.25 * G0, dt=1.0)
    assert s.vs == pytest.approx(0.25 * G0)
    assert s.z == pytest.approx(0.5 * 0.25 * G0)


def test_fly_command_turns_short_way_then_straight():
    # 30 deg left from north at 3 deg/s: 10 s turning then straight
    cmd = Command(trk=-30 * DEG)
    s = state()
    for _ in range(15):
        s = fly_command(s, cmd, 1.0)
    assert s.trk == pytest.approx(frames.wrap_2pi(-30 * DEG))
    w = 3 * DEG
    R = 55 / w
    # after the 10 s arc: x = -R(1 - cos 30deg), y = R sin 30deg; then 5 s straight on 330 deg
    x_exp = -R * (1 - math.cos(30 * DEG)) + 5 * 55 * math.sin(-30 * DEG)
    y_exp = R * math.sin(30 * DEG) + 5 * 55 * math.cos(-30 * DEG)
    assert s.x == pytest.approx(x_exp, abs=1e-6) and s.y == pytest.approx(y_exp, abs=1e-6)
    # a single 15 s step gives the same answer (exact piecewise)
    one = fly_command(state(), cmd, 15.0)
    assert one.x == pytest.approx(x_exp, abs=1e-6) and one.y == pytest.approx(y_exp, abs=1e-6)


def test_fly_command_vertical_and_nan_keeps():
    cmd = Command(vs=1500 * FPM)  # trk, gs nan -> keep
    s = fly_command(state(trk=1.0), cmd, 10.0)
    assert s.trk == pytest.approx(1.0) and s.gs == pytest.approx(55.0)
    assert s.vs == pytest.approx(1500 * FPM)
    t1 = 1500 * FPM / (0.25 * G0)
    assert s.z == pytest.approx(0.5 * 1500 * FPM * t1 + 1500 * FPM * (10 - t1))
    # limits: a 20000 fpm request is clipped to 6000 fpm
    s = fly_command(state(), Command(vs=20000 * FPM), 30.0)
    assert s.vs == pytest.approx(6000 * FPM)


def test_batched_equals_elementwise():
    rng = np.random.default_rng(1)
    n = 64
    st = AircraftState(rng.uniform(-1e3, 1e3, n), rng.uniform(-1e3, 1e3, n), rng.uniform(0, 1e3, n),
                       rng.uniform(30, 200, n), rng.uniform(0, 2 * np.pi, n), rng.uniform(-5, 5, n))
    cmd = Command(rng.uniform(0, 2 * np.pi, n), rng.uniform(-10, 10, n), rng.uniform(30, 200, n))
    batch = fly_command(st, cmd, 1.0)
    for i in range(0, n, 7):
        single = fly_command(st[i], cmd[i], 1.0)
        np.testing.assert_allclose(single.as_array(), batch[i].as_array(), rtol=0, atol=1e-9)


# --- frames ---------------------------------------------------------------------------------
def test_paper_frame_head_on_overtaking_and_left():
    own_p, own_v = np.zeros(3), frames.velocity_from_track(55, 0.0)  # north
    hd = frames.to_paper_state(own_p, own_v, [0, 3000, 100], frames.velocity_from_track(150, math.pi, -2))
    assert hd[frames.DX] == pytest.approx(3000) and hd[frames.DY] == pytest.approx(0, abs=1e-9)
    assert hd[frames.THETA] == pytest.approx(math.pi)
    assert hd[frames.DH] == pytest.approx(100) and hd[frames.VH] == pytest.approx(-2)
    ov = frames.to_paper_state(own_p, own_v, [0, -2000, 0], frames.velocity_from_track(100, 0.0))
    assert ov[frames.DX] == pytest.approx(-2000) and ov[frames.THETA] == pytest.approx(0, abs=1e-12)
    left = frames.to_paper_state(own_p, own_v, [-1000, 0, 0], frames.velocity_from_track(100, math.pi / 2))
    assert left[frames.DY] == pytest.approx(1000)  # west of a north-bound ownship is its left
    # intruder flying east while ownship flies north: heading is 90 deg to the right = -90 CCW
    assert left[frames.THETA] == pytest.approx(1.5 * math.pi)


def test_paper_frame_rotates_with_ownship_and_round_trips():
    rng = np.random.default_rng(2)
    paper = np.column_stack([rng.uniform(-1500, 1500, 50), rng.uniform(-1500, 1500, 50),
                             rng.uniform(-200, 200, 50), rng.uniform(70, 300, 50),
                             rng.uniform(-5, 5, 50), rng.uniform(0, 2 * np.pi, 50)])
    for trk in (0.0, 1.0, 4.0):
        op, ov, ip, iv = frames.from_paper_state(paper, 55.0, trk)
        back = frames.to_paper_state(op, ov, ip, iv)
        np.testing.assert_allclose(back[:, :5], paper[:, :5], atol=1e-9)
        np.testing.assert_allclose(np.cos(back[:, 5]), np.cos(paper[:, 5]), atol=1e-9)
        np.testing.assert_allclose(np.sin(back[:, 5]), np.sin(paper[:, 5]), atol=1e-9)


def test_geodetic_round_trip_and_scale():
    x, y, z = np.array([0.0, 1000.0, -5000.0]), np.array([0.0, 2000.0, 7000.0]), np.array([0, 50, 500.0])
    lat, lon, alt = frames.enu_to_geodetic(x, y, z, 36.1, -97.1, 300.0)
    xb, yb, zb = frames.geodetic_to_enu(lat, lon, alt, 36.1, -97.1, 300.0)
    np.testing.assert_allclose([xb, yb, zb], [x, y, z], atol=1e-6)
    # 1 arc-minute of latitude is about 1852 m (1849-1853 m between equator and pole)
    _, yy, _ = frames.geodetic_to_enu(36.1 + 1 / 60, -97.1, 0, 36.1, -97.1)
    assert 1845 < yy < 1855


def test_advance_skips_its_empty_second_segment_only_where_that_changes_no_bit():
    """With no acceleration, advance's second (speed-limit) segment has length 0 and is skipped when its
    arithmetic would change nothing. Bit for bit against both segments flown, on states built to break
    a careless skip: -0.0 positions, tracks and speeds, a zero speed while turning (the arc is then a
    signed zero of either sign), nan and inf."""
    from daa_sil.geometry.frames import wrap_2pi
    from daa_sil.geometry.kinematics import horizontal_segment_reference as horizontal_segment

    rng = np.random.default_rng(3)
    n = 4000
    pick = lambda *vals: rng.choice(np.array(vals, float), n)  # noqa: E731
    x = np.where(rng.random(n) < 0.5, pick(-0.0, 0.0, np.nan, np.inf), rng.normal(0, 1e4, n))
    y = np.where(rng.random(n) < 0.5, pick(-0.0, 0.0, -np.inf), rng.normal(0, 1e4, n))
    gs = np.where(rng.random(n) < 0.5, pick(-0.0, 0.0, np.nan, np.inf), rng.uniform(0, 300, n))
    trk = np.where(rng.random(n) < 0.5, pick(-0.0, 0.0, np.pi, 4.0, np.nan), rng.uniform(0, 2 * np.pi, n))
    w = np.where(rng.random(n) < 0.5, pick(0.0, -0.0, 0.05, -0.05, 1e-8), rng.uniform(-0.1, 0.1, n))
    perf = Performance(max_turn_rate=0.2, horizontal_accel=3.0, vertical_accel=2.0, max_vs=30.0, min_gs=0.0,
                       max_gs=400.0)
    with np.errstate(all="ignore"):  # the nan and inf rows make numpy warn, in both computations alike
        finite = np.flatnonzero(np.isfinite(x + y + gs + trk))
        # the batch, its finite rows (a batch the skip may take), and single rows (N = 1)
        for rows in [np.arange(n), finite] + [np.array([i]) for i in range(400)]:
            s = AircraftState(x[rows], y[rows], np.zeros(rows.size), gs[rows], trk[rows], np.zeros(rows.size))
            got = advance_reference(s, w[rows], 0.0, 0.0, 1.0, perf)  # the numpy skip (the kernel: below)
            x1, y1, gs1, trk1 = horizontal_segment(s.x, s.y, s.gs, s.trk, w[rows], np.zeros(rows.size), np.ones(rows.size))
            want = horizontal_segment(x1, y1, gs1, trk1, w[rows], 0.0, np.zeros(rows.size))
            for a, b in zip((got.x, got.y, got.gs, got.trk), want[:3] + (wrap_2pi(want[3]),)):
                assert a.tobytes() == b.tobytes()


def _motion_inputs(rng, n: int) -> tuple:
    """States, controls and commands for :func:`test_compiled_motion_is_the_numpy_motion`: realistic values, a
    quarter of them replaced by edge cases (signed zeros, nan, +-inf, huge, turn rates at the straight-line
    threshold, tracks at 0 / pi / 2 pi, speeds and vertical speeds at and beyond the limits)."""
    special = np.array([0.0, -0.0, np.nan, np.inf, -np.inf, 1e300, -1e300, 1e-300, 1e-6, -1e-6, 5e-7, 1e-7,
                        3 * DEG, -3 * DEG, 0.05, -0.05, np.pi, 2 * np.pi, -np.pi, 2.0, -2.0, 5.0, 30.0, -30.0,
                        200.0, 400.0, 1e4])

    def edge(a):
        pick = rng.random(n) < 0.25
        a[pick] = rng.choice(special, int(pick.sum()))
        return a

    state = AircraftState(edge(rng.normal(0, 8000, n)), edge(rng.normal(0, 8000, n)), edge(rng.normal(1000, 300, n)),
                          edge(rng.uniform(0, 150, n)), edge(rng.uniform(0, 2 * np.pi, n)), edge(rng.normal(0, 5, n)))
    controls = (edge(rng.normal(0, 0.05, n)), edge(rng.normal(0, 2, n)), edge(rng.normal(0, 2, n)))
    cmd = Command(edge(np.where(rng.random(n) < 0.3, np.nan, rng.uniform(0, 2 * np.pi, n))),
                  edge(np.where(rng.random(n) < 0.3, np.nan, rng.normal(0, 10, n))),
                  edge(np.where(rng.random(n) < 0.3, np.nan, rng.uniform(0, 250, n))))
    return state, controls, cmd


def _same_motion(got: AircraftState, want: AircraftState) -> None:
    """Every component bit for bit (a zero's sign too); nan where the reference has nan (a nan's sign and
    payload are not results: the compiler may take the other operand of a commutative operation)."""
    for name in ("x", "y", "z", "gs", "trk", "vs"):
        a, b = getattr(got, name), getattr(want, name)
        assert a.shape == b.shape
        nan = np.isnan(a) & np.isnan(b)
        bad = (a.view(np.int64) != b.view(np.int64)) & ~nan
        assert not bad.any(), f"{name}: {int(bad.sum())} differ, first {a[bad][:3]} vs {b[bad][:3]}"


def test_compiled_motion_is_the_numpy_motion(monkeypatch):
    """advance, fly_command and horizontal_segment as compiled kernels (a process that loaded the DAA's
    kernels) give the numpy references' numbers: batches with edge cases, single rows (N = 1), (N, M) intruder arrays, scalar
    controls, steps of 0 / 1e-9 / 0.1 / 1 / 2 s, and performances with no turn or no acceleration."""
    from daa_sil.daa import kernels

    kernels.get()
    rng = np.random.default_rng(21)
    ref_advance, ref_fly = advance_reference, fly_command_reference

    def not_here(*_a, **_k):
        raise AssertionError("the numpy reference ran: the compiled path was not taken")

    perfs = [Performance(), Performance(max_turn_rate=0.0, horizontal_accel=0.0, vertical_accel=0.0),
             Performance(max_turn_rate=0.2, horizontal_accel=3.0, vertical_accel=2.0, max_vs=30.0, min_gs=0.0,
                         max_gs=400.0)]
    cases = 0
    with np.errstate(all="ignore"):  # the nan / inf rows make the numpy references warn
        for trial in range(240):
            n = [1, 2, 9, 500][trial % 4]
            state, (w, a, av), cmd = _motion_inputs(rng, n)
            dt = [1.0, 0.1, 2.0, 0.0, 1e-9][trial % 5]
            perf = perfs[trial % 3]
            if trial % 6 == 5:  # scalar controls and a scalar command field, broadcast
                w, av = float(w[0]), float(av[0])
                cmd = Command(cmd.trk, np.array(float(cmd.vs[0])), cmd.gs)
            if trial % 3 == 1:  # no acceleration (the usual intruder): the speed-limit segment has length 0
                a = 0.0
            want_a = ref_advance(state, w, a, av, dt, perf)
            want_f = ref_fly(state, cmd, dt, perf)
            with monkeypatch.context() as m:
                m.setattr(kinematics, "advance_reference", not_here)
                m.setattr(kinematics, "fly_command_reference", not_here)
                got_a = kinematics.advance(state, w, a, av, dt, perf)
                got_f = kinematics.fly_command(state, cmd, dt, perf)
            _same_motion(got_a, want_a)
            _same_motion(got_f, want_f)
            # the arc alone (SM's phase starts): per-element turn rates, accelerations and durations
            t_seg = np.abs(rng.normal(0, 20, n)) if trial % 2 else np.where(rng.random(n) < 0.5, 0.0, dt)
            args = (state.x, state.y, state.gs, state.trk, w, a, t_seg)
            want_s = kinematics.horizontal_segment_reference(*args)
            with monkeypatch.context() as m:
                m.setattr(kinematics, "horizontal_segment_reference", not_here)
                got_s = kinematics.horizontal_segment(*args)
            _same_motion(AircraftState.adopt(*got_s[:2], state.z, *got_s[2:], state.vs),
                         AircraftState.adopt(*want_s[:2], state.z, *want_s[2:], state.vs))
            cases += 3
        # intruders (N, M)
        state, (w, a, av), _ = _motion_inputs(rng, 600)
        grid = AircraftState(*(getattr(state, f).reshape(200, 3) for f in ("x", "y", "z", "gs", "trk", "vs")))
        _same_motion(advance(grid, w.reshape(200, 3), a.reshape(200, 3), 0.0, 1.0), ref_advance(grid, w.reshape(200, 3),
                                                                                               a.reshape(200, 3), 0.0, 1.0))
    assert cases == 720
