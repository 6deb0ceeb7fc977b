"""Scalar forms of the chord certificates (:mod:`daa_sil.daa.certify`), compiled into the kernels.

Same operations in the same order as the numpy references named in each docstring.
"""

from __future__ import annotations

import math

from daa_sil.daa.kernels.jit import inline
from daa_sil.daa.kernels.scalar import INF, npmax, npmin, vertical_window

#: certify.CLEAR, INSIDE, UNDECIDED
CLEAR, INSIDE, UNDECIDED = 0, 1, 2


@inline
def classify(p0, p1, h, e_p, e_v, e_z, lo, hi, has_win, vol):
    """:func:`daa_sil.daa.certify.classify_pieces` of one piece from relative position ``p0`` to ``p1`` (each
    ``(x, y, z)``) -> CLEAR / INSIDE / UNDECIDED; ``(lo, hi)`` its vertical window when ``has_win``; ``vol`` the
    volume ``(D, D * D, H, TT, TC)``."""
    x0, y0, z0 = p0
    x1, y1, z1 = p1
    D, DD, H, TT, TC = vol
    half = 0.5 * TT
    inv = 1.0 / (h if h > 0 else 1.0)
    if not has_win:
        lo, hi = vertical_window(z0, (z1 - z0) * inv, 0.0, h, H + e_z, TC)
    if not (lo <= hi):
        return CLEAR
    vx, vy = (x1 - x0) * inv, (y1 - y0) * inv
    vv = vx * vx + vy * vy
    pv = x0 * vx + y0 * vy
    pp = x0 * x0 + y0 * y0
    tau0 = -pv / (vv if vv > 1e-18 else INF)
    tau = npmin(npmax(tau0, lo), hi)
    dp = D + e_p
    near_d = pp + tau * (2.0 * pv + tau * vv) <= dp * dp
    qv = pv + half * vv
    qq = pp + half * (pv + qv)
    speed = math.sqrt(vv)
    rmax = math.sqrt(npmax(pp, x1 * x1 + y1 * y1))
    slack = e_p * (speed + e_v) + rmax * e_v
    if not near_d:
        tau = npmin(npmax(tau0 - half, lo), hi)
        hs = half * (speed + e_v)
        rho_out = math.sqrt(DD + hs * hs) + e_p + half * e_v
        near_tau = qq + tau * (2.0 * qv + tau * vv) <= rho_out * rho_out
        if not near_tau:
            return CLEAR
        cross = abs(x0 * vy - y0 * vx)
        wide = cross - slack > D * (speed + e_v)
        opening = pv - slack >= 0
        if wide or opening:
            return CLEAR
    if not (h > 0):
        return UNDECIDED
    # -- inside: the chord, deflated by the error bounds, violates throughout [0, h]
    inside = rmax <= D - e_p
    if TT > 0:
        cross = abs(x0 * vy - y0 * vx)
        slow = npmax(speed - e_v, 0.0)
        hs = half * slow
        rho_in = math.sqrt(DD + hs * hs) - e_p - half * e_v
        q1 = qq + h * (2.0 * qv + h * vv)
        sv1 = pv + h * vv
        inside = inside or ((npmax(qq, q1) <= (rho_in * rho_in if rho_in > 0 else -1.0))
                            and (cross + slack <= D * slow) and (sv1 + slack < 0))
    inside = inside and (npmax(abs(z0), abs(z1)) <= H - e_z)
    return INSIDE if inside else UNDECIDED


@inline
def quad_min(c0, c1, c2, lo, hi):
    """``_quad_range(...)[0]`` of :mod:`daa_sil.daa.certify`: smallest ``c0 + c1 t + c2 t^2`` on [lo, hi]."""
    f_lo = c0 + lo * (c1 + lo * c2)
    f_hi = c0 + hi * (c1 + hi * c2)
    mn = npmin(f_lo, f_hi)
    tv = -c1 / (2.0 * c2)
    if (tv > lo) and (tv < hi):
        mn = npmin(mn, c0 + tv * (c1 + tv * c2))
    return mn


@inline
def quad_max(c0, c1, c2, lo, hi):
    """``_quad_range(...)[1]`` of :mod:`daa_sil.daa.certify`: largest ``c0 + c1 t + c2 t^2`` on [lo, hi]."""
    f_lo = c0 + lo * (c1 + lo * c2)
    f_hi = c0 + hi * (c1 + hi * c2)
    mx = npmax(f_lo, f_hi)
    tv = -c1 / (2.0 * c2)
    if (tv > lo) and (tv < hi):
        mx = npmax(mx, c0 + tv * (c1 + tv * c2))
    return mx


@inline
def line_min2(ax, ay, bx, by, lo, hi):
    """:func:`daa_sil.daa.certify._line_min2`: smallest ``|a + t b|^2`` for ``t`` in [lo, hi]."""
    bb = bx * bx + by * by
    ab = ax * bx + ay * by
    t = npmin(npmax(-ab / (bb if bb > 1e-18 else INF), lo), hi)
    return ax * ax + ay * ay + t * (2.0 * ab + t * bb)


@inline
def clear2(p0, p1, u0, u1, h, e_p, e_v, e_z, vol):
    """:func:`daa_sil.daa.certify.clear_second_order` of one piece -> bool (``p0``/``p1`` the relative positions
    ``(x, y, z)`` at its ends, ``u0``/``u1`` the horizontal relative velocities ``(x, y)`` there, ``vol`` as
    :func:`classify`)."""
    x0, y0, z0 = p0
    x1, y1, z1 = p1
    u0x, u0y = u0
    u1x, u1y = u1
    D, DD, H, TT, TC = vol
    half = 0.5 * TT
    inv = 1.0 / (h if h > 0 else 1.0)
    lo, hi = vertical_window(z0, (z1 - z0) * inv, 0.0, h, H + e_z, TC)
    if not (lo <= hi):
        return True
    wx, wy = (x1 - x0) * inv, (y1 - y0) * inv
    bx, by = (u1x - u0x) * inv, (u1y - u0y) * inv
    dp = D + e_p
    if line_min2(x0, y0, wx, wy, lo, hi) <= dp * dp:
        return False
    vmax = math.sqrt(npmax(u0x * u0x + u0y * u0y, u1x * u1x + u1y * u1y))
    qx, qy, qdx, qdy = x0 + half * u0x, y0 + half * u0y, wx + half * bx, wy + half * by
    hh = half * half
    hh2 = 2.0 * half * half
    f_mn = quad_min(qx * qx + qy * qy - hh * (u0x * u0x + u0y * u0y) - DD,
                    2.0 * (qx * qdx + qy * qdy) - hh2 * (u0x * bx + u0y * by),
                    qdx * qdx + qdy * qdy - hh * (bx * bx + by * by), lo, hi)
    q_max = npmax(math.hypot(qx, qy), math.hypot(qx + h * qdx, qy + h * qdy))
    dq = e_p + half * e_v
    near_tau = f_mn <= 2.0 * q_max * dq + dq * dq + hh * (2.0 * vmax * e_v + e_v * e_v)
    if not near_tau:
        return True
    rmax = math.sqrt(npmax(x0 * x0 + y0 * y0, x1 * x1 + y1 * y1))
    slack = e_p * (vmax + e_v) + rmax * e_v
    c0 = x0 * u0y - y0 * u0x
    c1 = wx * u0y - wy * u0x + x0 * by - y0 * bx
    c2 = wx * by - wy * bx
    sgn = 1.0 if quad_min(c0, c1, c2, lo, hi) > 0 else (-1.0 if quad_max(c0, c1, c2, lo, hi) < 0 else 0.0)
    n0, n1 = math.hypot(u0x, u0y), math.hypot(u1x, u1y)
    hs = h if h > 0 else 1.0
    m_mn = quad_min(sgn * c0 - D * n0, sgn * c1 - D * (n1 - n0) / hs, sgn * c2, lo, hi)
    if (sgn != 0) and (m_mn > slack + D * e_v):
        return True
    g_mn = quad_min(x0 * u0x + y0 * u0y, wx * u0x + wy * u0y + x0 * bx + y0 * by, wx * bx + wy * by, lo, hi)
    return g_mn - slack >= 0
