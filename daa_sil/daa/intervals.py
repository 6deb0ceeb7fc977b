"""Closed-form well-clear violation intervals on component arrays.

The kernel the trajectory evaluator (:mod:`daa_sil.daa.trajectory`) calls for every straight tail:
the same numbers as :func:`daa_sil.geometry.wellclear.violation_interval`. :func:`interval_soa` and
:func:`wcv_soa` run compiled (:mod:`daa_sil.daa.kernels`); the numpy versions ``*_reference`` are
their test oracles. Times in s from now; no violation is ``(inf, -inf)``.
"""

from __future__ import annotations

import numpy as np

from daa_sil.daa import kernels
from daa_sil.geometry import wellclear as wc
from daa_sil.geometry.thresholds import Thresholds

#: elements per pass of the elementwise kernels (their temporaries then stay in the CPU cache)
KERNEL_BLOCK = 16384


def in_cache_blocks(fn):
    """Run an elementwise kernel of 1-D arrays in pieces of KERNEL_BLOCK elements (its temporaries then
    stay in the CPU cache; the kernels are memory-bound and about 3x faster so). Array arguments (also
    inside tuples) of the length of the first one are sliced, others passed as they are."""
    def cut(a, sl, n):
        if isinstance(a, np.ndarray) and a.ndim == 1 and a.shape[0] == n:
            return a[sl]
        if isinstance(a, tuple):
            return tuple(cut(b, sl, n) for b in a)
        return a

    def run(*args, **kw):
        n = args[0].shape[0] if args[0].ndim == 1 else 0
        if n <= KERNEL_BLOCK:
            return fn(*args, **kw)
        parts = [fn(*(cut(a, sl, n) for a in args), **{k: cut(v, sl, n) for k, v in kw.items()})
                 for sl in (slice(i, i + KERNEL_BLOCK) for i in range(0, n, KERNEL_BLOCK))]
        if isinstance(parts[0], tuple):
            return tuple(np.concatenate(c) for c in zip(*parts))
        return np.concatenate(parts)
    run.__doc__, run.__name__, run.__wrapped__ = fn.__doc__, fn.__name__, fn
    return run


def row_blocks(n: int, per_row: int):
    """Slices of ``n`` encounter rows, each slice holding about KERNEL_BLOCK elements (``per_row`` per row)."""
    step = max(1, KERNEL_BLOCK // max(per_row, 1))
    return [slice(i, min(i + step, n)) for i in range(0, n, step)]


def as_vector(a, n: int) -> np.ndarray:
    """``a`` as a 1-D float array of length ``n`` (a scalar or a length-1 array broadcast, not copied)."""
    a = np.asarray(a, dtype=float)
    if a.shape == (n,):
        return a
    return a.reshape(1) if n == 1 and a.size == 1 else np.broadcast_to(a, (n,))  # (reshape: cheaper at N = 1)


def interval_soa(sx, sy, sz, vx, vy, vz, length, th: Thresholds, window=None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`daa_sil.geometry.wellclear.violation_interval` over ``[0, length]`` for 1-D component arrays
    (compiled; :func:`interval_soa_reference` is the same in numpy). ``window`` = the vertical window
    ``(lo, hi)`` when the caller has it."""
    n = np.shape(sx)[0]
    v = [as_vector(a, n) for a in (sx, sy, sz, vx, vy, vz, length)]
    lo, hi = (v[0], v[0]) if window is None else (as_vector(window[0], n), as_vector(window[1], n))
    t_in, t_out = np.empty(n), np.empty(n)
    D = float(th.dthr)
    kernels.get().interval_into(tuple(v[:6]), v[6], (lo, hi), window is not None,
                                (D, D * D, D ** 2, float(th.tthr), float(th.zthr), float(th.tcoa)), (t_in, t_out))
    return t_in, t_out


@in_cache_blocks
def interval_soa_reference(sx, sy, sz, vx, vy, vz, length, th: Thresholds, window=None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`daa_sil.geometry.wellclear.violation_interval` over ``[0, length]`` for 1-D component arrays.

    The same window functions (:func:`~daa_sil.geometry.wellclear.vertical_window`,
    :func:`~daa_sil.geometry.wellclear.horizontal_window`), so the results are identical; it is faster because (1) the components are contiguous arrays instead of strided views of ``(..., 3)`` arrays
    and (2) the horizontal part, which is most of the work, runs only where the vertical window is
    not empty (elsewhere the answer is ``(inf, -inf)`` in both). ``window`` = the vertical window
    ``(lo, hi)`` when the caller has it.
    """
    n = sx.shape[0]
    D, H, TT, TC = th.dthr, th.zthr, th.tthr, th.tcoa
    # -- vertical window (wellclear.violation_interval, t0 = 0, t1 = length) --------------------
    vlo, vhi = wc.vertical_window(sz, vz, 0.0, length, H, TC) if window is None else window
    ok = vlo <= vhi
    count = int(np.count_nonzero(ok))
    if count == 0:
        return np.full(n, np.inf), np.full(n, -np.inf)
    if count < 0.75 * n:  # sparse: gather the rows with a vertical window
        idx = np.flatnonzero(ok)
        t_lo = vlo[idx]
        L = vhi[idx] - t_lo
        hx, hy, qx, qy, qz, wz = vx[idx], vy[idx], sx[idx], sy[idx], sz[idx], vz[idx]
    else:  # dense: every row (those without a window are masked at the end)
        idx = None
        t_lo = np.where(ok, vlo, 0.0)
        L = np.where(ok, vhi - t_lo, 0.0)
        hx, hy, qx, qy, qz, wz = vx, vy, sx, sy, sz, vz
    # -- horizontal interval on [0, L] from p = s + t_lo v, only inside the vertical window -------
    px = qx + t_lo * hx
    py = qy + t_lo * hy
    hlo, hhi = wc.horizontal_window(px, py, hx, hy, L, D, TT)
    point = L == 0
    if idx is None:
        point &= ok
    if np.any(point):  # a single-instant vertical window: the predicate there (as DAIDALUS does)
        j = np.flatnonzero(point)
        p3 = np.stack([px[j], py[j], qz[j] + t_lo[j] * wz[j]], axis=-1)
        at = wc.wcv(p3, np.stack([hx[j], hy[j], wz[j]], axis=-1), th)
        hlo[j] = np.where(at, 0.0, np.inf)
        hhi[j] = np.where(at, 0.0, -np.inf)
    good = hlo <= hhi
    if idx is None:
        good &= ok
        return np.where(good, hlo + t_lo, np.inf), np.where(good, hhi + t_lo, -np.inf)
    t_in = np.full(n, np.inf)
    t_out = np.full(n, -np.inf)
    t_in[idx] = np.where(good, hlo + t_lo, np.inf)
    t_out[idx] = np.where(good, hhi + t_lo, -np.inf)
    return t_in, t_out


def filtered_interval(s, v, th: Thresholds, length) -> tuple[np.ndarray, np.ndarray]:
    """:func:`daa_sil.geometry.wellclear.violation_interval` over ``[0, length]`` for relative positions ``s``
    and velocities ``v`` (``(..., 3)``, broadcast together), via :func:`interval_soa`."""
    shape = np.broadcast_shapes(s.shape[:-1], v.shape[:-1], np.shape(length))
    comp = [np.ascontiguousarray(np.broadcast_to(a[..., i], shape)).ravel() for a in (s, v) for i in range(3)]
    t_in, t_out = interval_soa(*comp, np.ascontiguousarray(np.broadcast_to(length, shape)).ravel(), th)
    return t_in.reshape(shape), t_out.reshape(shape)


def wcv_soa(sx, sy, sz, vx, vy, vz, th: Thresholds) -> np.ndarray:
    """:func:`daa_sil.geometry.wellclear.wcv` on 1-D component arrays (relative position m, velocity
    m/s), compiled; :func:`wcv_soa_reference` is the same in numpy."""
    n = np.shape(sx)[0]
    out = np.empty(n, bool)
    D = float(th.dthr)
    kernels.get().wcv_soa_into(*(as_vector(a, n) for a in (sx, sy, sz, vx, vy, vz)), D * D, float(th.tthr),
                               float(th.zthr), float(th.tcoa), out)
    return out


@in_cache_blocks
def wcv_soa_reference(sx, sy, sz, vx, vy, vz, th: Thresholds) -> np.ndarray:
    """:func:`daa_sil.geometry.wellclear.wcv` on component arrays (relative position and velocity)."""
    D, TT = th.dthr, th.tthr
    r2 = sx * sx + sy * sy
    sv = sx * vx + sy * vy
    vv = vx * vx + vy * vy
    dcpa2 = r2 - sv * sv / np.where(vv > 0, vv, np.inf)
    horiz = (r2 <= D * D) | ((sv < 0) & (dcpa2 <= D * D) & (D * D - r2 >= TT * sv))
    vert = np.abs(sz) <= th.zthr
    if th.tcoa > 0:
        with np.errstate(divide="ignore", invalid="ignore"):
            tcoa = -sz / np.where(np.abs(vz) > 1e-12, vz, np.inf)
        vert |= (np.abs(vz) > 1e-12) & (sz * vz <= 0) & (tcoa <= th.tcoa)
    return horiz & vert


def relative_at_knots(pos, vel, t, ipos: np.ndarray, ivel: np.ndarray, shape) -> tuple[list, list]:
    """Relative position and velocity (ownship minus intruder; m, m/s) at the knots, three contiguous
    ``shape`` = ``(N, M, P, K)`` arrays each, from the ownship's knot positions / velocities ``pos``/``vel``
    (component arrays broadcastable to ``(N, P, K)``), knot times ``t`` (s, broadcastable to ``(N, P, K)``)
    and straight-line intruders at ``ipos`` with ``ivel`` ``(N, M, 3)`` at time 0 (compiled;
    :func:`relative_at_knots_reference` is the same in numpy)."""
    n, m, p, k = shape

    def b(a):  # (N, P, K) float64 (broadcast only when it is not that already)
        a = np.asarray(a, float)
        return a if a.shape == (n, p, k) else np.broadcast_to(a, (n, p, k))
    s, v = [np.empty(shape) for _ in range(3)], [np.empty(shape) for _ in range(3)]
    kernels.get().relative_knots_into(*(b(c) for c in pos), *(b(c) for c in vel), b(t), np.asarray(ipos, float),
                                      np.asarray(ivel, float), *s, *v)
    return s, v


def relative_at_knots_reference(pos, vel, t, ipos: np.ndarray, ivel: np.ndarray, shape) -> tuple[list, list]:
    """:func:`relative_at_knots` in numpy (its test oracle)."""
    ip = [ipos[..., i][:, :, None, None] for i in range(3)]
    iv = [ivel[..., i][:, :, None, None] for i in range(3)]
    t4 = np.broadcast_to(np.asarray(t, float), shape[:1] + shape[2:])[:, None]
    s = [np.asarray(pos[i])[:, None] - (ip[i] + t4 * iv[i]) for i in range(3)]
    s = [c if c.shape == shape else np.ascontiguousarray(np.broadcast_to(c, shape)) for c in s]
    v = [np.ascontiguousarray(np.broadcast_to(np.asarray(vel[i])[:, None] - iv[i], shape)) for i in range(3)]
    return s, v
