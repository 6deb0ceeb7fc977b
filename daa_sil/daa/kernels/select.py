"""The choice of a band candidate per encounter (paper Algorithm 2), compiled: one pass per row over the
candidates of the three axes, read in place from the bands (rows ``rows_*`` of each axis's arrays), so
that no (N, K) mask, cost or concatenated array is made. The numpy reference is
:func:`daa_sil.daa.resolution.search_maneuver` with ``resolution.COMPILED = False`` (``_pick``:
``np.argmin`` of the cost where the mask holds, inf elsewhere, found when that is finite;
``_Candidates.best_effort``: ``np.argmax``), with the same operations per element.

Each row reads only its own candidates of each axis, the columns ``lo_*`` .. ``hi_*`` of its row (a speed
axis's encounters have their own candidate counts; the columns past them are not candidates of theirs):
the choice is the one a call of its own makes.
"""

from __future__ import annotations

import math

from numba import boolean, int8, int64, types, void

from daa_sil.daa.kernels.jit import inline, kernel
from daa_sil.daa.kernels.signatures import A, A2, IA, F

#: daa.config RULE_*
_AXIS_DIR, _AXIS, _ANY, _BEST_EFFORT = 1, 2, 3, 4


@inline
def _argmin_step(best, bi, c, k, done, first):
    """One element of ``np.argmin`` (first minimum; the first nan wins; ``first``: the first element looked
    at): ``(best, index, done)``."""
    if done:
        return best, bi, True
    if c != c:
        return c, k, True
    if first or c < best:
        return c, k, False
    return best, bi, False


@inline
def _own(k, K_h, K_v, own):
    """Is column ``k`` (track, vertical speed, ground speed) one of the row's own candidates (``own``: the
    row's first and last own column of each axis, six ints)."""
    if k < K_h:
        return own[0] <= k <= own[1]
    if k < K_h + K_v:
        return own[2] <= k - K_h <= own[3]
    return own[4] <= k - K_h - K_v <= own[5]


@inline
def _own_row(lo_h, lo_v, lo_g, hi_h, hi_v, hi_g, rh, rv, rg):
    """The row's own columns of each axis, read once per row as a tuple of ints (:func:`_own`)."""
    return lo_h[rh], hi_h[rh], lo_v[rv], hi_v[rv], lo_g[rg], hi_g[rg]


@inline
def _best_effort(tin, tout, rh, rv, rg, K_h, K_v, K, own):
    """The best-effort candidate of one row (``np.argmax``, the first nan wins) over the three axes' own
    candidates (``own``: :func:`_own_row`; ``tin``/``tout`` the axes' ``t_in`` / ``t_out``): latest first LoWC
    (capped at 1e6 s), then earliest regain of well clear."""
    i_h, i_v, i_g = tin
    o_h, o_v, o_g = tout
    best, bi, done, first = 0.0, 0, False, True
    for k in range(K):
        if not _own(k, K_h, K_v, own):
            continue
        if k < K_h:
            ti, to = i_h[rh, k], o_h[rh, k]
        elif k < K_h + K_v:
            ti, to = i_v[rv, k - K_h], o_v[rv, k - K_h]
        else:
            ti, to = i_g[rg, k - K_h - K_v], o_g[rg, k - K_h - K_v]
        t1 = ti if (ti != ti or ti <= 1e6) else 1e6
        t2 = to if (to != to or to >= 0.0) else 0.0
        c = t1 * 1e3 - t2
        if not done:
            if c != c:
                best, bi, done = c, k, True
            elif first or c > best:
                best, bi = c, k
        first = False
    return bi


#: per-axis records (track, vertical speed, ground speed): float fields, row indices / own columns / sides
_F3, _I3 = types.UniTuple(A2, 3), types.UniTuple(IA, 3)


@kernel(void(_F3, _F3, _F3, _F3, _I3, _I3, _I3, _I3, IA, IA, A2, A, F, types.Array(int64, 1, "C"),
             types.Array(int8, 1, "C")), lazy=True)
def search_into(d, m, tin, tout, r, lo, hi, sides, ax, side, ref_t, rates, horizon, idx, rule):
    """Candidate index (columns: track, then vertical speed, then ground speed, as ``_Candidates``) and rule
    per row ``n``: the axes' ``delta`` (``d``), ``t_man`` (``m``), ``t_in`` (``tin``) and ``t_out`` (``tout``) read at
    rows ``r[a][n]`` (each a tuple over the three axes); ``sides`` the axes' candidate sides; ``ax``/``side`` the
    row's wanted axis code and side; ``ref_t`` (N, 4) the reference's change per axis code in s of
    maneuvering, ``rates`` (4,) per axis code; ``lo``/``hi`` each row's own columns of each axis (read at
    ``r[a][n]``)."""
    d_h, d_v, d_g = d
    m_h, m_v, m_g = m
    i_h, i_v, i_g = tin
    r_h, r_v, r_g = r
    lo_h, lo_v, lo_g = lo
    hi_h, hi_v, hi_g = hi
    side_h, side_v, side_g = sides
    K_h, K_v = side_h.shape[0], side_v.shape[0]
    K = K_h + K_v + side_g.shape[0]
    for n in range(idx.shape[0]):
        b1, b2, b3 = 0.0, 0.0, 0.0
        j1, j2, j3 = 0, 0, 0
        e1, e2, e3 = False, False, False
        first = True
        a_n, s_n = ax[n], side[n]
        rh, rv, rg = r_h[n], r_v[n], r_g[n]
        own = _own_row(lo_h, lo_v, lo_g, hi_h, hi_v, hi_g, rh, rv, rg)
        for k in range(K):
            if not _own(k, K_h, K_v, own):
                continue
            if k < K_h:
                a, j, r = 1, k, r_h[n]
                dl, tm, ti, sd = d_h[r, j], m_h[r, j], i_h[r, j], side_h[j]
            elif k < K_h + K_v:
                a, j, r = 2, k - K_h, r_v[n]
                dl, tm, ti, sd = d_v[r, j], m_v[r, j], i_v[r, j], side_v[j]
            else:
                a, j, r = 3, k - K_h - K_v, r_g[n]
                dl, tm, ti, sd = d_g[r, j], m_g[r, j], i_g[r, j], side_g[j]
            safe = ti > horizon
            dist = abs(dl / rates[a] - ref_t[n, a])
            on_axis_moving = safe and a == a_n and a_n != 0 and sd != 0
            c1 = dist if (on_axis_moving and sd == s_n and s_n != 0) else math.inf
            c2 = dist if on_axis_moving else math.inf
            c3 = tm if safe else math.inf
            b1, j1, e1 = _argmin_step(b1, j1, c1, k, e1, first)
            b2, j2, e2 = _argmin_step(b2, j2, c2, k, e2, first)
            b3, j3, e3 = _argmin_step(b3, j3, c3, k, e3, first)
            first = False
        if K > 0 and math.isfinite(b1):
            idx[n], rule[n] = j1, _AXIS_DIR
        elif K > 0 and math.isfinite(b2):
            idx[n], rule[n] = j2, _AXIS
        elif K > 0 and math.isfinite(b3):
            idx[n], rule[n] = j3, _ANY
        else:  # best effort: latest first LoWC, then earliest regain of well clear (np.argmax, the first nan wins)
            idx[n], rule[n] = _best_effort(tin, tout, rh, rv, rg, K_h, K_v, K, own), _BEST_EFFORT


_REGION_NONE, _REGION_RECOVERY = 0, 4
_R2 = types.Array(int8, 2, "A", readonly=True)
_R1 = types.Array(int8, 1, "A", readonly=True)
_B1 = types.Array(boolean, 1, "A", readonly=True)


@inline
def _axis_pick(reg, tm, side, r, want, pref, lo, hi):
    """``resolution.resolve``'s step 2 on one axis and row: ``(local index, found)`` of the candidate of region
    ``want`` (not the current value) on the preferred side ``pref`` (0: either) reached soonest, else on
    either side (``_pick`` of both masks on ``t_man``), among the row's own columns ``lo`` .. ``hi``."""
    b1, j1, e1 = 0.0, 0, False
    b2, j2, e2 = 0.0, 0, False
    for j in range(lo, hi + 1):
        ok = reg[r, j] == want and side[j] != 0
        c1 = tm[r, j] if (ok and (side[j] == pref or pref == 0)) else math.inf
        c2 = tm[r, j] if ok else math.inf
        b1, j1, e1 = _argmin_step(b1, j1, c1, j, e1, j == lo)
        b2, j2, e2 = _argmin_step(b2, j2, c2, j, e2, j == lo)
    if side.shape[0] and math.isfinite(b1):
        return j1, True
    if side.shape[0] and math.isfinite(b2):
        return j2, True
    return 0, False


@kernel(void(types.UniTuple(_R2, 3), _F3, types.UniTuple(_R1, 3), _F3, _F3, _I3, _I3, _I3, _I3, _B1, boolean, IA,
             IA, IA, types.Array(int64, 1, "C")))
def resolution_into(g, m, p, tin, tout, r, lo, hi, sides, in_conflict, has_prev, p_ax, p_side, res_axes, chosen):
    """The candidate ``resolution.resolve`` chooses per row ``n`` (columns: track, vertical speed, ground speed;
    -1: none, not in conflict): the axes' ``region`` (``g``), ``t_man`` (``m``), ``preferred`` (``p``), ``t_in``
    (``tin``) and ``t_out`` (``tout``) read at rows ``r[a][n]`` (each a tuple over the three axes); ``p_ax``/``p_side``
    the previous resolution's axis code and side (with ``has_prev``), ``res_axes`` the axis codes in priority
    order; ``lo``/``hi`` each row's own columns of each axis (read at ``r[a][n]``)."""
    g_h, g_v, g_g = g
    m_h, m_v, m_g = m
    p_h, p_v, p_g = p
    r_h, r_v, r_g = r
    lo_h, lo_v, lo_g = lo
    hi_h, hi_v, hi_g = hi
    side_h, side_v, side_g = sides
    K_h, K_v = side_h.shape[0], side_v.shape[0]
    K = K_h + K_v + side_g.shape[0]
    for n in range(chosen.shape[0]):
        ch = -1
        if not in_conflict[n]:
            chosen[n] = ch
            continue
        a_prev = p_ax[n] if has_prev else 0
        rh, rv, rg = r_h[n], r_v[n], r_g[n]
        # 1. persistence: the previous (axis, side), its conflict-free candidate reached soonest
        if a_prev != 0:
            if a_prev == 1:
                reg, tm, side, r, start, lo, hi = g_h, m_h, side_h, rh, 0, lo_h[rh], hi_h[rh]
            elif a_prev == 2:
                reg, tm, side, r, start, lo, hi = g_v, m_v, side_v, rv, K_h, lo_v[rv], hi_v[rv]
            else:
                reg, tm, side, r, start, lo, hi = g_g, m_g, side_g, rg, K_h + K_v, lo_g[rg], hi_g[rg]
            b, bj, done = 0.0, 0, False
            for j in range(lo, hi + 1):
                g = reg[r, j]
                ok = (g == _REGION_NONE or g == _REGION_RECOVERY) and side[j] == p_side[n] and side[j] != 0
                b, bj, done = _argmin_step(b, bj, tm[r, j] if ok else math.inf, j, done, j == lo)
            # (the other axes' columns are inf: they never win, and they come first only for a later axis)
            if side.shape[0] and math.isfinite(b):
                ch = start + bj
        # 2. fresh: axes in priority order, NONE then RECOVERY, the previous axis last
        for want in (_REGION_NONE, _REGION_RECOVERY):
            for allow_reversal in (False, True):
                for q in range(res_axes.shape[0]):
                    a = res_axes[q]
                    if ch >= 0:
                        break
                    if not (allow_reversal or a_prev != a):
                        continue
                    if a == 1:
                        j, f = _axis_pick(g_h, m_h, side_h, rh, want, p_h[rh], lo_h[rh], hi_h[rh])
                        start = 0
                    elif a == 2:
                        j, f = _axis_pick(g_v, m_v, side_v, rv, want, p_v[rv], lo_v[rv], hi_v[rv])
                        start = K_h
                    else:
                        j, f = _axis_pick(g_g, m_g, side_g, rg, want, p_g[rg], lo_g[rg], hi_g[rg])
                        start = K_h + K_v
                    if f:
                        ch = start + j
        # 3. best effort: latest first LoWC, then earliest regain of well clear
        if ch < 0:
            ch = _best_effort(tin, tout, rh, rv, rg, K_h, K_v, K, _own_row(lo_h, lo_v, lo_g, hi_h, hi_v, hi_g, rh, rv, rg))
        chosen[n] = ch
