"""One band axis from its candidates' conflicts to its regions, recovery and resolutions (compiled).

The numpy reference is :func:`daa_sil.daa.bands.axis_bands` itself (its ``earliest_exit`` recovery;
the cylinder recovery stays in numpy): red per intruder and level, the columns ordered low side
(outward in), current, high side (``bands._side_order``), the reductions over intruders (``np.any`` /
``np.min`` / ``np.max``, nan winning), isolated green candidates dropped on the DAIDALUS grid, the
candidate values (``bands._candidate_values``), the recovery columns and ``bands.resolutions``, each
with the reference's operations in its order. Python-scalar constants are computed by the caller.
"""

from __future__ import annotations

import numpy as np
from numba import int8, types, void

from daa_sil.daa.kernels.evaluate import candidates_path
from daa_sil.daa.kernels.jit import inline, inline_ir, kernel
from daa_sil.daa.kernels.scalar import INF, npmax, npmin
from daa_sil.daa.kernels.signatures import A, B2, IA, O, O2, F, I, B


#: daa.config REGION_* and AXIS_HORIZONTAL
NONE, MID, NEAR, RECOVERY = 0, 2, 3, 4
_HORIZONTAL = 1


@inline
def first_ok(ok_row, k0, want, c_lo, c_hi):
    """``bands._first_on_side`` of one row whose candidates are columns ``c_lo`` .. ``c_hi``: (index, found)."""
    if want > 0:
        if k0 + 1 > c_hi:
            return k0, False
        for j in range(k0 + 1, c_hi + 1):
            if ok_row[j]:
                return j, True
        return k0 + 1, False
    if k0 <= c_lo:
        return k0, False
    for j in range(k0 - 1, c_lo - 1, -1):
        if ok_row[j]:
            return j, True
    return k0 - 1, False


@inline_ir
def _repeat(n, c, src, axis, values, delta, t_man, t_in_all, t_out_c, region):
    """Column ``c`` of row ``n`` a copy of its column ``src`` (a track axis has no such column: its ``delta``
    and ``t_man`` have one row for every encounter)."""
    values[n, c], t_in_all[n, c], t_out_c[n, c], region[n, c] = (values[n, src], t_in_all[n, src], t_out_c[n, src],
                                                                  region[n, src])
    if axis != _HORIZONTAL:
        delta[n, c], t_man[n, c] = delta[n, src], t_man[n, src]


#: the records of :func:`axis_regions_into`
_CONFLICTS = types.UniTuple(A, 4)
_LISTS = types.UniTuple(B2, 3)
_TIMES = types.UniTuple(F, 7)
_AXIS = types.Tuple((B, I, F, F, F, B, F, F))
_FIELDS = types.UniTuple(O2, 5)
_CODES = types.UniTuple(types.Array(int8, 2, "C"), 2)


@kernel(void(_CONFLICTS, B, I, F, B, _LISTS, A, _TIMES, types.UniTuple(I, 2), types.UniTuple(IA, 2), _AXIS, A,
             _FIELDS, _CODES, types.UniTuple(O, 2), int8[:]))
def axis_regions_into(conflicts, from_paths, M, t_end, hfm, lists, tk, times, counts, rows, ax, cur, fields, codes, res,
                      pref):
    """The (N, K) candidate arrays, regions (N, K), gap regions (N, K-1; DAIDALUS grid), resolutions
    and preferred sides (N,) of one axis (module docstring) from its candidates' first violation / last
    exit per intruder, path side and knot (M, 2, J+1 per row): ``src_in``/``src_out`` themselves (flat over
    (N, M, 2, J+1)), or with ``from_paths`` the paths' tail intervals ``src_in``/``src_out`` (flat over
    (N, M, 2, J+1)) and segment intervals ``seg_in``/``seg_out`` (flat over (N, M, 2, J)), a row's
    candidates made from them over ``[0, t_end]`` (``evaluate.candidates_into`` of its paths) into a small
    buffer. ``alert2`` (N, M): alert level >= 2; ``near_list``/``mid_list`` the conflict lists (``hfm``);
    ``cur`` (N,) the current track / vs / gs; ``rate`` the turn rate or the axis acceleration. Records:
    ``conflicts`` = ``(src_in, src_out, seg_in, seg_out)``, ``lists`` = ``(near_list, mid_list, alert2)``,
    ``times`` = ``(L, warn, corr, sm_h, stab, pi_cut, two_pi)`` (lookahead, alerting times, SM horizon,
    recovery stability, the largest track resolution, 2 pi), ``counts`` = ``(j_lo, j_hi)``, ``rows`` =
    ``(jl_row, jh_row)``, ``ax`` = ``(dgrid, axis, rate, lim_lo, lim_hi, do_clip, clip_lo, clip_hi)``, the
    outputs ``fields`` = ``(values, delta, t_man, t_in_all, t_out_c)``, ``codes`` = ``(region, gap)``, ``res`` =
    ``(res_lo, res_hi)`` and ``pref``. The terms
    that do not depend on the row (a track candidate's change and time) or on the column (a speed side's
    time to its limit) are computed once, by the same operations; a track axis's ``delta`` and ``t_man``
    are the same for every encounter and have one row (1, K).

    Row ``n`` has its own ``jl_row[n]`` / ``jh_row[n]`` candidates per side (at most ``j_lo`` / ``j_hi``, the
    columns' counts) and its paths ``max(jl_row[n], jh_row[n])`` knot intervals: its outputs are those of a
    call of its own, over its own candidates (columns ``j_lo - jl_row[n]`` .. ``j_lo + jh_row[n]``); the columns
    past them repeat the row's outermost candidate on that side (every field, so every reading of the bands
    -- a scan from the current value, a minimum, a band interval of zero width -- finds what it would find
    without them)."""
    src_in, src_out, seg_in, seg_out = conflicts
    near_list, mid_list, alert2 = lists
    L, warn, corr, sm_h, stab, pi_cut, two_pi = times
    j_lo, j_hi = counts
    jl_row, jh_row = rows
    dgrid, axis, rate, lim_lo, lim_hi, do_clip, clip_lo, clip_hi = ax
    values, delta, t_man, t_in_all, t_out_c = fields
    region, gap = codes
    res_lo, res_hi = res
    N = values.shape[0]
    Kn = tk.shape[0]
    K = j_lo + j_hi + 1
    k0 = j_lo
    red_near = np.empty(K, np.bool_)
    red_mid = np.empty(K, np.bool_)
    g_near = np.empty(K, np.bool_)
    g_mid = np.empty(K, np.bool_)
    ok = np.empty(K, np.bool_)
    rec = np.empty(K, np.bool_)
    ti, to = np.empty((M, 2, Kn)), np.empty((M, 2, Kn))
    ti1, to1 = ti.reshape(-1), to.reshape(-1)
    # per column: side, knot, and for a track candidate its change (rad) and maneuver time (s)
    c_sgn, c_tk, c_th, c_tm = np.empty(K), np.empty(K), np.empty(K), np.empty(K)
    for c in range(K):
        sgn = -1.0 if c < j_lo else 1.0
        tc_k = tk[j_lo - c] if c < j_lo else tk[c - j_lo]
        c_sgn[c], c_tk[c] = sgn, tc_k
        if axis == _HORIZONTAL:
            th = sgn * (rate * tc_k)
            c_th[c], c_tm[c] = th, abs(th) / rate
            delta[0, c], t_man[0, c] = th, c_tm[c]  # (one row: the same for every encounter)
    row_len = M * 2 * Kn
    for n in range(N):
        # this row's own candidates (max(., 0): the compiler then knows a column index is never negative)
        c_lo, c_hi = k0 - jl_row[n], k0 + jh_row[n]
        kn = max(c_hi - k0, k0 - c_lo) + 1  # this row's paths' knots
        # -- the candidates' conflicts of this row (M, 2, J+1) ----------------------------------------------
        if from_paths:
            for m in range(M):
                for p in range(2):
                    path = (n * M + m) * 2 + p
                    candidates_path(src_in, src_out, seg_in, seg_out, path * Kn, path * (Kn - 1), kn, t_end, ti1,
                                    to1, (m * 2 + p) * Kn)
        else:
            for i in range(row_len):
                ti1[i], to1[i] = src_in[n * row_len + i], src_out[n * row_len + i]
        # -- regions from the conflicts per intruder ---------------------------------------------------
        for c in range(c_hi + 1):
            if c < c_lo:  # (from 0: the compiler then knows a column index is never negative)
                continue
            p, k = (0, j_lo - c) if c < j_lo else (1, c - j_lo)
            rn, rm = False, False
            a_in, a_out = INF, -INF
            for m in range(M):
                tv = ti[m, p, k]
                if hfm:
                    hn = L if near_list[n, m] else npmin(L, warn + tk[k])
                    hm = L if mid_list[n, m] else npmin(L, corr + tk[k])
                    r_near_i, r_mid_i = tv < hn, tv < hm
                    rm = rm or r_mid_i
                else:
                    r_mid_i = tv < (L if alert2[n, m] else corr)
                    r_near_i = tv < warn
                    rm = rm or (r_near_i or r_mid_i)
                rn = rn or r_near_i
                t_o = to[m, p, k] if (r_mid_i or r_near_i) else -INF
                # np.min / np.max over the intruders: the first one, then np.minimum / np.maximum
                a_in = tv if m == 0 else npmin(a_in, tv)
                a_out = t_o if m == 0 else npmax(a_out, t_o)
            red_near[c], red_mid[c] = rn, rm
            t_in_all[n, c], t_out_c[n, c] = a_in, a_out
        for c in range(c_hi + 1):
            if c < c_lo:  # (from 0: the compiler then knows a column index is never negative)
                continue
            gn, gm = not red_near[c], not red_mid[c]
            if dgrid:  # a run of one green candidate is not a band (recovery.drop_isolated)
                gn = gn and ((c > c_lo and not red_near[c - 1]) or (c < c_hi and not red_near[c + 1]))
                gm = gm and ((c > c_lo and not red_mid[c - 1]) or (c < c_hi and not red_mid[c + 1]))
            g_near[c], g_mid[c] = gn, gm
            region[n, c] = NEAR if not gn else (MID if not gm else NONE)
        # -- candidate values (bands._candidate_values) ----------------------------------------------------
        if axis == _HORIZONTAL:
            for c in range(c_hi + 1):
                if c < c_lo:  # (from 0: the compiler then knows a column index is never negative)
                    continue
                th = c_th[c]
                v = cur[n] + th
                if v < 0.0:
                    v = v + two_pi
                elif v >= two_pi:
                    v = v - two_pi
                values[n, c] = v
        else:
            v0 = cur[n]
            cap_lo = npmax((lim_lo - v0) * -1.0 / rate, 0.0)  # each side's time to its limit (s)
            cap_hi = npmax((lim_hi - v0) * 1.0 / rate, 0.0)
            for c in range(c_hi + 1):
                if c < c_lo:  # (from 0: the compiler then knows a column index is never negative)
                    continue
                sgn = c_sgn[c]
                tc = npmin(c_tk[c], cap_lo if sgn < 0 else cap_hi)
                v = v0 + sgn * rate * tc
                d = v - v0
                values[n, c] = npmin(npmax(v, clip_lo), clip_hi) if do_clip else v
                delta[n, c] = d
                t_man[n, c] = abs(d) / rate
        # -- recovery: every candidate MID or worse (earliest exit) ----------------------------------------
        saturated = True
        for c in range(c_hi + 1):
            if c < c_lo:  # (from 0: the compiler then knows a column index is never negative)
                continue
            saturated = saturated and region[n, c] >= MID
        any_late = False
        best = 0.0
        for c in range(c_hi + 1):
            if c < c_lo:  # (from 0: the compiler then knows a column index is never negative)
                continue
            any_late = any_late or t_in_all[n, c] > sm_h
            best = t_out_c[n, c] if c == c_lo else npmin(best, t_out_c[n, c])
        for c in range(c_hi + 1):
            if c < c_lo:  # (from 0: the compiler then knows a column index is never negative)
                continue
            late = t_in_all[n, c] > sm_h
            rec[c] = saturated and (late if any_late else t_out_c[n, c] <= best + stab)
            if rec[c]:
                region[n, c] = RECOVERY
        if dgrid:
            for c in range(c_hi):
                if c < c_lo:  # (from 0: the compiler then knows a column index is never negative)
                    continue
                if rec[c] and rec[c + 1]:
                    gap[n, c] = RECOVERY
                elif not (g_near[c] and g_near[c + 1]):
                    gap[n, c] = NEAR
                elif not (g_mid[c] and g_mid[c + 1]):
                    gap[n, c] = MID
                else:
                    gap[n, c] = NONE
        # -- resolutions (bands.resolutions) ---------------------------------------------------------------
        cr = region[n, k0]
        conflict = cr == MID or cr == NEAR
        for c in range(c_hi + 1):
            if c < c_lo:  # (from 0: the compiler then knows a column index is never negative)
                continue
            r = region[n, c]
            ok[c] = r == NONE or r == RECOVERY
            if axis == _HORIZONTAL and dgrid:
                ok[c] = ok[c] and abs(c_th[c]) < pi_cut
        i_lo, f_lo = first_ok(ok, k0, -1, c_lo, c_hi)
        i_hi, f_hi = first_ok(ok, k0, 1, c_lo, c_hi)
        if conflict:
            res_lo[n] = values[n, i_lo] if f_lo else -INF
            res_hi[n] = values[n, i_hi] if f_hi else INF
        else:
            res_lo[n], res_hi[n] = np.nan, np.nan
        d_lo, d_hi = (c_tm[i_lo], c_tm[i_hi]) if axis == _HORIZONTAL else (t_man[n, i_lo], t_man[n, i_hi])
        hi_first = d_hi <= d_lo + 1e-9 * npmax(d_lo, 1.0)
        if f_lo and f_hi:
            pr = 1 if hi_first else -1
        else:
            pr = 1 if f_hi else (-1 if f_lo else 0)
        pref[n] = pr if conflict else 0
        # -- the columns past this row's candidates repeat its outermost one on that side ----------------
        for c in range(0, c_lo):
            _repeat(n, c, c_lo, axis, values, delta, t_man, t_in_all, t_out_c, region)
            if dgrid:
                gap[n, c] = region[n, c_lo]
        for c in range(c_hi + 1, K):
            _repeat(n, c, c_hi, axis, values, delta, t_man, t_in_all, t_out_c, region)
            if dgrid:
                gap[n, c - 1] = region[n, c_hi]
