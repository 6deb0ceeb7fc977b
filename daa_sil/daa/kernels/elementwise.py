"""Elementwise kernels over 1-D component arrays: one loop, no temporaries.

Each writes into output arrays the caller allocates; array arguments may be strided views (a
scalar broadcast with ``np.broadcast_to`` costs nothing). The Python wrappers with the numpy
signatures are :func:`daa_sil.daa.intervals.interval_soa`, :func:`daa_sil.daa.intervals.wcv_soa`,
:func:`daa_sil.daa.certify.classify_pieces`, :func:`daa_sil.daa.certify.clear_second_order` and
:func:`daa_sil.geometry.wellclear.nmac_interval`.
"""

from __future__ import annotations

import math

from numba import boolean, int8, types, void

from daa_sil.daa.kernels.jit import inline, kernel
from daa_sil.daa.kernels.pieces import classify, clear2
from daa_sil.daa.kernels.scalar import EPS, interval, npmax, npmin, vertical_window, wcv_soa
from daa_sil.daa.kernels.signatures import A, O, I8, F


@kernel(void(types.UniTuple(A, 6), A, types.UniTuple(A, 2), boolean, types.UniTuple(F, 6), types.UniTuple(O, 2)))
def interval_into(rel, length, win, has_win, ivol, out):
    """Violation interval of each straight line ``rel`` = ``(sx, sy, sz, vx, vy, vz)`` over ``[0, length]``
    (vertical window ``win`` = ``(wlo, whi)`` when ``has_win``; ``ivol`` = ``(D, D * D, D ** 2, TTHR, ZTHR,
    TCOA)``) into ``out`` = ``(t_in, t_out)``."""
    sx, sy, sz, vx, vy, vz = rel
    wlo, whi = win
    D, DD, D2, TT, H, TC = ivol
    t_in, t_out = out
    for i in range(sx.shape[0]):
        if has_win:
            lo, hi = wlo[i], whi[i]
        else:
            lo, hi = vertical_window(sz[i], vz[i], 0.0, length[i], H, TC)
        t_in[i], t_out[i] = interval(sx[i], sy[i], sz[i], vx[i], vy[i], vz[i], length[i], lo, hi,
                                     D, DD, D2, TT, H, TC)


@kernel(void(A, A, A, A, A, A, F, F, F, F, boolean[:]), lazy=True)
def wcv_soa_into(sx, sy, sz, vx, vy, vz, DD, TT, H, TC, out):
    """Instantaneous well-clear violation of each relative state into ``out``."""
    for i in range(sx.shape[0]):
        out[i] = wcv_soa(sx[i], sy[i], sz[i], vx[i], vy[i], vz[i], DD, TT, H, TC)


#: records: relative positions ``(x, y, z)`` and horizontal velocities ``(x, y)`` (arrays), error bounds
#: ``(e_p, e_v, e_z)`` (arrays), the volume ``(D, D * D, ZTHR, TTHR, TCOA)``
_XYZ, _XY, _ERR, _VOL = types.UniTuple(A, 3), types.UniTuple(A, 2), types.UniTuple(A, 3), types.UniTuple(F, 5)


@kernel(void(_XYZ, _XYZ, A, _ERR, _XY, boolean, _VOL, int8[:]), lazy=True)
def classify_into(p0, p1, h, err, win, has_win, vol, out):
    """CLEAR / INSIDE / UNDECIDED code of each chord piece (from ``p0`` to ``p1`` in ``h`` s, error bounds
    ``err``, vertical window ``win`` = ``(lo, hi)`` when ``has_win``) into ``out``."""
    x0, y0, z0 = p0
    x1, y1, z1 = p1
    e_p, e_v, e_z = err
    wlo, whi = win
    for i in range(x0.shape[0]):
        lo, hi = (wlo[i], whi[i]) if has_win else (0.0, 0.0)
        out[i] = classify((x0[i], y0[i], z0[i]), (x1[i], y1[i], z1[i]), h[i], e_p[i], e_v[i], e_z[i], lo, hi,
                          has_win, vol)


@kernel(void(_XYZ, _XYZ, _XY, _XY, A, _ERR, _VOL, boolean[:]), lazy=True)
def clear2_into(p0, p1, u0, u1, h, err, vol, out):
    """Second-order CLEAR certificate of each piece (relative positions ``p0``/``p1`` and horizontal velocities
    ``u0``/``u1`` at its ends, ``h`` s, error bounds ``err``) into ``out``."""
    x0, y0, z0 = p0
    x1, y1, z1 = p1
    u0x, u0y = u0
    u1x, u1y = u1
    e_p, e_v, e_z = err
    for i in range(x0.shape[0]):
        out[i] = clear2((x0[i], y0[i], z0[i]), (x1[i], y1[i], z1[i]), (u0x[i], u0y[i]), (u1x[i], u1y[i]), h[i],
                        e_p[i], e_v[i], e_z[i], vol)


#: daa.config DIR_* codes by (axis code, side + 1) (daa.config.side_to_dir's table)
_DIRS = ((0, 0, 0), (1, 0, 2), (4, 0, 3), (6, 0, 5))


@kernel(void(A, A, A, A, A, A, F, F, F, F, F, F, F, F, I8, I8))
def classify_command_into(trk, vs, gs, c_trk, c_vs, c_gs, db_trk, db_vs, db_gs, turn_rate, v_acc, h_acc, pi, two_pi,
                          axis_out, dir_out):
    """(axis, direction) code of each command against its state (``resolution.classify_command``): nan
    command fields held, the track change wrapped to [-pi, pi), changes inside the deadbands zero, the
    axis whose change takes longest (the first on ties; none if nothing changes or a time is nan)."""
    for i in range(trk.shape[0]):
        ct = trk[i] if c_trk[i] != c_trk[i] else c_trk[i]
        cv = vs[i] if c_vs[i] != c_vs[i] else c_vs[i]
        cg = gs[i] if c_gs[i] != c_gs[i] else c_gs[i]
        d = ((ct - trk[i]) + pi) % two_pi - pi, cv - vs[i], cg - gs[i]
        d0 = 0.0 if abs(d[0]) < db_trk else d[0]
        d1 = 0.0 if abs(d[1]) < db_vs else d[1]
        d2 = 0.0 if abs(d[2]) < db_gs else d[2]
        t0, t1, t2 = abs(d0) / turn_rate, abs(d1) / v_acc, abs(d2) / h_acc
        if t0 != t0 or t1 != t1 or t2 != t2:  # np.max is nan: not moved
            axis_out[i], dir_out[i] = 0, 0
            continue
        ax, best, side = 1, t0, d0
        if t1 > best:
            ax, best, side = 2, t1, d1
        if t2 > best:
            ax, best, side = 3, t2, d2
        if best > 0:
            axis_out[i] = ax
            dir_out[i] = _DIRS[ax][(1 if side > 0 else (-1 if side < 0 else 0)) + 1]
        else:
            axis_out[i], dir_out[i] = 0, 0


@inline
def disc_interval(px, py, vx, vy, radius, t_end):
    """``wellclear._disc_interval``: times in [0, t_end] with |p + t v| <= radius (2-D), (inf, -inf) if none."""
    a = vx * vx + vy * vy
    p2 = px * px + py * py
    pv = px * vx + py * vy
    rr = radius * radius
    moving = a >= EPS
    disc = pv * pv - a * (p2 - rr)
    if moving:
        root = math.sqrt(npmax(disc, 0.0))
        lo, hi, hit = (-pv - root) / a, (-pv + root) / a, disc >= 0
    else:
        lo, hi, hit = (0.0 if p2 <= rr else math.inf), (t_end if p2 <= rr else -math.inf), p2 <= rr
    if not hit:
        return math.inf, -math.inf
    return npmax(lo, 0.0), npmin(hi, t_end)


@inline
def slab_interval(z, vz, half, t_end):
    """``wellclear._slab_interval``: times in [0, t_end] with |z + t vz| <= half, (inf, -inf) if none."""
    if abs(vz) < EPS:
        inside = abs(z) <= half
        return (0.0 if inside else math.inf), (t_end if inside else -math.inf)
    ta = (-half - z) / vz
    tb = (half - z) / vz
    return npmax(npmin(ta, tb), 0.0), npmin(npmax(ta, tb), t_end)


@kernel(void(A, A, A, A, A, A, F, F, F, O, O))
def nmac_interval_into(sx, sy, sz, vx, vy, vz, nmac_h, nmac_v, t_end, lo_out, hi_out):
    """``wellclear.nmac_interval`` of each straight line over ``[0, t_end]`` into ``lo_out``/``hi_out``."""
    for i in range(sx.shape[0]):
        hlo, hhi = disc_interval(sx[i], sy[i], vx[i], vy[i], nmac_h, t_end)
        zlo, zhi = slab_interval(sz[i], vz[i], nmac_v, t_end)
        lo, hi = npmax(hlo, zlo), npmin(hhi, zhi)
        if lo > hi:
            lo_out[i], hi_out[i] = math.inf, -math.inf
        else:
            lo_out[i], hi_out[i] = lo, hi


@inline
def t_cpa(sx, sy, vx, vy):
    """``wellclear.t_cpa``: time (s) to the horizontal closest approach, 0 without relative motion."""
    a = vx * vx + vy * vy  # (numpy's v ** 2 is its square, x * x)
    return -(sx * vx + sy * vy) / a if a > EPS else 0.0


@kernel(void(types.UniTuple(A, 6), types.UniTuple(F, 8), types.Tuple((O, O, O, O, boolean[:]))))
def geometry_into(rel, consts, out):
    """``wellclear.encounter_geometry`` of each relative state: horizontal range (m), HMD within ``lookahead``
    (m), height difference (m), modified tau with DMOD ``dmod`` (s, nan when diverging outside DMOD) and the
    well-clear violation (``dthr`` .. ``tcoa``). ``dmod_sq`` is ``dmod * dmod`` and ``dthr_sq`` is
    ``dthr ** 2``, as the numpy code computes them in Python. ``rel`` = ``(sx, sy, sz, vx, vy, vz)``, ``consts`` =
    ``(lookahead, dmod, dmod_sq, dthr, dthr_sq, tthr, zthr, tcoa)``, ``out`` = ``(range, hmd, dh, tau_mod,
    wcv)``."""
    sx, sy, sz, vx, vy, vz = rel
    lookahead, dmod, dmod_sq, dthr, dthr_sq, tthr, zthr, tcoa = consts
    range_out, hmd_out, dh_out, tau_out, wcv_out = out
    for i in range(sx.shape[0]):
        x, y, z, u, w, h = sx[i], sy[i], sz[i], vx[i], vy[i], vz[i]
        r = math.hypot(x, y)
        sv = x * u + y * w
        t = t_cpa(x, y, u, w)
        tc = npmin(npmax(t, 0.0), lookahead)
        range_out[i] = r
        hmd_out[i] = math.hypot(x + tc * u, y + tc * w)
        dh_out[i] = -z
        den = sv if sv < 0 else -1.0
        if r <= dmod:
            tau_out[i] = 0.0
        elif sv < 0:
            tau_out[i] = (dmod_sq - r * r) / den
        else:
            tau_out[i] = math.nan
        tau = (dthr_sq - r * r) / den
        horiz = (r <= dthr) or ((math.hypot(x + t * u, y + t * w) <= dthr) and (sv < 0) and (tau <= tthr))
        moving = abs(h) > EPS
        t_coa = -z / (h if moving else 1.0)
        vert = (abs(z) <= zthr) or (moving and (z * h <= 0) and (t_coa <= tcoa))
        wcv_out[i] = horiz and vert
