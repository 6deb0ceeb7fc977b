"""Certificates for a piece of the true (curved) ownship path against its chord.

A piece is *clear* (no instant of the true path violates), *inside* (every instant does) or
undecided (:mod:`daa_sil.daa.trajectory` then resolves it on the true state). A piece of duration
``h`` is within ``A h^2 / 8`` of its chord in position and ``A h / 2`` in velocity (``A`` the path's
acceleration bound, m/s^2); the tests use the form ``|s + (TTHR/2) v| <= sqrt(DTHR^2 + (TTHR/2)^2 |v|^2)``
of the tau_mod test (exact for TCOA = 0, every preset).
"""

from __future__ import annotations

import numpy as np

from daa_sil.daa.intervals import in_cache_blocks, as_vector
from daa_sil.daa import kernels
from daa_sil.geometry import wellclear as wc
from daa_sil.geometry.thresholds import Thresholds

#: m/s, the largest velocity error |v - v_chord| left where a chord is used: at a boundary it moves the tau_mod
#: test by at most TTHR/2 * V_TOL = 10.5 m of |s + (TTHR/2) v| (TTHR = 35 s), under 0.1 s at 100 m/s closure;
#: DAIDALUS's own 1 deg coast segments are off by up to 0.96 m/s at 55 m/s
V_TOL = 0.6
#: m, the largest position error |p - chord| left when a piece's chord is used
P_TOL = 0.5


CLEAR, INSIDE, UNDECIDED = 0, 1, 2


def classify_pieces(x0, y0, z0, x1, y1, z1, h, th: Thresholds, e_p, e_v, e_z=0.0, window=None) -> np.ndarray:
    """CLEAR / INSIDE / UNDECIDED code (int8) of pieces of a true relative path (1-D arrays; compiled,
    :func:`classify_pieces_reference` is the same in numpy and documents the arguments)."""
    n = np.shape(h)[0]
    v = [as_vector(a, n) for a in (x0, y0, z0, x1, y1, z1, h, e_p, e_v, e_z)]
    lo, hi = (v[0], v[0]) if window is None else (as_vector(window[0], n), as_vector(window[1], n))
    out = np.empty(n, np.int8)
    D = float(th.dthr)
    kernels.get().classify_into(tuple(v[:3]), tuple(v[3:6]), v[6], tuple(v[7:10]), (lo, hi), window is not None,
                                (D, D * D, float(th.zthr), float(th.tthr), float(th.tcoa)), out)
    return out


@in_cache_blocks
def classify_pieces_reference(x0, y0, z0, x1, y1, z1, h, th: Thresholds, e_p, e_v, e_z=0.0, window=None) -> np.ndarray:
    """CLEAR / INSIDE / UNDECIDED code (int8) of pieces of a true relative path.

    A piece runs from relative position ``(x0, y0, z0)`` to ``(x1, y1, z1)`` in ``h`` s; at every instant
    the true path is within ``e_p`` (horizontal position), ``e_z`` (altitude) and ``e_v`` (horizontal
    velocity) of the chord (arrays or scalars). CLEAR: no instant of the true path violates ``th``;
    INSIDE: every instant does; UNDECIDED otherwise. Both verdicts are guaranteed for TCOA = 0: the
    tau_mod test is used in the form ``|s + (TTHR/2) v| <= sqrt(DTHR^2 + (TTHR/2)^2 |v|^2)`` with
    ``s.v < 0`` and ``|s x v| <= DTHR |v|`` (d_cpa), each bounded on the piece (``docs/daa.md``).
    ``window`` = ``(lo, hi)``: the pieces' exact vertical windows (s from the piece start) when the
    caller knows them.
    """
    D, H, TT = th.dthr, th.zthr, th.tthr
    half = 0.5 * TT
    inv = 1.0 / np.where(h > 0, h, 1.0)
    if window is None:
        lo, hi = wc.vertical_window(z0, (z1 - z0) * inv, 0.0, h, H + e_z, th.tcoa)
    else:
        lo, hi = window
    vert_any = lo <= hi
    lo = np.where(vert_any, lo, 0.0)
    hi = np.where(vert_any, hi, 0.0)
    # -- clear: the chord, inflated by the error bounds, meets neither the DTHR circle nor the tau_mod
    #    circle on its vertical window, or the tau_mod part is excluded by d_cpa or by never closing
    vx, vy = (x1 - x0) * inv, (y1 - y0) * inv
    vv = vx * vx + vy * vy
    pv = x0 * vx + y0 * vy
    pp = x0 * x0 + y0 * y0
    tau0 = -pv / np.where(vv > 1e-18, vv, np.inf)
    tau = np.minimum(np.maximum(tau0, lo), hi)
    near_d = pp + tau * (2.0 * pv + tau * vv) <= (D + e_p) ** 2  # min |p|^2 on the window
    qv = pv + half * vv
    qq = pp + half * (pv + qv)  # |p + (TT/2) v|^2 at the start
    tau = np.minimum(np.maximum(tau0 - half, lo), hi)
    speed = np.sqrt(vv)
    rho_out = np.sqrt(D * D + (half * (speed + e_v)) ** 2) + e_p + half * e_v
    near_tau = qq + tau * (2.0 * qv + tau * vv) <= rho_out * rho_out
    rmax = np.sqrt(np.maximum(pp, x1 * x1 + y1 * y1))
    slack = e_p * (speed + e_v) + rmax * e_v  # >= |s x v - s_c x v_c| and |s.v - s_c.v_c|
    cross = np.abs(x0 * vy - y0 * vx)  # |s_c x v_c|, constant along the chord
    wide = cross - slack > D * (speed + e_v)  # d_cpa > DTHR everywhere on the true path
    opening = pv - slack >= 0  # never closing on the true path (s_c.v_c grows along the chord)
    maybe = vert_any & (near_d | (near_tau & ~wide & ~opening))
    code = maybe.astype(np.int8) * UNDECIDED
    # -- inside: the chord, deflated by the error bounds, violates throughout [0, h] -------------------
    cand = maybe & (h > 0)
    count = int(np.count_nonzero(cand))
    if count == 0:
        return code
    idx = np.flatnonzero(cand) if count < 0.5 * cand.size else None  # few candidates: only those rows
    g = (lambda a: a) if idx is None else (lambda a: a[idx] if np.ndim(a) else a)  # noqa: E731
    rmax, e_p, e_v, e_z, z0, z1 = g(rmax), g(e_p), g(e_v), g(e_z), g(z0), g(z1)
    inside = rmax <= D - e_p
    if TT > 0:
        speed, qq, qv, vv, h, pv, cross, slack = g(speed), g(qq), g(qv), g(vv), g(h), g(pv), g(cross), g(slack)
        slow = np.maximum(speed - e_v, 0.0)
        rho_in = np.sqrt(D * D + (half * slow) ** 2) - e_p - half * e_v
        q1 = qq + h * (2.0 * qv + h * vv)
        sv1 = pv + h * vv  # s_c . v_c at the end of the chord
        inside |= ((np.maximum(qq, q1) <= np.where(rho_in > 0, rho_in * rho_in, -1.0))
                   & (cross + slack <= D * slow) & (sv1 + slack < 0))
    inside &= np.maximum(np.abs(z0), np.abs(z1)) <= H - e_z
    if idx is None:
        inside &= cand
        return code - inside.astype(np.int8)  # UNDECIDED - 1 = INSIDE
    code[idx] -= inside.astype(np.int8)
    return code


def _quad_range(c0, c1, c2, lo, hi):
    """(min, max) of ``c0 + c1 t + c2 t^2`` over ``t`` in ``[lo, hi]`` (elementwise, lo <= hi)."""
    f_lo = c0 + lo * (c1 + lo * c2)
    f_hi = c0 + hi * (c1 + hi * c2)
    mn, mx = np.minimum(f_lo, f_hi), np.maximum(f_lo, f_hi)
    with np.errstate(divide="ignore", invalid="ignore"):
        tv = -c1 / (2.0 * c2)
        mid = (tv > lo) & (tv < hi)
        fv = c0 + tv * (c1 + tv * c2) if np.any(mid) else None
    if fv is not None:
        mn = np.where(mid, np.minimum(mn, fv), mn)
        mx = np.where(mid, np.maximum(mx, fv), mx)
    return mn, mx


def _line_min2(ax, ay, bx, by, lo, hi):
    """Smallest ``|a + t b|^2`` for ``t`` in ``[lo, hi]`` (2-D, elementwise)."""
    bb = bx * bx + by * by
    ab = ax * bx + ay * by
    t = np.minimum(np.maximum(-ab / np.where(bb > 1e-18, bb, np.inf), lo), hi)
    return ax * ax + ay * ay + t * (2.0 * ab + t * bb)


def clear_second_order(x0, y0, z0, x1, y1, z1, u0x, u0y, u1x, u1y, h, th: Thresholds, e_p, e_v, e_z=0.0) -> np.ndarray:
    """Second-order CLEAR certificate (1-D arrays; compiled, :func:`clear_second_order_reference` is the
    same in numpy and documents it)."""
    n = np.shape(h)[0]
    out = np.empty(n, bool)
    D = float(th.dthr)
    c = [as_vector(a, n) for a in (x0, y0, z0, x1, y1, z1, u0x, u0y, u1x, u1y, h, e_p, e_v, e_z)]
    kernels.get().clear2_into(tuple(c[0:3]), tuple(c[3:6]), tuple(c[6:8]), tuple(c[8:10]), c[10], tuple(c[11:14]),
                              (D, D * D, float(th.zthr), float(th.tthr), float(th.tcoa)), out)
    return out


@in_cache_blocks
def clear_second_order_reference(x0, y0, z0, x1, y1, z1, u0x, u0y, u1x, u1y, h, th: Thresholds, e_p, e_v,
                                 e_z=0.0) -> np.ndarray:
    """True where a piece is certified CLEAR with a second-order model: the chord for position and the
    line between the true end velocities ``u0``, ``u1`` for the horizontal velocity, the true path within
    ``e_p`` / ``e_z`` (position) and ``e_v`` (velocity, ``|d^2v/dt^2| h^2 / 8``) of it. Much tighter than
    :func:`classify_pieces` on short pieces, used where a clip of the volume must be excluded."""
    D, H, TT = th.dthr, th.zthr, th.tthr
    half = 0.5 * TT
    inv = 1.0 / np.where(h > 0, h, 1.0)
    lo, hi = wc.vertical_window(z0, (z1 - z0) * inv, 0.0, h, H + e_z, th.tcoa)
    vert = lo <= hi
    lo, hi = np.where(vert, lo, 0.0), np.where(vert, hi, 0.0)
    wx, wy = (x1 - x0) * inv, (y1 - y0) * inv
    bx, by = (u1x - u0x) * inv, (u1y - u0y) * inv
    near_d = _line_min2(x0, y0, wx, wy, lo, hi) <= (D + e_p) ** 2
    vmax = np.sqrt(np.maximum(u0x * u0x + u0y * u0y, u1x * u1x + u1y * u1y))
    # tau_mod part: f = |s + (TT/2) v|^2 - (TT/2)^2 |v|^2 - DTHR^2 <= 0, a quadratic in t on the model
    qx, qy, qdx, qdy = x0 + half * u0x, y0 + half * u0y, wx + half * bx, wy + half * by
    f_mn = _quad_range(qx * qx + qy * qy - half * half * (u0x * u0x + u0y * u0y) - D * D,
                       2.0 * (qx * qdx + qy * qdy) - 2.0 * half * half * (u0x * bx + u0y * by),
                       qdx * qdx + qdy * qdy - half * half * (bx * bx + by * by), lo, hi)[0]
    q_max = np.maximum(np.hypot(qx, qy), np.hypot(qx + h * qdx, qy + h * qdy))
    dq = e_p + half * e_v
    near_tau = f_mn <= 2.0 * q_max * dq + dq * dq + half * half * (2.0 * vmax * e_v + e_v * e_v)
    rmax = np.sqrt(np.maximum(x0 * x0 + y0 * y0, x1 * x1 + y1 * y1))
    slack = e_p * (vmax + e_v) + rmax * e_v
    # d_cpa > DTHR everywhere: |s x v| > DTHR |v|; s x v is quadratic on the model and |v| is below the
    # line between its end values (a norm is convex), so check c(t) - DTHR * l(t) > slack + DTHR e_v
    c0, c1, c2 = x0 * u0y - y0 * u0x, wx * u0y - wy * u0x + x0 * by - y0 * bx, wx * by - wy * bx
    f_mn, f_mx = _quad_range(c0, c1, c2, lo, hi)
    sgn = np.where(f_mn > 0, 1.0, np.where(f_mx < 0, -1.0, 0.0))  # 0: s x v changes sign, d_cpa reaches 0
    n0, n1 = np.hypot(u0x, u0y), np.hypot(u1x, u1y)
    hs = np.where(h > 0, h, 1.0)
    m_mn = _quad_range(sgn * c0 - D * n0, sgn * c1 - D * (n1 - n0) / hs, sgn * c2, lo, hi)[0]
    wide = (sgn != 0) & (m_mn > slack + D * e_v)
    g_mn = _quad_range(x0 * u0x + y0 * u0y, wx * u0x + wy * u0y + x0 * bx + y0 * by, wx * bx + wy * by, lo, hi)[0]
    opening = g_mn - slack >= 0  # never closing on the window
    return ~vert | ~(near_d | (near_tau & ~wide & ~opening))


def settle_time(acc_h, acc_v) -> np.ndarray:
    """Longest piece duration (s) whose chord is within V_TOL / P_TOL of the true path, for horizontal
    and vertical accelerations ``acc_h``, ``acc_v`` (m/s^2)."""
    with np.errstate(divide="ignore"):
        t_v = np.where(acc_h > 0, 2.0 * V_TOL / np.where(acc_h > 0, acc_h, 1.0), np.inf)
        a = np.maximum(acc_h, acc_v)
        t_p = np.where(a > 0, np.sqrt(8.0 * P_TOL / np.where(a > 0, a, 1.0)), np.inf)
    return np.minimum(t_v, t_p)
