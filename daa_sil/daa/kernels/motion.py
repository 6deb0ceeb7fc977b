"""The true ownship state on a band axis's maneuver path, relative to a straight-line intruder, and
the bisection of a crossing of the well-clear boundary on it (compiled).

A path is one row of ``kin``: ``x0, y0, z0, gs0, sin(trk0), cos(trk0), vs0, side (+-1), limit`` (SI) of
:data:`KIN_FIELDS`; the axis code and its rate (turn rate rad/s or acceleration m/s^2) are scalars.
The numpy references are :func:`daa_sil.daa.axis_paths._axis_state_soa` and
:meth:`daa_sil.daa.undecided.UndecidedPieces._bisect`.
"""

from __future__ import annotations

import math

from numba import boolean, float64, int64, types, void

from daa_sil.daa.kernels.jit import inline, kernel
from daa_sil.daa.kernels.scalar import npmax, npmin, wcv_soa

#: columns of a path's row in ``kin``
KIN_FIELDS = ("x0", "y0", "z0", "gs0", "st", "ct", "vs0", "sgn", "lim")
#: axis codes (daa.config.AXIS_*)
_HORIZONTAL, _VERTICAL = 1, 2

A2 = types.Array(float64, 2, "A", readonly=True)
A = types.Array(float64, 1, "A", readonly=True)
O = float64[:]
F = float64
I = int64


@inline
def axis_state(axis, rate, x0, y0, z0, gs0, st, ct, vs0, sgn, lim, t):
    """Ownship (x, y, z, vx, vy, vz) after ``t`` s on the path (``_axis_state_soa``)."""
    if axis == _HORIZONTAL:
        th = rate * t
        r = gs0 / rate
        sth, cth = math.sin(th), math.cos(th)
        fwd, lat = r * sth, sgn * r * (1.0 - cth)
        ssth = sgn * sth
        return (x0 + fwd * st + lat * ct, y0 + fwd * ct - lat * st, z0 + vs0 * t,
                gs0 * (st * cth + ct * ssth), gs0 * (ct * cth - st * ssth), vs0 + 0.0 * t)
    v0 = vs0 if axis == _VERTICAL else gs0
    tc = npmin(t, npmax((lim - v0) * sgn / rate, 0.0))
    sa = sgn * rate
    dist = v0 * t + sa * tc * (t - 0.5 * tc)
    v_t = v0 + sa * tc
    if axis == _VERTICAL:
        return x0 + gs0 * st * t, y0 + gs0 * ct * t, z0 + dist, gs0 * st + 0.0 * t, gs0 * ct + 0.0 * t, v_t
    return x0 + dist * st, y0 + dist * ct, z0 + vs0 * t, v_t * st, v_t * ct, vs0 + 0.0 * t


@inline
def rel_state(axis, rate, kin, ipv, i, t):
    """Relative state (ownship - intruder) of path row ``i`` at ``t``."""
    ox, oy, oz, ovx, ovy, ovz = axis_state(axis, rate, kin[i, 0], kin[i, 1], kin[i, 2], kin[i, 3], kin[i, 4],
                                           kin[i, 5], kin[i, 6], kin[i, 7], kin[i, 8], t)
    ivx, ivy, ivz = ipv[i, 3], ipv[i, 4], ipv[i, 5]
    return (ox - (ipv[i, 0] + t * ivx), oy - (ipv[i, 1] + t * ivy), oz - (ipv[i, 2] + t * ivz),
            ovx - ivx, ovy - ivy, ovz - ivz)


@kernel(void(I, F, A2, A2, A, types.Array(float64, 2, "C")))
def rel_states_into(axis, rate, kin, ipv, t, out):
    """Relative state of path row ``i`` at ``t[i]`` into ``out[:, i]`` (six rows)."""
    for i in range(t.shape[0]):
        out[0, i], out[1, i], out[2, i], out[3, i], out[4, i], out[5, i] = rel_state(axis, rate, kin, ipv, i, t[i])


@kernel(void(I, F, A2, A2, O, O, types.Array(boolean, 1, "A", readonly=True), I, I, I, boolean, F, F, F, F))
def bisect_into(axis, rate, kin, ipv, lo, hi, lo_in, steps, n_in, n_out, mixed, DD, TT, H, TC):
    """Halve ``[lo, hi]`` ``steps`` times keeping the predicate ``lo_in`` at ``lo``; with ``mixed``, rows
    starting inside stop after ``n_out`` halvings and the others after ``n_in`` (``_bisect``)."""
    for i in range(lo.shape[0]):
        a, b, flag = lo[i], hi[i], lo_in[i]
        for k in range(steps):
            mid = 0.5 * (a + b)
            sx, sy, sz, vx, vy, vz = rel_state(axis, rate, kin, ipv, i, mid)
            same = wcv_soa(sx, sy, sz, vx, vy, vz, DD, TT, H, TC) == flag
            if mixed:
                if k < (n_out if flag else n_in):
                    if same:
                        a = mid
                    else:
                        b = mid
            elif same:
                a = mid
            else:
                b = mid
        lo[i], hi[i] = a, b
