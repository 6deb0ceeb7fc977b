"""Conflict detection along kinematic ownship trajectories against straight-line intruders.

A *maneuver path* is the ownship flying a maneuver (turn at the turn-rate limit, accelerate at the
horizontal or vertical limit, or a multi-axis command), sampled at knot times
``t_0 = 0 < t_1 < ... < t_J``. Candidate ``k`` of the path flies the path up to knot ``k`` and then
continues straight with the knot-``k`` velocity. Two parts are evaluated:

* **tails** (straight after knot ``k``): the exact closed form of
  :func:`daa_sil.geometry.wellclear.violation_interval` (re-stated on contiguous component arrays in
  :func:`interval_soa`, identical numbers, about 2x faster);
* **the maneuver between knots** on the true trajectory (arc, parabola), not on its chords. A piece of
  duration ``h`` is within ``A h^2 / 8`` of its chord in position and ``A h / 2`` in velocity (``A`` the
  path's acceleration bound); with these bounds :func:`classify_pieces` certifies it *clear* (no
  instant of the true path violates) or *inside* (every instant does), blocks of :data:`BLOCK`
  segments first. A segment left undecided is resolved with the exact predicate on the true state
  (:meth:`PathEvaluator._resolve`): both ends violating give its first entry and last exit exactly;
  one end violating, the boundary by bisection (:data:`BISECT_DT_IN`, :data:`BISECT_DT_OUT`) with
  the other side certified clear; both ends clear, a second-order certificate
  (:func:`clear_second_order`) or, for the few it cannot clear, sampling every :data:`CLIP_DT`.

This replaces the chords of the previous version in **every preset**: a chord's velocity is wrong by
up to half a knot step (2.4 m/s for 5 deg at 55 m/s) and it missed short violations during turns
(issue 15, example 4). It is a correctness fix, not a choice of semantics, so ``do365`` and
``paper`` get it as well as ``daidalus``; their bands change only where the chords were wrong. We
also differ here from DAIDALUS, whose straight *coast* segments keep each knot's velocity for a
whole knot interval (``docs/daa.md``, "Differences from DAIDALUS we keep").

The certificates use the form ``|s + (TTHR/2) v| <= sqrt(DTHR^2 + (TTHR/2)^2 |v|^2)`` of the tau_mod
test, with d_cpa and closing bounded separately; they are exact for TCOA = 0 (every preset). Times
are absolute (s from now); no violation is ``(inf, -inf)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from daa_sil.geometry import wellclear as wc
from daa_sil.geometry.frames import wrap_2pi, wrap_pi
from daa_sil.geometry.kinematics import (_W_EPS, AircraftState, Command, _horizontal_segment, _vertical,
    fly_command)
from daa_sil.geometry.thresholds import Thresholds
from .config import DaaConfig

#: m/s, the largest velocity error |v - v_chord| left where a chord is used: at a boundary it moves the tau_mod
#: test by at most TTHR/2 * V_TOL = 10.5 m of |s + (TTHR/2) v| (TTHR = 35 s), under 0.1 s at 100 m/s closure;
#: DAIDALUS's own 1 deg coast segments are off by up to 0.96 m/s at 55 m/s
V_TOL = 0.6
#: m, the largest position error |p - chord| left when a piece's chord is used
P_TOL = 0.5
#: most parts an undecided segment is split into (as many as its parts' chords need to meet V_TOL / P_TOL)
MAX_SPLIT = 16
#: s, how closely an entry into / an exit from the volume on the true path is located (bisection brackets;
#: entries decide when a candidate conflicts, exits only rank recovery candidates)
BISECT_DT_IN = 0.04
BISECT_DT_OUT = 0.1
#: s, sampling interval of the true predicate inside a short piece whose ends are clear but which is not
#: certified clear (a clip of the volume shorter than this can be missed)
CLIP_DT = 0.01
#: most rounds of splitting an undecided piece
MAX_DEPTH = 8
#: elements per pass of the elementwise kernels (their temporaries then stay in the CPU cache)
KERNEL_BLOCK = 16384
#: knot-to-knot segments examined together first (a block far from the volume is clear as a whole)
BLOCK = 4

#: ``state_at(n, p) -> f`` with ``f(t) -> (x, y, z, vx, vy, vz)``: the true ownship state on path ``p[i]`` of
#: encounter ``n[i]`` at time ``t[i]`` (the per-path parameters are gathered once, then ``f`` is cheap)
StateAt = Callable[[np.ndarray, np.ndarray], Callable[[np.ndarray], tuple]]


def _in_blocks(fn):
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


def _row_blocks(n: int, per_row: int):
    """Slices of encounter rows holding about KERNEL_BLOCK elements of ``per_row`` each."""
    step = max(1, KERNEL_BLOCK // max(per_row, 1))
    return [slice(i, min(i + step, n)) for i in range(0, n, step)]


@_in_blocks
def interval_soa(sx, sy, sz, vx, vy, vz, length, th: Thresholds, window=None) -> tuple[np.ndarray, np.ndarray]:
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


# --------------------------------------------------------------------------------------------------
# certification of a piece of the true path against its chord
# --------------------------------------------------------------------------------------------------
CLEAR, INSIDE, UNDECIDED = 0, 1, 2


@_in_blocks
def classify_pieces(x0, y0, z0, x1, y1, z1, h, th: Thresholds, e_p, e_v, e_z=0.0, window=None) -> np.ndarray:
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


@_in_blocks
def clear_second_order(x0, y0, z0, x1, y1, z1, u0x, u0y, u1x, u1y, h, th: Thresholds, e_p, e_v, e_z=0.0) -> np.ndarray:
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


def _settle_time(acc_h, acc_v) -> np.ndarray:
    """Longest piece duration (s) whose chord is within V_TOL / P_TOL of the true path."""
    with np.errstate(divide="ignore"):
        t_v = np.where(acc_h > 0, 2.0 * V_TOL / np.where(acc_h > 0, acc_h, 1.0), np.inf)
        a = np.maximum(acc_h, acc_v)
        t_p = np.where(a > 0, np.sqrt(8.0 * P_TOL / np.where(a > 0, a, 1.0)), np.inf)
    return np.minimum(t_v, t_p)


# --------------------------------------------------------------------------------------------------
# maneuver paths
# --------------------------------------------------------------------------------------------------
@dataclass
class ManeuverPaths:
    """P maneuver paths per encounter sampled at knots, and the exact ownship state at any time.

    ``pos``/``vel`` ownship position / velocity at the knots as three component arrays (x, y, z) each
    broadcastable to ``(N, P, K)``; ``t`` knot times broadcastable to ``(N, P, K)`` (s); ``state_at(n, p)`` a function of time giving the true ownship position and
    velocity (six component arrays) on paths ``p`` of encounters ``n`` (flat index arrays, :data:`StateAt`); ``acc_h``/``acc_v`` ``(N, P)`` bounds
    on the ownship's horizontal / vertical acceleration along the path, m/s^2 (the chord of a piece of
    duration h is then within ``acc h^2 / 8`` of the path and its velocity within ``acc_h h / 2``);
    ``vz_const``: the vertical speed is the same all along every path (turns and speed changes);
    ``jerk_h``/``kink_t`` bound how far the velocity between two instants is from the line between its
    true values there (``jerk h^2 / 8``, or ``acc_h h / 2`` across a kink), used to exclude clips.
    """

    pos: tuple
    vel: tuple
    t: np.ndarray
    state_at: StateAt
    acc_h: np.ndarray
    acc_v: np.ndarray
    vz_const: bool = False
    jerk_h: "np.ndarray | None" = None  #: (N, P) bound on |d^2 v / dt^2| (m/s^3) away from kinks (None = unknown)
    kink_t: "np.ndarray | None" = None  #: (N, P) or (N, P, Q) s, times the horizontal acceleration jumps (inf = never)

    @property
    def shape(self) -> tuple[int, int, int]:
        return np.broadcast_shapes(*(np.shape(a) for a in self.pos + self.vel), np.shape(self.t),
                                   np.shape(self.acc_h) + (1,))

    def stacked(self) -> tuple[np.ndarray, np.ndarray]:
        """Position and velocity at the knots as ``(N, P, K, 3)`` arrays."""
        shape = self.shape
        return tuple(np.stack([np.broadcast_to(a, shape) for a in c], axis=-1) for c in (self.pos, self.vel))

    def knot_times(self) -> np.ndarray:
        return np.broadcast_to(np.asarray(self.t, float), self.shape)

    def subset(self, idx: np.ndarray) -> "ManeuverPaths":
        """The paths of encounters ``idx`` (state_at keeps addressing the original encounters)."""
        idx = np.asarray(idx)
        base = self.state_at
        sub = lambda a: None if a is None else a[idx]  # noqa: E731
        return ManeuverPaths(tuple(a[idx] for a in self.pos), tuple(a[idx] for a in self.vel), self.knot_times()[idx],
                             lambda n, p: base(idx[n], p),
                             self.acc_h[idx], self.acc_v[idx], self.vz_const, sub(self.jerk_h), sub(self.kink_t))


@dataclass
class PathConflicts:
    """Violation intervals (absolute s) of P paths against M intruders, ``t_end`` the horizon.

    ``seg_in``/``seg_out`` ``(N, M, P, K-1)``: first entry and last exit on the true maneuver between
    knots j and j+1; ``tail_in``/``tail_out`` ``(N, M, P, K)``: the straight tail from knot k over
    ``[t_k, t_end]``; ``t`` ``(N, 1, P, K)`` knot times.
    """

    seg_in: np.ndarray
    seg_out: np.ndarray
    tail_in: np.ndarray
    tail_out: np.ndarray
    t: np.ndarray
    t_end: float

    def prefix(self) -> tuple[np.ndarray, np.ndarray]:
        """First entry / last exit on the maneuver up to knot k, ``(N, M, P, K)`` (k = 0: none)."""
        shape = self.tail_in.shape
        if shape[-1] > 1:
            pre_in = np.minimum.accumulate(self.seg_in, axis=-1)
            pre_out = np.maximum.accumulate(self.seg_out, axis=-1)
            edge = np.full(shape[:-1] + (1,), np.inf)
            return np.concatenate([edge, pre_in], axis=-1), np.concatenate([-edge, pre_out], axis=-1)
        return np.full(shape, np.inf), np.full(shape, -np.inf)

    def candidates(self) -> tuple[np.ndarray, np.ndarray]:
        """First violation and last exit of candidate k (maneuver to knot k, then straight) over
        ``[0, t_end]``, ``(N, M, P, K)``; no violation is ``(inf, -inf)``."""
        t_in, t_out = self.tail_in.copy(), self.tail_out.copy()
        if t_in.shape[-1] > 1:  # min / max with the prefix (k = 0 has none)
            np.minimum(t_in[..., 1:], np.minimum.accumulate(self.seg_in, axis=-1), out=t_in[..., 1:])
            np.maximum(t_out[..., 1:], np.maximum.accumulate(self.seg_out, axis=-1), out=t_out[..., 1:])
        none = ~(t_in <= self.t_end)
        t_in[none] = np.inf
        np.minimum(t_out, self.t_end, out=t_out)
        t_out[none] = -np.inf
        return t_in, t_out


class PathEvaluator:
    """Relative geometry of maneuver paths against straight-line intruders, evaluated for any volume.

    Built once per (paths, intruders); :meth:`evaluate` then gives :class:`PathConflicts` for a
    well-clear volume or a cylinder (a :class:`~daa_sil.geometry.thresholds.Thresholds` with TTHR = 0).
    ``tails``: True (every knot), ``"last"`` (only the last knot's) or False. ``exits=False``: the last
    exits are not searched (a segment that starts violating ends its violation at its end; use it when
    only first entries matter, as for SM).
    """

    def __init__(self, paths: ManeuverPaths, intr: AircraftState, t_end: float, tails: "bool | str" = True,
                 exits: bool = True):
        n, p, k = paths.shape
        m = intr.shape[1]
        self.paths, self.t_end, self.with_tails, self.exits = paths, float(t_end), tails, exits
        self.shape = (n, m, p, k)
        tt = paths.knot_times()[:, None]  # (N, 1, P, K)
        self.t = tt
        self.ipos, self.ivel = intr.position(), intr.velocity()  # (N, M, 3)
        own_c, ovel_c = paths.pos, paths.vel
        ip = [self.ipos[..., i][:, :, None, None] for i in range(3)]
        iv = [self.ivel[..., i][:, :, None, None] for i in range(3)]
        #: relative position ownship - intruder at the knots, per component (N, M, P, K)
        t4 = np.asarray(paths.t, float)[..., None, :, :] if np.ndim(paths.t) == 3 else tt
        self.s = [own_c[i][:, None] - (ip[i] + t4 * iv[i]) for i in range(3)]  # (intruder: no side axis)
        self.s = [c if c.shape == self.shape else np.ascontiguousarray(np.broadcast_to(c, self.shape)) for c in self.s]
        #: relative velocity of the tails (N, M, P, K), contiguous
        self.v = [np.ascontiguousarray(np.broadcast_to(ovel_c[i][:, None] - iv[i], self.shape)) for i in range(3)]
        self._vwin = None

    def evaluate(self, th: Thresholds) -> PathConflicts:
        """Segment and tail intervals for volume ``th`` (see :class:`PathConflicts`)."""
        n, m, p, k = self.shape
        tt = np.broadcast_to(self.t, self.shape)
        seg_shape = (n, m, p, max(k - 1, 0))
        self._vwin = None
        if self.paths.vz_const:  # relative altitude linear in time on every path: one vertical window each
            self._vwin = wc.vertical_window(self.s[2][..., :1], self.v[2][..., :1], 0.0, self.t_end, th.zthr, th.tcoa)
        full_tails = self.with_tails is True
        tail = (lambda fill: np.empty(self.shape)) if full_tails else (lambda fill: np.full(self.shape, fill))  # noqa: E731
        pc = PathConflicts(np.full(seg_shape, np.inf), np.full(seg_shape, -np.inf), tail(np.inf), tail(-np.inf), self.t,
                           self.t_end)
        if k > 1:
            self._segments(th, tt, pc)
        if self.with_tails:
            want = None
            if self.with_tails == "last":
                want = np.zeros(self.shape, bool)
                want[..., -1] = True
            self._tails(th, pc, want)
        return pc

    def _tails(self, th: Thresholds, pc: PathConflicts, want: "np.ndarray | None") -> None:
        """Tail intervals of every knot (``want`` None) or of the knots where ``want``."""
        if want is None:  # every knot, in cache-sized blocks of encounters
            n, m, p, k = self.shape
            tt_all = np.broadcast_to(self.t, self.shape)
            for sl in _row_blocks(n, m * p * k):
                tt = tt_all[sl]
                tk = tt.reshape(-1)
                win = None
                if self._vwin is not None:
                    win = ((np.maximum(self._vwin[0][sl], tt) - tt).reshape(-1),
                           (np.minimum(self._vwin[1][sl], self.t_end) - tt).reshape(-1))
                t_in, t_out = interval_soa(*(c[sl].reshape(-1) for c in self.s), *(c[sl].reshape(-1) for c in self.v),
                                           np.maximum(self.t_end - tk, 0.0), th, win)
                t_in += tk
                t_out += tk
                late = tk > self.t_end
                if late.any():
                    t_in[late], t_out[late] = np.inf, -np.inf
                pc.tail_in[sl] = t_in.reshape(tt.shape)
                pc.tail_out[sl] = t_out.reshape(tt.shape)
            return
        sel = np.flatnonzero(want)  # the chosen knots
        if not sel.size:
            return
        comp = [c.reshape(-1)[sel] for c in self.s]
        vel = [c.reshape(-1)[sel] for c in self.v]
        tk = self._flat_times()[sel]
        win = None
        if self._vwin is not None:
            path = sel // self.shape[3]
            lo, hi = self._vwin[0].reshape(-1)[path], self._vwin[1].reshape(-1)[path]
            win = (np.maximum(lo, tk) - tk, np.minimum(hi, self.t_end) - tk)
        t_in, t_out = interval_soa(*comp, *vel, np.maximum(self.t_end - tk, 0.0), th, win)
        ok = tk <= self.t_end
        pc.tail_in.reshape(-1)[sel] = np.where(ok, t_in + tk, np.inf)
        pc.tail_out.reshape(-1)[sel] = np.where(ok, t_out + tk, -np.inf)

    def _classify_between(self, th: Thresholds, tt, ja, jb) -> np.ndarray:
        """Codes ``(N, M, P, len(ja))`` of the pieces from knot ``ja[i]`` to knot ``jb[i]`` of every path."""
        t0, t1 = tt[..., ja], tt[..., jb]
        h = t1 - t0
        s0 = [np.ascontiguousarray(c[..., ja]).ravel() for c in self.s]
        s1 = [np.ascontiguousarray(c[..., jb]).ravel() for c in self.s]
        acc_h = self.paths.acc_h[:, None, :, None]
        e_p = np.ascontiguousarray(np.broadcast_to(acc_h * h * h * 0.125, h.shape)).ravel()
        e_v = np.ascontiguousarray(np.broadcast_to(acc_h * h * 0.5, h.shape)).ravel()
        if np.any(self.paths.acc_v):
            e_z = np.ascontiguousarray(np.broadcast_to(self.paths.acc_v[:, None, :, None] * h * h * 0.125, h.shape)).ravel()
        else:
            e_z = 0.0
        win = None
        if self._vwin is not None:
            lo, hi = self._vwin
            win = (np.ascontiguousarray(np.maximum(lo, t0) - t0).ravel(), np.ascontiguousarray(np.minimum(hi, t1) - t0).ravel())
        code = classify_pieces(*s0, *s1, np.ascontiguousarray(h).ravel(), th, e_p, e_v, e_z, win)
        return code.reshape(h.shape)

    def _segments(self, th: Thresholds, tt: np.ndarray, pc: PathConflicts) -> None:
        """Fill ``pc.seg_in``/``pc.seg_out`` (module docstring)."""
        n, m, p, k = self.shape
        seg_shape = (n, m, p, k - 1)
        live = tt[..., :-1] < self.t_end
        j = np.arange(k - 1)
        if k - 1 > BLOCK:  # coarse pass: blocks of BLOCK segments decided at once (most are far away)
            edges = np.r_[np.arange(0, k - 1, BLOCK), k - 1]
            bcode = self._classify_between(th, tt, edges[:-1], edges[1:])
            per_seg = np.repeat(bcode, np.diff(edges), axis=-1)
            code = np.where(per_seg == INSIDE, INSIDE, CLEAR).astype(np.int8)
            fb = np.flatnonzero(bcode == UNDECIDED)  # undecided blocks: classify their segments
            if fb.size:
                nb = edges.size - 1
                path, b = np.divmod(fb, nb)
                width = np.diff(edges)[b]
                offs = np.arange(BLOCK)
                seg = (path * (k - 1) + edges[b])[:, None] + offs[None, :]
                fine = seg[offs[None, :] < width[:, None]]
                code.ravel()[fine] = self._classify_flat(th, fine, seg_shape)
        else:
            code = self._classify_between(th, tt, j, j + 1)
        code[~live] = CLEAR
        inside = code == INSIDE
        np.copyto(pc.seg_in, tt[..., :-1], where=inside)
        np.copyto(pc.seg_out, tt[..., 1:], where=inside)
        todo = np.flatnonzero(code == UNDECIDED)
        if todo.size:
            self._resolve(todo, th, pc.seg_in.reshape(-1), pc.seg_out.reshape(-1))

    def _flat_times(self) -> np.ndarray:
        """Knot times as a flat contiguous (N*M*P*K) array (cached)."""
        if getattr(self, "_tt_flat", None) is None:
            self._tt_flat = np.ascontiguousarray(np.broadcast_to(self.t, self.shape)).ravel()
        return self._tt_flat

    def _path_tables(self):
        """Per path (flat n, m, p) lookups, cached: encounter, path index, flat (n, m), acceleration
        bounds and the vertical window bounds."""
        if getattr(self, "_tables", None) is None:
            n, m, p, k = self.shape
            nn, mm, pp = (a.ravel() for a in np.indices((n, m, p)))
            P = self.paths
            self._tables = dict(n=nn, p=pp, nm=nn * m + mm, acc_h=P.acc_h[nn, pp], acc_v=P.acc_v[nn, pp],
                                jerk=None if P.jerk_h is None else P.jerk_h[nn, pp],
                                kink=None if P.kink_t is None else P.kink_t[nn, pp])
        return self._tables

    def _pieces(self, flat_seg):
        """Path (flat n, m, p), first-knot flat index, start, duration and end points of segments ``flat_seg``."""
        k = self.shape[3]
        path = flat_seg // (k - 1)
        ka = flat_seg + path  # = path * k + (flat_seg - path * (k - 1))
        tt = self._flat_times()
        t0 = tt[ka]
        h = tt[ka + 1] - t0
        return path, ka, t0, h

    def _classify_flat(self, th, flat_seg, seg_shape) -> np.ndarray:
        path, ka, t0, h = self._pieces(flat_seg)
        tab = self._path_tables()
        a_h, a_v = tab["acc_h"][path], tab["acc_v"][path]
        win = None
        if self._vwin is not None:
            lo, hi = self._vwin[0].reshape(-1)[path], self._vwin[1].reshape(-1)[path]
            win = (np.maximum(lo, t0) - t0, np.minimum(hi, t0 + h) - t0)
        e_z = a_v * h * h * 0.125 if np.any(a_v) else 0.0
        s = [c.reshape(-1) for c in self.s]
        return classify_pieces(s[0][ka], s[1][ka], s[2][ka], s[0][ka + 1], s[1][ka + 1], s[2][ka + 1], h, th,
                               a_h * h * h * 0.125, a_h * h * 0.5, e_z, win)

    def _mover(self, path):
        """``f(t)``: the true relative state (6 component arrays) of flat paths ``path`` at times ``t``."""
        tab = self._path_tables()
        own = self.paths.state_at(tab["n"][path], tab["p"][path])
        nm = tab["nm"][path]
        if getattr(self, "_intr_flat", None) is None:  # intruder position / velocity components, flat (N * M)
            self._intr_flat = [np.ascontiguousarray(a[..., i]).reshape(-1) for a in (self.ipos, self.ivel) for i in range(3)]
        ipx, ipy, ipz, ivx, ivy, ivz = (a[nm] for a in self._intr_flat)

        def f(t):
            ox, oy, oz, ovx, ovy, ovz = own(t)
            return ox - (ipx + t * ivx), oy - (ipy + t * ivy), oz - (ipz + t * ivz), ovx - ivx, ovy - ivy, ovz - ivz
        return f

    def _state(self, path, t):
        """True relative state (6 component arrays) of flat paths ``path`` at times ``t``."""
        return self._mover(path)(t)

    def _bisect(self, th, path, lo, hi, lo_in):
        """Bracket ``(lo, hi)`` (s) of a crossing of the violation boundary on the true path between times
        ``lo`` and ``hi`` (the predicate is ``lo_in`` at ``lo`` and the opposite at ``hi``; bool or array), at
        most BISECT_DT_IN (an entry) or BISECT_DT_OUT (an exit) wide."""
        lo, hi = lo.copy(), hi.copy()
        f = self._mover(path)
        lo_in = np.broadcast_to(np.asarray(lo_in, bool), lo.shape)

        def steps(mask, dt):
            return int(np.ceil(np.log2(max(np.max(hi[mask] - lo[mask], initial=0.0), dt) / dt)))
        n_in, n_out = steps(~lo_in, BISECT_DT_IN), steps(lo_in, BISECT_DT_OUT)
        mixed = n_in != n_out and lo_in.any() and not lo_in.all()
        for k in range(max(n_in, n_out) if lo.size else 0):
            mid = 0.5 * (lo + hi)
            same = _wcv_soa(*f(mid), th) == lo_in
            if mixed:  # the same number of halvings per kind as when they are bisected apart
                live = np.where(lo_in, k < n_out, k < n_in)
                lo = np.where(same & live, mid, lo)
                hi = np.where(~same & live, mid, hi)
            else:
                lo = np.where(same, mid, lo)
                hi = np.where(same, hi, mid)
        return lo, hi

    def _resolve(self, flat_seg, th, seg_in, seg_out) -> None:
        """Undecided segments on the true path (module docstring); updates the flat ``seg_in``/``seg_out``.

        The predicate is exact at both ends (true states). Both violate: first entry at the start, last
        exit at the end. One violates: the boundary is found by bisection on the true path and the other
        side is certified CLEAR. Neither violates (a possible clip inside), or the certificate fails: the
        piece is split into parts (each with exact end flags) and examined again; a both-clear part as
        short as V_TOL / P_TOL allow is sampled every CLIP_DT for a clip of the volume (:meth:`_clip`).
        """
        path, ka, t0, h = self._pieces(flat_seg)
        s = [c.reshape(-1) for c in self.s]
        v = [c.reshape(-1) for c in self.v]
        sa, sb = [c[ka] for c in s], [c[ka + 1] for c in s]
        va, vb = [c[ka] for c in v], [c[ka + 1] for c in v]
        f0, f1 = _wcv_soa(*sa, *va, th), _wcv_soa(*sb, *vb, th)
        pieces = (flat_seg, path, t0, t0 + h, sa, sb, f0, f1, va[:2], vb[:2])
        tab = self._path_tables()
        for depth in range(MAX_DEPTH):
            sid, pth, ta, tb, pa, pb, fa, fb, ua, ub = pieces
            if not sid.size:
                return
            both = fa & fb
            if both.any():
                _update(seg_in, seg_out, sid[both], ta[both], tb[both])
            split = np.zeros(sid.size, bool)
            last = depth == MAX_DEPTH - 1
            settled = ((tb - ta) <= _settle_time(tab["acc_h"][pth], tab["acc_v"][pth]) * (1.0 + 1e-9)) | last
            cross = np.flatnonzero(fa != fb)  # entries (start clear, end violating) and exits (start violating)
            if cross.size and not self.exits:  # an exit: first entry at the start; the last exit is not needed
                ex = cross[fa[cross]]
                _update(seg_in, seg_out, sid[ex], ta[ex], tb[ex])
                cross = cross[fb[cross]]
            if cross.size:
                entry = fb[cross]
                lo, hi = self._bisect(th, pth[cross], ta[cross], tb[cross], lo_in=~entry)
                # certify that the other side of the crossing is clear: before an entry, after an exit
                mid_state = self._state(pth[cross], np.where(entry, lo, hi))
                c_a, c_b = np.where(entry, ta[cross], hi), np.where(entry, lo, tb[cross])
                p_a = [np.where(entry, pa[c][cross], mid_state[c]) for c in range(3)]
                p_b = [np.where(entry, mid_state[c], pb[c][cross]) for c in range(3)]
                ok = (self._classify_part(th, pth[cross], c_a, c_b, p_a, p_b) == CLEAR) | settled[cross]
                t_cross = 0.5 * (lo + hi)
                good, e, tc = cross[ok], entry[ok], t_cross[ok]
                _update(seg_in, seg_out, sid[good], np.where(e, tc, ta[good]), np.where(e, tb[good], tc))
                split[cross[~ok]] = True
            j = np.flatnonzero(~fa & ~fb)  # both ends clear: a clip may lie inside unless certified clear
            if j.size and depth > 0:  # (at depth 0 these are the segments the first-order test left undecided)
                code = self._classify_part(th, pth[j], ta[j], tb[j], [c[j] for c in pa], [c[j] for c in pb])
                j = j[code != CLEAR]
            if j.size and tab["jerk"] is not None:  # the tighter second-order certificate (true end velocities)
                j = j[~self._clear2(th, pth[j], ta[j], tb[j], [c[j] for c in pa], [c[j] for c in pb],
                                    [c[j] for c in ua], [c[j] for c in ub])]
            if j.size:
                final = j[settled[j]]
                if final.size:
                    self._clip(th, sid[final], pth[final], ta[final], tb[final],
                               [c[final] for c in pa], [c[final] for c in pb], seg_in, seg_out)
                split[j[~settled[j]]] = True
            idx = np.flatnonzero(split)
            if not idx.size:
                return
            pieces = self._split(th, *(a[idx] for a in (sid, pth, ta, tb)), [c[idx] for c in pa], [c[idx] for c in pb],
                                 fa[idx], fb[idx], [c[idx] for c in ua], [c[idx] for c in ub])

    def _classify_part(self, th, pth, ta, tb, pa, pb) -> np.ndarray:
        tab = self._path_tables()
        h = tb - ta
        a_h, a_v = tab["acc_h"][pth], tab["acc_v"][pth]
        win = None
        if self._vwin is not None:
            vlo, vhi = self._vwin[0].reshape(-1)[pth], self._vwin[1].reshape(-1)[pth]
            win = (np.maximum(vlo, ta) - ta, np.minimum(vhi, tb) - ta)
        e_z = a_v * h * h * 0.125 if np.any(a_v) else 0.0
        return classify_pieces(*pa, *pb, h, th, a_h * h * h * 0.125, a_h * h * 0.5, e_z, win)

    def _clear2(self, th, pth, ta, tb, pa, pb, ua, ub) -> np.ndarray:
        """Second-order CLEAR certificate of pieces (see :func:`clear_second_order`)."""
        tab = self._path_tables()
        h = tb - ta
        a_h, a_v, jerk = tab["acc_h"][pth], tab["acc_v"][pth], tab["jerk"][pth]
        e_v = jerk * h * h * 0.125
        if tab["kink"] is not None:
            kt = tab["kink"][pth]
            across = (kt > ta) & (kt < tb) if kt.ndim == 1 else ((kt > ta[:, None]) & (kt < tb[:, None])).any(axis=-1)
            e_v = e_v + np.where(across, a_h * h * 0.5, 0.0)
        e_z = a_v * h * h * 0.125 if np.any(a_v) else 0.0
        return clear_second_order(*pa, *pb, *ua, *ub, h, th, a_h * h * h * 0.125, e_v, e_z)

    def _split(self, th, sid, pth, ta, tb, pa, pb, fa, fb, ua, ub):
        """Split pieces into the fewest equal parts that settle (at least 2, at most MAX_SPLIT), with
        exact states and flags at the new ends."""
        tab = self._path_tables()
        settle = _settle_time(tab["acc_h"][pth], tab["acc_v"][pth])
        q = int(min(MAX_SPLIT, max(2, np.ceil(np.max((tb - ta) / settle) - 1e-9))))
        L = sid.size
        ts = ta[:, None] + (tb - ta)[:, None] * (np.arange(1, q) / q)[None, :]  # (L, q-1)
        st = self._state(np.repeat(pth, q - 1), ts.ravel())
        flag = _wcv_soa(*st, th).reshape(L, q - 1)
        times = np.concatenate([ta[:, None], ts, tb[:, None]], axis=1)
        pos = [np.concatenate([pa[c][:, None], st[c].reshape(L, q - 1), pb[c][:, None]], axis=1) for c in range(3)]
        flags = np.concatenate([fa[:, None], flag, fb[:, None]], axis=1)
        vel = [np.concatenate([ua[c][:, None], st[3 + c].reshape(L, q - 1), ub[c][:, None]], axis=1) for c in range(2)]
        rep = lambda a: np.repeat(a, q)  # noqa: E731
        return (rep(sid), rep(pth), times[:, :-1].ravel(), times[:, 1:].ravel(), [c[:, :-1].ravel() for c in pos],
                [c[:, 1:].ravel() for c in pos], flags[:, :-1].ravel(), flags[:, 1:].ravel(),
                [c[:, :-1].ravel() for c in vel], [c[:, 1:].ravel() for c in vel])

    def _clip(self, th, sid, pth, ta, tb, pa, pb, seg_in, seg_out) -> None:
        """Short pieces whose ends are clear but which are not certified clear (a clip of the volume may
        lie inside): the true predicate sampled every CLIP_DT, and around the first and last violating
        samples the entry and exit found by bisection on the true path."""
        h = tb - ta
        q = int(np.ceil(np.max(h) / CLIP_DT - 1e-9))
        if q < 1:
            return
        frac = (np.arange(q) + 0.5) / q
        ts = ta[:, None] + h[:, None] * frac[None, :]  # (L, q)
        L = sid.size
        hit = _wcv_soa(*self._state(np.repeat(pth, q), ts.ravel()), th).reshape(L, q)
        rows = np.flatnonzero(hit.any(axis=1))
        if not rows.size:
            return
        first = np.argmax(hit[rows], axis=1)
        last = q - 1 - np.argmax(hit[rows, ::-1], axis=1)
        t_first, t_last = ts[rows, first], ts[rows, last]
        before = np.where(first > 0, ts[rows, np.maximum(first - 1, 0)], ta[rows])
        after = np.where(last < q - 1, ts[rows, np.minimum(last + 1, q - 1)], tb[rows])
        l1, h1 = self._bisect(th, pth[rows], before, t_first, lo_in=False)
        l2, h2 = self._bisect(th, pth[rows], t_last, after, lo_in=True)
        _update(seg_in, seg_out, sid[rows], 0.5 * (l1 + h1), 0.5 * (l2 + h2))


def _update(seg_in, seg_out, sid, t_in, t_out) -> None:
    """seg_in[sid] = min(seg_in[sid], t_in), seg_out[sid] = max(...) (repeated ids allowed)."""
    np.minimum.at(seg_in, sid, t_in)
    np.maximum.at(seg_out, sid, t_out)


@_in_blocks
def _wcv_soa(sx, sy, sz, vx, vy, vz, th: Thresholds) -> np.ndarray:
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


def path_conflicts(paths: ManeuverPaths, intr: AircraftState, th: Thresholds, t_end: float,
                   tails: "bool | str" = True, exits: bool = True) -> PathConflicts:
    """:class:`PathConflicts` of ``paths`` against intruders ``(N, M)`` for volume ``th`` over ``[0, t_end]``."""
    return PathEvaluator(paths, intr, t_end, tails, exits).evaluate(th)


# --------------------------------------------------------------------------------------------------
# commands (SM)
# --------------------------------------------------------------------------------------------------
def maneuver_times(own: AircraftState, cmd: Command, cfg: DaaConfig) -> tuple[np.ndarray, ...]:
    """Time (s) to reach the commanded track, vertical speed and ground speed at the limits."""
    c = cmd.resolved(own)
    perf = cfg.performance()
    t_trk = np.abs(wrap_pi(c.trk - own.trk)) / cfg.turn_rate
    t_vs = np.abs(np.clip(c.vs, -perf.max_vs, perf.max_vs) - own.vs) / cfg.vertical_accel
    t_gs = np.abs(np.clip(c.gs, perf.min_gs, perf.max_gs) - own.gs) / cfg.horizontal_accel
    return t_trk, t_vs, t_gs


class _CommandMotion:
    """:func:`daa_sil.geometry.kinematics.fly_command` from one state, with the start of each of its three phases
    (turn and speed change together, then the longer one alone, then straight) computed once. The state
    at a time is then one piece of one phase: the same operations as ``fly_command`` (so the same
    numbers), with the sines and cosines of each phase's initial track reused (4 instead of 20 per state)."""

    def __init__(self, own: AircraftState, cmd: Command, perf):
        c = cmd.resolved(own)
        self.own, self.perf, self.trk_cmd = own, perf, c.trk
        self.tgt_gs = np.clip(c.gs, perf.min_gs, perf.max_gs)
        self.tgt_vs = np.clip(c.vs, -perf.max_vs, perf.max_vs)
        self.dpsi = wrap_pi(c.trk - own.trk)
        w = np.sign(self.dpsi) * perf.max_turn_rate
        t_turn = np.abs(self.dpsi) / perf.max_turn_rate if perf.max_turn_rate > 0 else np.zeros_like(self.dpsi)
        self.dgs = self.tgt_gs - own.gs
        acc = np.sign(self.dgs) * perf.horizontal_accel
        t_spd = np.abs(self.dgs) / perf.horizontal_accel if perf.horizontal_accel > 0 else np.zeros_like(self.dgs)
        b1, b2 = np.minimum(t_turn, t_spd), np.maximum(t_turn, t_spd)
        starts = [(own.x, own.y, own.gs, own.trk)]
        params = []
        for lo, hi in ((0.0, b1), (b1, b2), (b2, None)):
            w_p, a_p = np.where(t_turn > lo, w, 0.0), np.where(t_spd > lo, acc, 0.0)
            params.append((w_p, a_p))
            if hi is not None:
                starts.append(_horizontal_segment(*starts[-1], w_p, a_p, np.maximum(hi - lo, 0.0)))
        #: (3, N) phase start times, x, y, gs, trk, turn rate, acceleration, and sin / cos of the start track
        self.t0 = np.stack([np.zeros_like(b1), b1, b2])
        self.x, self.y, self.gs, self.trk = (np.stack([st[i] for st in starts]) for i in range(4))
        self.w, self.acc = (np.stack([pr[i] for pr in params]) for i in range(2))
        self.sin0, self.cos0 = np.sin(self.trk), np.cos(self.trk)
        self.exotic = bool(np.any((self.w != 0.0) & (np.abs(self.w) < _W_EPS)))  # (as _arc's "small" branch)

    def state(self, n: np.ndarray, tau: np.ndarray) -> tuple:
        """Position and velocity (six arrays) of encounters ``n`` at times ``tau`` (broadcast together)."""
        if self.exotic:  # a turn rate _arc treats as straight: the reference implementation
            st = fly_command(self.own[n], Command(self.trk_cmd[n], self.tgt_vs[n], self.tgt_gs[n]), dt=tau,
                             perf=self.perf)
            return st.x, st.y, st.z, st.gs * np.sin(st.trk), st.gs * np.cos(st.trk), st.vs
        n, tau = np.broadcast_arrays(n, tau)
        ph = (tau > self.t0[1, n]).astype(np.intp) + (tau > self.t0[2, n])
        g = lambda a: a[ph, n]  # noqa: E731
        t = tau - g(self.t0)
        gs0, acc, w, trk0, s0, c0 = g(self.gs), g(self.acc), g(self.w), g(self.trk), g(self.sin0), g(self.cos0)
        turning = w != 0.0
        ws = np.where(turning, w, 1.0)
        th1 = trk0 + w * t
        s1, c1 = np.sin(th1), np.cos(th1)
        dist = gs0 * t + 0.5 * acc * t * t
        # _arc's two branches (straight: w = 0, so trk0 + 0.5 w t = trk0 exactly)
        dx = np.where(turning, gs0 * (c0 - c1) / ws + acc * (-t * c1 / ws + (s1 - s0) / ws ** 2), dist * s0)
        dy = np.where(turning, gs0 * (s1 - s0) / ws + acc * (t * s1 / ws + (c1 - c0) / ws ** 2), dist * c0)
        x, y = g(self.x) + dx, g(self.y) + dy
        gs, trk = gs0 + acc * t, th1
        perf = self.perf
        trk = np.where(np.abs(self.dpsi[n]) <= perf.max_turn_rate * tau, self.trk_cmd[n], trk)
        gs = np.where(np.abs(self.dgs[n]) <= perf.horizontal_accel * tau, self.tgt_gs[n], gs)
        o = self.own
        z, vs = _vertical(o.z[n], o.vs[n], self.tgt_vs[n], perf.vertical_accel, tau)
        trk = wrap_2pi(trk)
        return x, y, z, gs * np.sin(trk), gs * np.cos(trk), vs


def command_paths(own: AircraftState, cmd: Command, cfg: DaaConfig) -> ManeuverPaths:
    """The single path (P = 1) of each ownship flying ``cmd`` kinematically (as
    :func:`daa_sil.geometry.kinematics.fly_command`), with knots at the spacing of the axes the command changes
    (the finest one if several), so a single-axis command has the knots of its band candidate."""
    cmd = cmd.resolved(own)
    perf = cfg.performance()
    t_trk, t_vs, t_gs = maneuver_times(own, cmd, cfg)
    eps = 1e-9
    knots = np.stack([np.where(t_trk > eps, cfg.knot_trk, np.inf), np.where(t_vs > eps, cfg.knot_vs, np.inf),
                      np.where(t_gs > eps, cfg.knot_gs, np.inf)], axis=-1).min(axis=-1)
    t_man = np.maximum(np.maximum(t_trk, t_vs), t_gs)
    h = np.where(np.isfinite(knots), knots, 1.0)
    n_knots = np.where(t_man > eps, np.ceil(t_man / h - 1e-9), 0.0)
    j_max = int(n_knots.max()) if n_knots.size else 0
    t = np.arange(j_max + 1)[None, :] * h[:, None]  # (N, J+1)
    motion = _CommandMotion(own, cmd, perf)
    px, py, pz, vx, vy, vz = motion.state(np.arange(own.shape[0])[:, None], t)
    gs_max = np.maximum(own.gs, np.clip(cmd.gs, perf.min_gs, perf.max_gs))
    acc_h = np.where(t_trk > eps, gs_max * cfg.turn_rate, 0.0) + np.where(t_gs > eps, cfg.horizontal_accel, 0.0)
    acc_v = np.where(t_vs > eps, cfg.vertical_accel, 0.0)
    # v = g(t) u(trk(t)): |v''| <= 2 |g'| w + g w^2 between the instants the turn or the speed change
    # ends (the horizontal acceleration jumps there)
    w = np.where(t_trk > eps, cfg.turn_rate, 0.0)
    jerk = 2.0 * np.where(t_gs > eps, cfg.horizontal_accel, 0.0) * w + gs_max * w * w
    kink = np.stack([np.where(t_trk > eps, t_trk, np.inf), np.where(t_gs > eps, t_gs, np.inf)], axis=-1)

    def state_at(n, p):
        return lambda tq: motion.state(n, tq)

    return ManeuverPaths((px[:, None], py[:, None], pz[:, None]), (vx[:, None], vy[:, None], vz[:, None]),
                         t[:, None], state_at,
                         acc_h[:, None], acc_v[:, None], vz_const=not np.any(t_vs > eps), jerk_h=jerk[:, None],
                         kink_t=kink[:, None])


def command_conflicts(own: AircraftState, intr: AircraftState, cmd: Command, cfg: DaaConfig,
                      t_end: float, exits: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """``(t_in, t_out)`` per intruder ``(N, M)`` when the ownship flies ``cmd`` (kinematically, as
    :func:`daa_sil.geometry.kinematics.fly_command`, evaluated on the true trajectory) and the intruders fly
    straight, over ``[0, t_end]`` s. With ``exits=False`` only ``t_in`` is exact (``t_out`` may be
    late by up to one knot interval during the maneuver)."""
    paths = command_paths(own, cmd, cfg)
    pc = path_conflicts(paths, intr, cfg.th, t_end, tails="last", exits=exits)
    pre_in, pre_out = pc.prefix()
    t_in = np.minimum(pre_in[..., -1], pc.tail_in[..., -1])
    t_out = np.maximum(pre_out[..., -1], pc.tail_out[..., -1])
    t_in = np.where(t_in <= t_end, t_in, np.inf)
    t_out = np.where(np.isfinite(t_in), np.minimum(t_out, t_end), -np.inf)
    return t_in[..., 0], t_out[..., 0]


def safety_metric(own: AircraftState, intr: AircraftState, cmd: Command, cfg: DaaConfig,
                  horizon_s: "float | None" = None) -> np.ndarray:
    """Safety metric SM(u), s, ``(N,)``: ``min(t_LoWC(u), H + margin) - H``.

    ``t_LoWC(u)`` is the first time the ownship, flying command ``u`` kinematically from its current
    state (turn at ``cfg.turn_rate``, accelerate at the limits, then straight), violates well clear
    (``cfg.th``) with **any** intruder (intruders straight-line), searched over ``[0, H + margin]``;
    ``H = horizon_s`` (default ``cfg.sm_horizon_s`` = 55 s, the corrective alerting time) and
    ``margin = cfg.sm_margin_s``. So SM > 0 iff following u keeps the ownship well clear of every
    intruder for H seconds; SM = -H when violating now; SM = margin when clear over H + margin.
    """
    horizon = cfg.sm_horizon_s if horizon_s is None else float(horizon_s)
    t_end = horizon + cfg.sm_margin_s
    t_in, _ = command_conflicts(own, intr, cmd, cfg, t_end, exits=False)
    return sm_from_tin(t_in.min(axis=-1) if t_in.shape[-1] else np.full(own.shape, np.inf), horizon, cfg)


def sm_from_tin(t_in, horizon: float, cfg: DaaConfig) -> np.ndarray:
    """SM (s) from the first LoWC time (s; inf = none) for horizon ``horizon`` s."""
    return np.minimum(t_in, horizon + cfg.sm_margin_s) - horizon
