"""Scalar forms of the well-clear windows and predicates, compiled into the kernels.

Each function is the per-element form of a numpy function, with the same operations in the same
order (so the same rounding); the numpy function named in each docstring is its reference. Python
scalars the reference computes with Python arithmetic (``D * D``, ``dthr ** 2``) are passed in
precomputed by the caller, never recomputed here.
"""

from __future__ import annotations

import math

from daa_sil.daa.kernels.jit import inline

INF = math.inf
#: wellclear._EPS
EPS = 1e-12


@inline
def halve(a, b, mid, same, k, mixed, flag, n_in, n_out):
    """Halving ``k`` of a bisection bracket ``[a, b]`` (s) at ``mid``: ``same`` when the predicate at ``mid``
    equals the one at ``a`` (``flag``). With ``mixed`` a bracket starting inside halves only ``n_out``
    times and one starting outside ``n_in`` times (as when the two kinds are bisected apart)."""
    if mixed and k >= (n_out if flag else n_in):
        return a, b
    if same:
        return mid, b
    return a, mid


@inline
def npmax(a, b):
    """``np.maximum`` of two floats (nan if either is nan)."""
    if a != a:
        return a
    if b != b:
        return b
    return a if a >= b else b


@inline
def npmin(a, b):
    """``np.minimum`` of two floats (nan if either is nan)."""
    if a != a:
        return a
    if b != b:
        return b
    return a if a <= b else b


@inline
def npsign(x):
    """``np.sign`` of a float."""
    if x > 0.0:
        return 1.0
    if x < 0.0:
        return -1.0
    if x == 0.0:
        return 0.0
    return x


@inline
def vertical_toward(z0, vs0, tgt, v_acc, dt):
    """``kinematics.vertical_toward`` of one element: altitude (m) and vertical speed (m/s) after ``dt`` s
    moving toward ``tgt`` (m/s) at |acceleration| ``v_acc`` (m/s^2)."""
    dv = tgt - vs0
    if v_acc > 0:
        t1 = npmin(abs(dv) / v_acc, dt)
    else:
        t1 = 0.0 if dv == 0 else dt
    a = npsign(dv) * v_acc
    vs1 = vs0 + a * t1
    z = z0 + vs0 * t1 + 0.5 * a * t1 * t1 + vs1 * (dt - t1)
    return z, (tgt if abs(dv) <= v_acc * dt else vs1)


@inline
def vertical_window(sz, vz, t0, t1, zthr, tcoa):
    """:func:`daa_sil.geometry.wellclear.vertical_window` -> (lo, hi)."""
    avz = abs(vz)
    vz0 = avz < EPS
    vz_s = 1.0 if vz0 else vz
    sgn = npsign(vz_s)
    if vz0:
        inside_z = abs(sz) <= zthr
        return (t0 if inside_z else INF), (t1 if inside_z else -INF)
    t_ent = (-sgn * npmax(zthr, avz * tcoa) - sz) / vz_s
    t_ext = (sgn * zthr - sz) / vz_s
    return npmax(t0, t_ent), npmin(t1, t_ext)


@inline
def horizontal_window(px, py, vx, vy, length, D, DD, TT):
    """:func:`daa_sil.geometry.wellclear.horizontal_window` -> (lo, hi); ``DD`` = ``D * D``."""
    a = vx * vx + vy * vy
    p2 = px * px + py * py
    pv = px * vx + py * vy
    moving = a >= EPS
    a_s = a if moving else 1.0
    inside_d = p2 <= DD
    if inside_d:
        if not moving:
            return 0.0, length
        t_cexit = (-pv + math.sqrt(npmax(pv * pv - a * (p2 - DD), 0.0))) / a_s
        return 0.0, npmin(length, t_cexit)
    if not moving or not (pv < 0):
        return INF, -INF
    b = 2.0 * pv + TT * a
    c = p2 + TT * pv - DD
    disc = b * b - 4.0 * a * c
    t_tau = (-b - math.sqrt(npmax(disc, 0.0))) / (2.0 * a_s)
    cr = px * vy - py * vx
    delta = DD * a - cr * cr
    if disc >= 0 and delta >= 0 and t_tau <= length:
        t_cexit = (-pv + math.sqrt(npmax(pv * pv - a * (p2 - DD), 0.0))) / a_s
        return npmax(0.0, t_tau), npmin(length, t_cexit)
    return INF, -INF


@inline
def wcv(sx, sy, sz, vx, vy, vz, D, D2, TT, H, TC):
    """:func:`daa_sil.geometry.wellclear.wcv` of one relative state; ``D2`` = ``dthr ** 2`` (Python)."""
    r = math.hypot(sx, sy)
    sv = sx * vx + sy * vy
    tau = (D2 - r * r) / (sv if sv < 0 else -1.0)
    a = vx * vx + vy * vy
    t = -sv / a if a > EPS else 0.0
    dcpa = math.hypot(sx + t * vx, sy + t * vy)
    horiz = (r <= D) or ((dcpa <= D) and (sv < 0) and (tau <= TT))
    big = abs(vz) > EPS
    tcoa = -sz / (vz if big else 1.0)
    vert = (abs(sz) <= H) or (big and (sz * vz <= 0) and (tcoa <= TC))
    return horiz and vert


@inline
def wcv_soa(sx, sy, sz, vx, vy, vz, DD, TT, H, TC):
    """:func:`daa_sil.daa.intervals.wcv_soa_reference` of one relative state; ``DD`` = ``D * D``."""
    r2 = sx * sx + sy * sy
    sv = sx * vx + sy * vy
    vv = vx * vx + vy * vy
    dcpa2 = r2 - sv * sv / (vv if vv > 0 else INF)
    horiz = (r2 <= DD) or ((sv < 0) and (dcpa2 <= DD) and (DD - r2 >= TT * sv))
    if not horiz:
        return False
    vert = abs(sz) <= H
    if TC > 0 and not vert:
        big = abs(vz) > 1e-12
        tcoa = -sz / (vz if big else INF)
        vert = big and (sz * vz <= 0) and (tcoa <= TC)
    return vert


@inline
def interval(sx, sy, sz, vx, vy, vz, length, vlo, vhi, D, DD, D2, TT, H, TC):
    """:func:`daa_sil.daa.intervals.interval_soa_reference` of one straight line given its vertical window
    ``[vlo, vhi]`` -> (t_in, t_out)."""
    if not (vlo <= vhi):
        return INF, -INF
    t_lo = vlo
    L = vhi - t_lo
    px = sx + t_lo * vx
    py = sy + t_lo * vy
    if L == 0:  # a single-instant vertical window: the predicate there
        if wcv(px, py, sz + t_lo * vz, vx, vy, vz, D, D2, TT, H, TC):
            return 0.0 + t_lo, 0.0 + t_lo
        return INF, -INF
    hlo, hhi = horizontal_window(px, py, vx, vy, L, D, DD, TT)
    if hlo <= hhi:
        return hlo + t_lo, hhi + t_lo
    return INF, -INF
