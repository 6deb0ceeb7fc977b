"""The true ownship state on a band axis's maneuver path or a command's path, relative to a
straight-line intruder (compiled; the scalar steps the fused resolution and the knot kernels inline,
and the knot kernels themselves). Per-evaluation kernels of the unfused resolution are in
:mod:`daa_sil.daa.kernels.unfused`.

A path is one row of ``kin``: ``x0, y0, z0, gs0, sin(trk0), cos(trk0), vs0, side (+-1), limit`` (SI) of
:data:`KIN_FIELDS`; the axis code and its rate (turn rate rad/s or acceleration m/s^2) are scalars.
The numpy reference is :func:`daa_sil.daa.axis_paths._axis_state_soa`.
"""

from __future__ import annotations

import math

import numpy as np

from numba import float64, types, void

from daa_sil.daa.kernels.jit import inline, inline_ir, kernel
from daa_sil.daa.kernels.scalar import npmax, npmin, vertical_toward
from daa_sil.daa.kernels.signatures import A, A2, A3, F, I

#: columns of a path's row in ``kin``
KIN_FIELDS = ("x0", "y0", "z0", "gs0", "st", "ct", "vs0", "sgn", "lim")
#: axis codes (daa.config.AXIS_*)
_HORIZONTAL, _VERTICAL = 1, 2


@inline
def turn_state(rate, x0, y0, z0, gs0, st, ct, vs0, sgn, sth, cth, t):
    """The turn of :func:`axis_state_capped` given ``sth``/``cth``, the sine and cosine of ``rate * t``."""
    r = gs0 / rate
    fwd, lat = r * sth, sgn * r * (1.0 - cth)
    ssth = sgn * sth
    return (x0 + fwd * st + lat * ct, y0 + fwd * ct - lat * st, z0 + vs0 * t,
            gs0 * (st * cth + ct * ssth), gs0 * (ct * cth - st * ssth), vs0 + 0.0 * t)


@inline
def limit_time(axis, rate, vs0, gs0, sgn, lim):
    """Time (s) a vertical / speed path takes to reach its limit ``lim`` (m/s) from ``vs0`` / ``gs0`` at
    ``rate`` (m/s^2) on side ``sgn`` (0 if past it; 0.0 on a track path, which does not read it): the
    same at every ``t`` of a path, so the callers that evaluate a path many times compute it once."""
    if axis == _HORIZONTAL:
        return 0.0
    v0 = vs0 if axis == _VERTICAL else gs0
    return npmax((lim - v0) * sgn / rate, 0.0)


@inline
def axis_state_capped(axis, rate, x0, y0, z0, gs0, st, ct, vs0, sgn, cap, t):
    """Ownship (x, y, z, vx, vy, vz) after ``t`` s on the path (``axis_paths._axis_state_soa``), given the
    path's :func:`limit_time` ``cap`` (s)."""
    if axis == _HORIZONTAL:
        th = rate * t
        return turn_state(rate, x0, y0, z0, gs0, st, ct, vs0, sgn, math.sin(th), math.cos(th), t)
    v0 = vs0 if axis == _VERTICAL else gs0
    tc = npmin(t, cap)
    sa = sgn * rate
    dist = v0 * t + sa * tc * (t - 0.5 * tc)
    v_t = v0 + sa * tc
    if axis == _VERTICAL:
        return x0 + gs0 * st * t, y0 + gs0 * ct * t, z0 + dist, gs0 * st + 0.0 * t, gs0 * ct + 0.0 * t, v_t
    return x0 + dist * st, y0 + dist * ct, z0 + vs0 * t, v_t * st, v_t * ct, vs0 + 0.0 * t


@inline
def axis_row(kin, i):
    """Path row ``i`` of ``kin`` as a tuple of its :data:`KIN_FIELDS` (loaded once for the many times at
    which a bisection or a sampling evaluates one row)."""
    return (kin[i, 0], kin[i, 1], kin[i, 2], kin[i, 3], kin[i, 4], kin[i, 5], kin[i, 6], kin[i, 7], kin[i, 8])


@inline
def row_limit_time(axis, rate, row):
    """:func:`limit_time` of the path ``row`` (:func:`axis_row`)."""
    x0, y0, z0, gs0, st, ct, vs0, sgn, lim = row
    return limit_time(axis, rate, vs0, gs0, sgn, lim)


@inline
def intruder_row(ipv, i):
    """Intruder row ``i`` of ``ipv`` (position m, velocity m/s) as a tuple of six floats."""
    return ipv[i, 0], ipv[i, 1], ipv[i, 2], ipv[i, 3], ipv[i, 4], ipv[i, 5]


@inline
def relative(ox, oy, oz, ovx, ovy, ovz, iv, t):
    """Ownship state minus that of the straight-line intruder ``iv`` (:func:`intruder_row`) at ``t``."""
    ipx, ipy, ipz, ivx, ivy, ivz = iv
    return (ox - (ipx + t * ivx), oy - (ipy + t * ivy), oz - (ipz + t * ivz), ovx - ivx, ovy - ivy, ovz - ivz)


@inline
def axis_rel(axis, rate, row, cap, iv, t):
    """Relative state at ``t`` of the path ``row`` (:func:`axis_row`, its :func:`row_limit_time` ``cap``)
    against the intruder ``iv``: scalars only, so nothing is reference-counted per call."""
    x0, y0, z0, gs0, st, ct, vs0, sgn, lim = row
    ox, oy, oz, ovx, ovy, ovz = axis_state_capped(axis, rate, x0, y0, z0, gs0, st, ct, vs0, sgn, cap, t)
    return relative(ox, oy, oz, ovx, ovy, ovz, iv, t)


@inline_ir
def rel_state(axis, rate, kin, ipv, i, t):
    """Relative state (ownship - intruder) of path row ``i`` at ``t``."""
    row = axis_row(kin, i)
    return axis_rel(axis, rate, row, row_limit_time(axis, rate, row), intruder_row(ipv, i), t)


# --------------------------------------------------------------------------------------------------
# a command flown kinematically (SM's paths): daa_sil.daa.safety._CommandMotion.state
# --------------------------------------------------------------------------------------------------
#: columns of an encounter's row in ``phases`` (one row per phase: turn and speed change, the longer
#: one alone, straight) and in ``enc``
PHASE_FIELDS = ("t0", "x", "y", "gs", "trk", "w", "acc", "sin0", "cos0")
ENC_FIELDS = ("dpsi", "trk_cmd", "dgs", "tgt_gs", "z", "vs", "tgt_vs")
_TWO_PI = 2.0 * math.pi


@inline
def command_row(ph_rows, enc, i):
    """Encounter row ``i`` of ``ph_rows`` and ``enc`` as tuples ``(phase 0, phase 1, phase 2, enc)`` of their
    :data:`PHASE_FIELDS` and :data:`ENC_FIELDS` (loaded once for the many times of one row)."""
    p0 = (ph_rows[i, 0, 0], ph_rows[i, 0, 1], ph_rows[i, 0, 2], ph_rows[i, 0, 3], ph_rows[i, 0, 4], ph_rows[i, 0, 5],
          ph_rows[i, 0, 6], ph_rows[i, 0, 7], ph_rows[i, 0, 8])
    p1 = (ph_rows[i, 1, 0], ph_rows[i, 1, 1], ph_rows[i, 1, 2], ph_rows[i, 1, 3], ph_rows[i, 1, 4], ph_rows[i, 1, 5],
          ph_rows[i, 1, 6], ph_rows[i, 1, 7], ph_rows[i, 1, 8])
    p2 = (ph_rows[i, 2, 0], ph_rows[i, 2, 1], ph_rows[i, 2, 2], ph_rows[i, 2, 3], ph_rows[i, 2, 4], ph_rows[i, 2, 5],
          ph_rows[i, 2, 6], ph_rows[i, 2, 7], ph_rows[i, 2, 8])
    return p0, p1, p2, (enc[i, 0], enc[i, 1], enc[i, 2], enc[i, 3], enc[i, 4], enc[i, 5], enc[i, 6])


@inline
def command_motion(row, tau, max_turn, h_acc, v_acc):
    """Ownship (x, y, z, vx, vy, vz) at ``tau`` s of the encounter ``row`` (:func:`command_row`;
    ``_CommandMotion.state``)."""
    p0, p1, p2, e = row
    ph = (1 if tau > p1[0] else 0) + (1 if tau > p2[0] else 0)
    p = p0 if ph == 0 else (p1 if ph == 1 else p2)
    t = tau - p[0]
    gs0, acc, w, trk0 = p[3], p[6], p[5], p[4]
    s0, c0 = p[7], p[8]
    turning = w != 0.0
    ws = w if turning else 1.0
    th1 = trk0 + w * t
    s1, c1 = math.sin(th1), math.cos(th1)
    if turning:
        ws2 = ws * ws
        dx = gs0 * (c0 - c1) / ws + acc * (-t * c1 / ws + (s1 - s0) / ws2)
        dy = gs0 * (s1 - s0) / ws + acc * (t * s1 / ws + (c1 - c0) / ws2)
    else:
        dist = gs0 * t + 0.5 * acc * t * t
        dx, dy = dist * s0, dist * c0
    x, y = p[1] + dx, p[2] + dy
    gs, trk = gs0 + acc * t, th1
    if abs(e[0]) <= max_turn * tau:
        trk = e[1]
    if abs(e[2]) <= h_acc * tau:
        gs = e[3]
    z, vs = vertical_toward(e[4], e[5], e[6], v_acc, tau)
    trk = trk % _TWO_PI
    return x, y, z, gs * math.sin(trk), gs * math.cos(trk), vs


@inline
def command_rel(row, iv, t, max_turn, h_acc, v_acc):
    """Relative state at ``t`` of the encounter ``row`` (:func:`command_row`) against the intruder ``iv``
    (:func:`intruder_row`): scalars only."""
    ox, oy, oz, ovx, ovy, ovz = command_motion(row, t, max_turn, h_acc, v_acc)
    return relative(ox, oy, oz, ovx, ovy, ovz, iv, t)


@inline_ir
def command_state(ph_rows, enc, i, tau, max_turn, h_acc, v_acc):
    """Ownship (x, y, z, vx, vy, vz) of encounter row ``i`` at ``tau`` s (``_CommandMotion.state``)."""
    return command_motion(command_row(ph_rows, enc, i), tau, max_turn, h_acc, v_acc)


@inline_ir
def command_rel_state(ph_rows, enc, ipv, i, t, max_turn, h_acc, v_acc):
    """Relative state (ownship - intruder) of row ``i`` at ``t``."""
    return command_rel(command_row(ph_rows, enc, i), intruder_row(ipv, i), t, max_turn, h_acc, v_acc)


@kernel(void(A3, A2, F, F, F, A2, types.Array(float64, 3, "C")))
def command_states_into(ph_rows, enc, max_turn, h_acc, v_acc, t, out):
    """Ownship state of row ``i`` at each ``t[i, j]`` into ``out[:, i, j]`` (six rows; SM's knots)."""
    for i in range(t.shape[0]):
        for j in range(t.shape[1]):
            out[0, i, j], out[1, i, j], out[2, i, j], out[3, i, j], out[4, i, j], out[5, i, j] = command_state(
                ph_rows, enc, i, t[i, j], max_turn, h_acc, v_acc)


@inline
def axis_knot(axis, rate, row, cap, sth, cth, t):
    """Ownship state on the path ``row`` (:func:`axis_row`, its :func:`row_limit_time` ``cap``) at knot
    time ``t`` (``sth``/``cth``: the turn's sine and cosine there)."""
    x0, y0, z0, gs0, st, ct, vs0, sgn, lim = row
    if axis == _HORIZONTAL:
        return turn_state(rate, x0, y0, z0, gs0, st, ct, vs0, sgn, sth, cth, t)
    return axis_state_capped(axis, rate, x0, y0, z0, gs0, st, ct, vs0, sgn, cap, t)


@inline
def turn_sincos(rate, t):
    """Sines and cosines of ``rate * t[k]`` (the same on every path)."""
    K = t.shape[0]
    sth, cth = np.empty(K), np.empty(K)
    for k in range(K):
        th = rate * t[k]
        sth[k], cth[k] = math.sin(th), math.cos(th)
    return sth, cth


@kernel(void(I, F, A3, A, A3, A3, *([types.Array(float64, 4, "C")] * 6)), lazy=True)
def axis_relative_knots_into(axis, rate, kin, t, ipos, ivel, s0, s1, s2, v0, v1, v2):
    """:func:`axis_knots_into` then ``evaluate.relative_knots_into`` in one pass: the relative position and
    velocity (ownship - intruder ``m``, ``ipos``/``ivel`` (N, M, 3)) at the knots ``(N, M, P, K)`` per
    component, without storing the ownship's knot states."""
    K = t.shape[0]
    sth, cth = turn_sincos(rate, t)
    for n in range(kin.shape[0]):
        for p in range(kin.shape[1]):
            row = axis_row(kin[n], p)
            cap = row_limit_time(axis, rate, row)
            for k in range(K):
                ox, oy, oz, ovx, ovy, ovz = axis_knot(axis, rate, row, cap, sth[k], cth[k], t[k])
                tk = t[k]
                for m in range(ipos.shape[1]):
                    ix, iy, iz = ipos[n, m, 0], ipos[n, m, 1], ipos[n, m, 2]
                    jx, jy, jz = ivel[n, m, 0], ivel[n, m, 1], ivel[n, m, 2]
                    s0[n, m, p, k] = ox - (ix + tk * jx)
                    s1[n, m, p, k] = oy - (iy + tk * jy)
                    s2[n, m, p, k] = oz - (iz + tk * jz)
                    v0[n, m, p, k] = ovx - jx
                    v1[n, m, p, k] = ovy - jy
                    v2[n, m, p, k] = ovz - jz


@kernel(void(I, F, A3, A, types.Array(float64, 4, "C")), lazy=True)
def axis_knots_into(axis, rate, kin, t, out):
    """Ownship state on path ``p`` of encounter ``n`` (row ``kin[n, p]``) at each knot time ``t[k]`` into
    ``out[:, n, p, k]`` (six rows; the band axis's knot states, ``axis_paths.maneuver_paths``)."""
    K = t.shape[0]
    sth, cth = turn_sincos(rate, t)
    for n in range(kin.shape[0]):
        for p in range(kin.shape[1]):
            row = axis_row(kin[n], p)
            cap = row_limit_time(axis, rate, row)
            for k in range(K):
                a, b, c, d, e, f = axis_knot(axis, rate, row, cap, sth[k], cth[k], t[k])
                out[0, n, p, k], out[1, n, p, k], out[2, n, p, k], out[3, n, p, k], out[4, n, p, k], out[5, n, p, k] = \
                    a, b, c, d, e, f
