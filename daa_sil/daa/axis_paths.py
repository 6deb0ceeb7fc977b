"""The maneuver paths of one band axis (track, vertical speed, ground speed): candidates anchored at
the current value, knot times at the performance limits, and the true ownship state along each
path."""

from __future__ import annotations

import functools

import numpy as np

from daa_sil.daa.config import (
    AXIS_HORIZONTAL,
    AXIS_SPEED,
    AXIS_VERTICAL,
    DaaConfig,
)
from daa_sil.daa.trajectory import ManeuverPaths
from daa_sil.geometry.kinematics import TWO_PI, AircraftState

#: False: the knot states of :func:`maneuver_paths` from the numpy closed forms (:func:`_turn_knots`,
#: :func:`_axis_state_soa`), the oracle the tests compare the compiled ``kernels.motion.axis_knots_into`` with
COMPILED = True


def speed_limits(vertical: bool, cfg: DaaConfig, sgn) -> tuple:
    """``(acceleration m/s^2, limit m/s per side)`` of the vertical-speed or ground-speed axis: the
    side ``sgn < 0`` slows/descends to the lower limit, ``sgn > 0`` to the upper one (DAIDALUS grid:
    no vertical limits, ground speed down to 0)."""
    acc = cfg.vertical_accel if vertical else cfg.horizontal_accel
    if cfg.daidalus_grid:
        return acc, np.where(sgn < 0, -np.inf if vertical else 0.0, np.inf)
    return acc, np.where(sgn < 0, -cfg.max_vs if vertical else cfg.min_gs, cfg.max_vs if vertical else cfg.max_gs)


@functools.lru_cache(maxsize=64)
def _track_counts(trk_range: float, trk_step: float, daidalus_grid: bool) -> tuple[int, int]:
    """:func:`candidate_counts` of the track axis (the configuration's alone; made once per configuration,
    not per step: ``np.isclose`` costs ~20 us)."""
    j_lo = int(round(trk_range / trk_step))
    full_circle = np.isclose(trk_range, np.pi)
    return j_lo, (j_lo - 1 if full_circle and not daidalus_grid else j_lo)


def candidate_counts(own: AircraftState, axis: int, cfg: DaaConfig) -> tuple[int, int]:
    """Number of candidates on the low and high side of ``axis`` for this batch of ownships (>= 0 each): the
    most any of them has (:func:`row_counts`), the columns of the batch's bands."""
    if axis == AXIS_HORIZONTAL:
        return _track_counts(float(cfg.trk_range), float(cfg.trk_step), bool(cfg.daidalus_grid))
    cur, lo, hi, step = ((own.vs, -cfg.max_vs, cfg.max_vs, cfg.vs_step) if axis == AXIS_VERTICAL
                         else (own.gs, cfg.min_gs, cfg.max_gs, cfg.gs_step))
    j_lo = int(np.ceil(np.max(cur - lo, initial=0.0) / step - 1e-9))
    j_hi = int(np.ceil(np.max(hi - cur, initial=0.0) / step - 1e-9))
    return max(j_lo, 0), max(j_hi, 0)


def row_counts(own: AircraftState, axis: int, cfg: DaaConfig) -> tuple[np.ndarray, np.ndarray]:
    """Each ownship's own number of candidates on the low and high side of ``axis``, ``(N,)`` int64 each: the
    counts :func:`candidate_counts` gives for that ownship alone (a speed axis's reach its limits from the
    current value; a track axis's are the configuration's)."""
    n = own.shape[0]
    if axis == AXIS_HORIZONTAL:
        j_lo, j_hi = _track_counts(float(cfg.trk_range), float(cfg.trk_step), bool(cfg.daidalus_grid))
        return np.full(n, j_lo, np.int64), np.full(n, j_hi, np.int64)
    cur, lo, hi, step = ((own.vs, -cfg.max_vs, cfg.max_vs, cfg.vs_step) if axis == AXIS_VERTICAL
                         else (own.gs, cfg.min_gs, cfg.max_gs, cfg.gs_step))
    cur = np.asarray(cur, float)

    def side(gap):  # int(np.ceil(np.max(gap, initial=0.0) / step - 1e-9)) of one ownship, then max(., 0)
        c = np.ceil(np.maximum(gap, 0.0) / step - 1e-9)  # (nan and inf raise no floating-point error here)
        return np.where((c > 0) & (c < 2 ** 62), c, 0).astype(np.int64)  # (a non-finite state: the batch's count raises)
    return side(cur - lo), side(hi - cur)


def _axis_state_soa(axis: int, cfg: DaaConfig, x0, y0, z0, gs0, st, ct, vs0, sgn, t, with_value: bool = False) -> tuple:
    """Ownship position and velocity (six component arrays, arguments broadcast) on the maneuver of
    ``axis`` toward side ``sgn`` (+-1) after ``t`` s; ``st``/``ct`` are the sine and cosine of the
    initial track. Closed forms of :func:`daa_sil.geometry.kinematics.advance` for a constant-rate turn and for
    an acceleration that saturates at the axis limit (with ``cfg.daidalus_grid`` it runs past the limit
    by up to one step, as DAIDALUS evaluates its last candidate, but never below zero speed).
    ``with_value``: ``(components, value)`` with the axis value (track change, vs or gs)."""
    if axis == AXIS_HORIZONTAL:
        w = cfg.turn_rate
        th = w * t
        r = gs0 / w
        sth, cth = np.sin(th), np.cos(th)
        fwd, lat = r * sth, sgn * r * (1.0 - cth)
        ssth = sgn * sth
        out = (x0 + fwd * st + lat * ct, y0 + fwd * ct - lat * st, z0 + vs0 * t,
               gs0 * (st * cth + ct * ssth), gs0 * (ct * cth - st * ssth), vs0 + 0.0 * t)
        return (out, sgn * th) if with_value else out
    vertical = axis == AXIS_VERTICAL
    acc, lim = speed_limits(vertical, cfg, sgn)
    v0 = vs0 if vertical else gs0
    tc = np.minimum(t, np.maximum((lim - v0) * sgn / acc, 0.0))
    dist = v0 * t + sgn * acc * tc * (t - 0.5 * tc)
    v_t = v0 + sgn * acc * tc
    if vertical:
        out = x0 + gs0 * st * t, y0 + gs0 * ct * t, z0 + dist, gs0 * st + 0.0 * t, gs0 * ct + 0.0 * t, v_t
    else:
        out = x0 + dist * st, y0 + dist * ct, z0 + vs0 * t, v_t * st, v_t * ct, vs0 + 0.0 * t
    return (out, v_t) if with_value else out


def _turn_knots(cfg: DaaConfig, x0, y0, z0, gs0, st, ct, vs0, t):
    """:func:`_axis_state_soa` of the turn for both sides at once (side axis 1: left, right), the same
    numbers: the two sides share every term but the sign of the lateral ones. Returns the six components
    (the vertical ones without the side axis) and the signed track change ``(1, 2, K)``."""
    w = cfg.turn_rate
    th = w * t
    r = gs0 / w
    sth, cth = np.sin(th), np.cos(th)
    fwd = r * sth
    lat = r * (1.0 - cth)
    both = lambda base, off: np.stack([base - off, base + off], axis=1)[:, :, 0]  # noqa: E731  (left, right)
    out = (both(x0 + fwd * st, lat * ct), both(y0 + fwd * ct, -(lat * st)), z0 + vs0 * t,
           both(st * cth, ct * sth) * gs0, both(ct * cth, -(st * sth)) * gs0, vs0 + 0.0 * t)
    return out, np.concatenate([-th, th], axis=1)


def _kin_table(axis: int, cfg: DaaConfig, x0, y0, z0, gs0, st, ct, vs0, sgn) -> tuple:
    """``("axis", axis, rate, (N, 2, 9) rows)`` of the low/high-side paths for the compiled state kernel
    (:data:`daa_sil.daa.kernels.motion.KIN_FIELDS`; the same inputs as :func:`_axis_state_soa`)."""
    if axis == AXIS_HORIZONTAL:
        rate, lim = cfg.turn_rate, np.zeros(2)
    else:
        rate, lim = speed_limits(axis == AXIS_VERTICAL, cfg, sgn)
    kin = np.empty((x0.shape[0], 2, 9))
    kin[:, 0, :7] = np.stack((x0, y0, z0, gs0, st, ct, vs0), axis=1)
    kin[:, 1, :7] = kin[:, 0, :7]
    kin[:, :, 7], kin[:, :, 8] = sgn, lim
    return "axis", axis, float(rate), kin


@functools.lru_cache(maxsize=64)
def knot_times(knot: float, j: int) -> np.ndarray:
    """The knot times ``k * knot`` (s) of k = 0..j (read-only; made once per spacing and count)."""
    t = np.arange(j + 1) * knot
    t.setflags(write=False)
    return t


_SIDES = np.array([-1.0, 1.0])
_SIDES.setflags(write=False)


def maneuver_paths(own: AircraftState, axis: int, cfg: DaaConfig, j: int,
                    with_values: bool = True) -> tuple[ManeuverPaths, "np.ndarray | None"]:
    """Low-side and high-side maneuver paths of ``axis`` at knots 0..j (P = 2; knot spacing from
    ``cfg``, s) and the axis value at each knot ``(N, 2, j+1)`` (rad, m/s; None without ``with_values``)."""
    knot = {AXIS_HORIZONTAL: cfg.knot_trk, AXIS_VERTICAL: cfg.knot_vs, AXIS_SPEED: cfg.knot_gs}[axis]
    t = knot_times(float(knot), int(j))
    sgn = _SIDES
    n = own.shape[0]
    st, ct = np.sin(own.trk), np.cos(own.trk)
    kin = _kin_table(axis, cfg, own.x, own.y, own.z, own.gs, st, ct, own.vs, sgn)
    # the path's start as the kernel's table holds it (copies of the ownship's state, sine and cosine of its track)
    x0, y0, z0, gs0, st, ct, vs0 = (kin[3][:, 0, c] for c in range(7))
    value = None
    if COMPILED and not with_values:  # computed when asked for (ManeuverPaths.knot_states: kernels.motion's
        comp = (None,) * 6  # axis_knots_into, the same numbers as below; the evaluator does without them)
    else:
        col = lambda a: a[:, None, None]  # noqa: E731
        s3, t3 = sgn[None, :, None], t[None, None, :]
        if axis == AXIS_HORIZONTAL:
            comp, value = _turn_knots(cfg, col(x0), col(y0), col(z0), col(gs0), col(st), col(ct), col(vs0), t3)
            if with_values:
                value = col(own.trk) + value
                # wrap to [0, 2pi) as frames.wrap_2pi (the same numbers: |turn| <= pi, fmod there is one subtraction)
                value = np.where(value < 0.0, value + TWO_PI, np.where(value >= TWO_PI, value - TWO_PI, value))
        else:
            comp, value = _axis_state_soa(axis, cfg, col(x0), col(y0), col(z0), col(gs0), col(st), col(ct), col(vs0),
                                          s3, t3, with_value=True)
    kink = None
    two = np.empty((3, n, 2))  # acc_h, acc_v, jerk of both sides
    if axis == AXIS_HORIZONTAL:  # constant-rate turn: |a| = V w, |da/dt| = V w^2
        two[0] = (gs0 * cfg.turn_rate)[:, None]
        two[1] = 0.0
        two[2] = (gs0 * cfg.turn_rate ** 2)[:, None]
    elif axis == AXIS_SPEED:  # along-track acceleration until the speed limit (a kink there)
        two[0], two[1], two[2] = cfg.horizontal_accel, 0.0, 0.0
        if not cfg.daidalus_grid:
            lim = np.array([cfg.min_gs, cfg.max_gs])[None, :]
            kink = np.maximum((lim - gs0[:, None]) * sgn[None, :] / cfg.horizontal_accel, 0.0)
    else:  # vertical acceleration: the horizontal motion is straight
        two[0], two[1], two[2] = 0.0, cfg.vertical_accel, 0.0

    def state_at(ni, pi):  # f(t): true ownship state on paths pi of encounters ni at times t
        args = (x0[ni], y0[ni], z0[ni], gs0[ni], st[ni], ct[ni], vs0[ni], sgn[pi])
        return lambda tq: _axis_state_soa(axis, cfg, *args, tq)

    paths = ManeuverPaths(None if comp[0] is None else comp[:3], None if comp[0] is None else comp[3:],
                          t[None, None, :], state_at, two[0], two[1],
                          vz_const=axis != AXIS_VERTICAL, jerk_h=two[2], kink_t=kink,
                          kin=kin)
    return paths, (np.broadcast_to(value, (n, 2, j + 1)) if with_values else None)
