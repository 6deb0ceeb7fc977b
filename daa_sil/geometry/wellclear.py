"""DO-365 well clear, tau_mod, HMD, the exact time interval of violation and NMAC, vectorised over any
leading batch shape (the penetration integral over a violation is :mod:`daa_sil.geometry.penetration`).

Conventions (the definitions are stated in docs/daa.md, "Well clear and alert levels"):

* ``s`` and ``v`` are *relative* position and velocity, **ownship minus intruder**, arrays of
  shape ``(..., 3)`` in ENU metres and m/s (x east, y north, z up). Every quantity here is
  symmetric under ``(s, v) -> (-s, -v)``, so the sign convention only matters for display.
* "Undefined" results are ``nan`` (e.g. tau_mod while diverging outside DMOD); an empty time
  interval is ``(+inf, -inf)``.
* Boundaries are closed (``<=``), as in DAIDALUS' WCV detectors.

The violation interval is the closed form of DAIDALUS ``WCV_tvar.WCV_interval`` (vertical window
first, then the horizontal tau_mod/DMOD interval inside it). The violation set along a straight
line is a single interval (PVS lemma ``WCV_locally_convex``), so two endpoints describe it exactly.
"""

from __future__ import annotations

import numpy as np

from daa_sil.config.settings import STEP
from daa_sil.runtime.compiled import loaded_kernels
from .thresholds import Thresholds, get_thresholds

_EPS = 1e-12


def _f(a):
    return np.asarray(a, dtype=float)


def relative(own_pos, own_vel, intr_pos, intr_vel) -> tuple[np.ndarray, np.ndarray]:
    """Relative state ``(s, v)`` = ownship minus intruder, each ``(..., 3)``."""
    return _f(own_pos) - _f(intr_pos), _f(own_vel) - _f(intr_vel)


def horizontal_range(s) -> np.ndarray:
    """Horizontal range ``r = |s_xy|``, m."""
    s = _f(s)
    return np.hypot(s[..., 0], s[..., 1])


def _sv(s, v):
    return s[..., 0] * v[..., 0] + s[..., 1] * v[..., 1]


def _vv(v):
    return v[..., 0] ** 2 + v[..., 1] ** 2


def range_rate(s, v) -> np.ndarray:
    """Horizontal range rate ``(s.v)/r``, m/s (negative = closing; nan at r = 0)."""
    s, v = _f(s), _f(v)
    r = horizontal_range(s)
    with np.errstate(all="ignore"):
        return np.where(r > 0, _sv(s, v) / np.where(r > 0, r, 1.0), np.nan)


def t_cpa(s, v) -> np.ndarray:
    """Time to horizontal closest point of approach ``-(s.v)/|v|^2``, s (0 if no relative motion).

    Negative when the CPA is in the past (diverging).
    """
    s, v = _f(s), _f(v)
    a = _vv(v)
    return np.where(a > _EPS, -_sv(s, v) / np.where(a > _EPS, a, 1.0), 0.0)


def d_cpa(s, v) -> np.ndarray:
    """Horizontal distance at CPA with the (unclipped) t_cpa, m; used by the WCV test."""
    s, v = _f(s), _f(v)
    t = t_cpa(s, v)
    return np.hypot(s[..., 0] + t * v[..., 0], s[..., 1] + t * v[..., 1])


def hmd(s, v, lookahead: float = np.inf) -> np.ndarray:
    """Horizontal miss distance within ``lookahead`` s: the range at ``clip(t_cpa, 0, lookahead)``.

    Equals the current range when diverging (DAIDALUS ``Horizontal.hmd``).
    """
    s, v = _f(s), _f(v)
    t = np.clip(t_cpa(s, v), 0.0, lookahead)
    return np.hypot(s[..., 0] + t * v[..., 0], s[..., 1] + t * v[..., 1])


def tau_mod(s, v, dmod: float) -> np.ndarray:
    """DO-365 modified tau, s: ``(DMOD^2 - r^2)/(s.v)`` while closing, 0 inside DMOD, nan otherwise."""
    s, v = _f(s), _f(v)
    r = horizontal_range(s)
    sv = _sv(s, v)
    with np.errstate(all="ignore"):
        closing = (dmod * dmod - r * r) / np.where(sv < 0, sv, -1.0)
    return np.where(r <= dmod, 0.0, np.where(sv < 0, closing, np.nan))


def t_coa(s, v) -> np.ndarray:
    """Time to co-altitude ``-s_z/v_z``, s: 0 at co-altitude, nan when not converging vertically."""
    s, v = _f(s), _f(v)
    sz, vz = s[..., 2], v[..., 2]
    conv = (sz * vz < 0) & (np.abs(vz) > _EPS)
    with np.errstate(all="ignore"):
        t = -sz / np.where(conv, vz, 1.0)
    return np.where(sz == 0, 0.0, np.where(conv, t, np.nan))


def vmd(s, v, lookahead: float = np.inf) -> np.ndarray:
    """Vertical miss distance within ``lookahead`` s (DAIDALUS ``Vertical.vmd``), m."""
    s, v = _f(s), _f(v)
    sz, vz = s[..., 2], v[..., 2]
    tc = t_coa(s, v)
    conv = sz * vz < 0
    return np.where(conv, np.where(tc <= lookahead, 0.0, np.abs(sz + lookahead * vz)), np.abs(sz))


def wcv(s, v, th: "Thresholds | str | None" = None) -> np.ndarray:
    """Instantaneous well-clear violation (DO-365 / paper Eq. 9 conditions), bool.

    Horizontal: ``r <= DTHR`` or (``d_cpa <= DTHR`` and ``0 <= tau_mod <= TTHR``).
    Vertical:   ``|s_z| <= ZTHR`` or (converging and ``t_coa <= TCOA``). WCV = both.
    """
    th = get_thresholds(th)
    s, v = _f(s), _f(v)
    r = horizontal_range(s)
    sv = _sv(s, v)
    with np.errstate(all="ignore"):
        tau = (th.dthr ** 2 - r * r) / np.where(sv < 0, sv, -1.0)
    horiz = (r <= th.dthr) | ((d_cpa(s, v) <= th.dthr) & (sv < 0) & (tau <= th.tthr))
    sz, vz = s[..., 2], v[..., 2]
    with np.errstate(all="ignore"):
        tcoa = -sz / np.where(np.abs(vz) > _EPS, vz, 1.0)
    vert = (np.abs(sz) <= th.zthr) | ((np.abs(vz) > _EPS) & (sz * vz <= 0) & (tcoa <= th.tcoa))
    return horiz & vert


def encounter_geometry(s, v, th: "Thresholds | str | None" = None, lookahead: float = np.inf) -> dict:
    """Per relative state (``s``, ``v`` of one shape ``(..., 3)``): ``range_m`` (:func:`horizontal_range`),
    ``hmd_m`` (:func:`hmd` within ``lookahead`` s), ``dh_m`` (``-s_z``), ``tau_mod_s`` (:func:`tau_mod` with
    DMOD = DTHR) and ``wcv`` (:func:`wcv`) of thresholds ``th``: one compiled pass where the process has the
    kernels (:mod:`daa_sil.runtime.compiled`), else :func:`encounter_geometry_reference` (the same numbers)."""
    th = get_thresholds(th)
    s, v = _f(s), _f(v)
    k = loaded_kernels()
    if k is None or s.shape != v.shape:
        return encounter_geometry_reference(s, v, th, lookahead)
    shape = s.shape[:-1]
    out = {name: np.empty(shape) for name in ("range_m", "hmd_m", "dh_m", "tau_mod_s")}
    out["wcv"] = np.empty(shape, bool)
    D = float(th.dthr)
    k.geometry_into(tuple(a[..., i].reshape(-1) for a in (s, v) for i in range(3)),
                    (float(lookahead), D, D * D, D, th.dthr ** 2, float(th.tthr), float(th.zthr), float(th.tcoa)),
                    tuple(out[n].reshape(-1) for n in ("range_m", "hmd_m", "dh_m", "tau_mod_s", "wcv")))
    return out


def encounter_geometry_reference(s, v, th: "Thresholds | str | None" = None, lookahead: float = np.inf) -> dict:
    """:func:`encounter_geometry` from the numpy functions (the compiled kernel's reference)."""
    th = get_thresholds(th)
    return {"range_m": horizontal_range(s), "hmd_m": hmd(s, v, lookahead), "dh_m": -_f(s)[..., 2],
            "tau_mod_s": tau_mod(s, v, th.dthr), "wcv": wcv(s, v, th)}


def vertical_window(sz, vz, t0, t1, zthr: float, tcoa: float) -> tuple[np.ndarray, np.ndarray]:
    """Times ``[lo, hi]`` within ``[t0, t1]`` (s) when the vertical WCV condition holds for
    ``sz + t vz`` (m, m/s): ``|z| <= ZTHR`` or converging with ``t_coa <= TCOA``; empty if lo > hi."""
    avz = np.abs(vz)
    vz0 = avz < _EPS
    vz_s = np.where(vz0, 1.0, vz)
    sgn = np.sign(vz_s)
    t_ent = (-sgn * np.maximum(zthr, avz * tcoa) - sz) / vz_s
    t_ext = (sgn * zthr - sz) / vz_s
    inside_z = np.abs(sz) <= zthr
    lo = np.where(vz0, np.where(inside_z, t0, np.inf), np.maximum(t0, t_ent))
    hi = np.where(vz0, np.where(inside_z, t1, -np.inf), np.minimum(t1, t_ext))
    return lo, hi


def horizontal_window(px, py, vx, vy, length, dthr: float, tthr: float) -> tuple[np.ndarray, np.ndarray]:
    """Times ``[lo, hi]`` within ``[0, length]`` (s) when the horizontal WCV condition holds for
    ``p + t v`` (m, m/s): ``r <= DTHR``, or closing with ``d_cpa <= DTHR`` and ``tau_mod <= TTHR``
    (closed form, DAIDALUS ``WCV_tvar``); ``(inf, -inf)`` when it never holds."""
    D, TT = dthr, tthr
    a = vx * vx + vy * vy
    p2 = px * px + py * py
    pv = px * vx + py * vy
    moving = a >= _EPS
    a_s = np.where(moving, a, 1.0)
    inside_d = p2 <= D * D
    t_cexit = (-pv + np.sqrt(np.maximum(pv * pv - a * (p2 - D * D), 0.0))) / a_s
    b = 2.0 * pv + TT * a
    c = p2 + TT * pv - D * D
    disc = b * b - 4.0 * a * c
    t_tau = (-b - np.sqrt(np.maximum(disc, 0.0))) / (2.0 * a_s)
    delta = D * D * a - (px * vy - py * vx) ** 2
    case_a = ~moving & inside_d
    case_b = moving & inside_d
    case_c = moving & ~inside_d & (pv < 0) & (disc >= 0) & (delta >= 0) & (t_tau <= length)
    hlo = np.where(case_a | case_b, 0.0, np.where(case_c, np.maximum(0.0, t_tau), np.inf))
    hhi = np.where(case_a, length, np.where(case_b | case_c, np.minimum(length, t_cexit), -np.inf))
    return hlo, hhi


def violation_interval(s, v, th: "Thresholds | str | None" = None, t0=0.0, t1=180.0
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Exact interval ``[t_in, t_out]`` within ``[t0, t1]`` (s) during which the WCV predicate holds
    for straight-line relative motion ``s + t v``. Empty intervals are ``(+inf, -inf)``.
    """
    th = get_thresholds(th)
    s, v = _f(s), _f(v)
    shape = np.broadcast_shapes(s.shape[:-1], v.shape[:-1], np.shape(t0), np.shape(t1))
    s = s if s.shape == shape + (3,) else np.broadcast_to(s, shape + (3,))
    v = v if v.shape == shape + (3,) else np.broadcast_to(v, shape + (3,))
    B, T = _f(t0), _f(t1)  # the windows below take the shape of s and v
    D, H, TT, TC = th.dthr, th.zthr, th.tthr, th.tcoa
    sz, vz = s[..., 2], v[..., 2]

    vlo, vhi = vertical_window(sz, vz, B, T, H, TC)
    ok = vlo <= vhi
    t_lo = np.where(ok, vlo, 0.0)
    L = np.where(ok, vhi - vlo, 0.0)
    px = s[..., 0] + t_lo * v[..., 0]
    py = s[..., 1] + t_lo * v[..., 1]
    hlo, hhi = horizontal_window(px, py, v[..., 0], v[..., 1], L, D, TT)

    # a single-instant vertical window: evaluate the predicate there (as DAIDALUS does)
    point = ok & (L == 0)
    if np.any(point):
        p3 = np.stack([px, py, sz + t_lo * vz], axis=-1)
        at = wcv(p3, v, th)
        hlo = np.where(point, np.where(at, 0.0, np.inf), hlo)
        hhi = np.where(point, np.where(at, 0.0, -np.inf), hhi)

    good = ok & (hlo <= hhi)
    t_in = np.where(good, hlo + t_lo, np.inf)
    t_out = np.where(good, hhi + t_lo, -np.inf)
    return t_in, t_out


def time_to_violation(s, v, th: "Thresholds | str | None" = None, lookahead: float = 180.0) -> np.ndarray:
    """First time (s) within ``[0, lookahead]`` at which WCV holds; 0 = violating now, inf = none."""
    return violation_interval(s, v, th, 0.0, lookahead)[0]


def nmac(s, th: "Thresholds | str | None" = None) -> np.ndarray:
    """Instantaneous NMAC: horizontal separation <= nmac_h and vertical <= nmac_v (bool)."""
    th = get_thresholds(th)
    s = _f(s)
    return (horizontal_range(s) <= th.nmac_h) & (np.abs(s[..., 2]) <= th.nmac_v)


def _disc_interval(px, py, vx, vy, radius, t_end):
    """Times in [0, t_end] at which |p + t v| <= radius (2-D), as (lo, hi); empty = (inf, -inf)."""
    a = vx * vx + vy * vy
    p2 = px * px + py * py
    pv = px * vx + py * vy
    moving = a >= _EPS
    a_s = np.where(moving, a, 1.0)
    disc = pv * pv - a * (p2 - radius * radius)
    root = np.sqrt(np.maximum(disc, 0.0))
    lo = np.where(moving, (-pv - root) / a_s, np.where(p2 <= radius * radius, 0.0, np.inf))
    hi = np.where(moving, (-pv + root) / a_s, np.where(p2 <= radius * radius, t_end, -np.inf))
    hit = np.where(moving, disc >= 0, p2 <= radius * radius)
    lo = np.where(hit, np.maximum(lo, 0.0), np.inf)
    hi = np.where(hit, np.minimum(hi, t_end), -np.inf)
    return lo, hi


def _slab_interval(z, vz, half, t_end):
    """Times in [0, t_end] at which |z + t vz| <= half, as (lo, hi); empty = (inf, -inf)."""
    still = np.abs(vz) < _EPS
    vz_s = np.where(still, 1.0, vz)
    ta = (-half - z) / vz_s
    tb = (half - z) / vz_s
    lo = np.where(still, np.where(np.abs(z) <= half, 0.0, np.inf), np.maximum(np.minimum(ta, tb), 0.0))
    hi = np.where(still, np.where(np.abs(z) <= half, t_end, -np.inf), np.minimum(np.maximum(ta, tb), t_end))
    return lo, hi


def nmac_interval(s, v, th: "Thresholds | str | None" = None, t_end=1.0) -> tuple[np.ndarray, np.ndarray]:
    """Interval within ``[0, t_end]`` during which straight-line motion ``s + t v`` is an NMAC (compiled
    where the process has the kernels, :mod:`daa_sil.runtime.compiled`; else :func:`nmac_interval_reference`)."""
    th = get_thresholds(th)
    s, v = _f(s), _f(v)
    k = loaded_kernels()
    if k is not None and s.shape == v.shape and isinstance(t_end, (float, int)):
        shape = s.shape[:-1]
        lo, hi = np.empty(shape), np.empty(shape)
        k.nmac_interval_into(*(a[..., i].reshape(-1) for a in (s, v) for i in range(3)), float(th.nmac_h),
                             float(th.nmac_v), float(t_end), lo.reshape(-1), hi.reshape(-1))
        return lo, hi
    return nmac_interval_reference(s, v, th, t_end)


def nmac_interval_reference(s, v, th: "Thresholds | str | None" = None, t_end=1.0) -> tuple[np.ndarray, np.ndarray]:
    """:func:`nmac_interval` in numpy (the compiled kernel's reference)."""
    th = get_thresholds(th)
    s, v = _f(s), _f(v)
    hlo, hhi = _disc_interval(s[..., 0], s[..., 1], v[..., 0], v[..., 1], th.nmac_h, t_end)
    zlo, zhi = _slab_interval(s[..., 2], v[..., 2], th.nmac_v, t_end)
    lo, hi = np.maximum(hlo, zlo), np.minimum(hhi, zhi)
    empty = lo > hi
    return np.where(empty, np.inf, lo), np.where(empty, -np.inf, hi)


def segment_events(s0, s1, dt: float = STEP.default, th: "Thresholds | str | None" = None
                   ) -> tuple[np.ndarray, np.ndarray]:
    """LoWC and NMAC *anywhere* on the segment between two sampled relative positions ``dt`` apart.

    The relative motion between the samples is taken as the straight line from ``s0`` to ``s1``
    (relative velocity ``(s1 - s0)/dt``); for a 3 deg/s turn at 55 m/s the chord departs from the
    arc by under 0.4 m over 1 s. Returns ``(lowc, nmac)`` bool arrays; an event that happens only
    strictly between the samples is detected.
    """
    th = get_thresholds(th)
    s0, s1 = _f(s0), _f(s1)
    v = (s1 - s0) / dt
    t_in, _ = violation_interval(s0, v, th, 0.0, dt)
    n_in, _ = nmac_interval(s0, v, th, dt)
    return np.isfinite(t_in), np.isfinite(n_in)


def min_separation_on_segment(s0, s1) -> tuple[np.ndarray, np.ndarray]:
    """Minimum horizontal range on the segment ``s0 -> s1`` and the vertical separation at that time."""
    s0, s1 = _f(s0), _f(s1)
    v = s1 - s0
    t = np.clip(t_cpa(s0, v), 0.0, 1.0)
    p = s0 + t[..., None] * v
    return horizontal_range(p), np.abs(p[..., 2])
