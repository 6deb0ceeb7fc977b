"""DAIDALUS's shrinking-cylinder recovery for the rows of one band axis, compiled: the bisection of one
cylinder's recovery time (:func:`pivot_search_into`: per row, the earliest time B (to 0.5 s) at which some
candidate avoids the cylinder on [0, B] and the corrective volume after B, then the candidates that do so at
the recovery time), and the rows' whole search from their conflicts (:func:`cylinder_prepare_into`,
:func:`cylinder_step_into`, :func:`cylinder_finish_into`: what the evaluator's path of
:func:`daa_sil.daa.bands.axis_bands` computes for a saturated row, read per row). The numpy reference is that
path (:class:`daa_sil.daa.recovery.CylinderRecovery`, its ``_at_pivot``, ``_green`` and the loop of ``run``,
and the regions and resolutions of ``axis_bands``), with its operations in their order; each row is
bisected on its own (the reference halves the rows that are still going and leaves the others as they
are, so a row's steps are its own there too).
"""

from __future__ import annotations

import numpy as np
from numba import boolean, int8, types, void

from daa_sil.daa.kernels.evaluate import candidates_path
from daa_sil.daa.kernels.jit import inline, kernel
from daa_sil.daa.kernels.regions import MID, NEAR, NONE, RECOVERY, first_ok
from daa_sil.daa.kernels.scalar import INF, npmax, npmin
from daa_sil.daa.kernels.signatures import A, A2, A4, B2, IA, O, O2, F, I, B

_R4 = types.Array(boolean, 4, "A", readonly=True)
_BW1 = types.Array(boolean, 1, "C")
_BW2 = types.Array(boolean, 2, "C")
_O4 = types.Array(types.float64, 4, "C")


@inline
def _columns(red, shape, dgrid, out):
    """Green columns (K,) into ``out`` from red ``(2, J+1)`` (path 0 = low side, 1 = high side; the columns
    ordered low side outward in, current, high side: ``bands._side_order``), isolated ones dropped on the
    DAIDALUS grid (``recovery.drop_isolated``). Returns whether one is green."""
    j_lo, j_hi = shape
    K = j_lo + j_hi + 1
    some = False
    for col in range(K):
        p, k = (0, j_lo - col) if col < j_lo else (1, col - j_lo)
        g = not red[p, k]
        if dgrid and g:  # a run of one green candidate is not a band (recovery.drop_isolated)
            left = col > 0 and not (red[0, j_lo - col + 1] if col - 1 < j_lo else red[1, col - 1 - j_lo])
            right = col < K - 1 and not (red[0, j_lo - col - 1] if col + 1 < j_lo else red[1, col + 1 - j_lo])
            g = left or right
        out[col] = g
        some = some or g
    return some


@inline
def _green(corr, r, cyl, c, red_only, horizon, listed, shape, dgrid, B, red, out):
    """``CylinderRecovery._at_pivot`` of row ``r`` (row ``c`` of the cylinder's arrays) at time ``B`` (s): the
    candidates (K,) into ``out``, green where the candidate avoids the cylinder on [0, B] and the corrective
    volume after B (past an intruder's horizon, its cylinder only), isolated ones dropped on the DAIDALUS
    grid. Returns whether one is green. ``red`` (2, J+1) is a working array."""
    c_pre_out, c_in, c_out, tk, window = corr
    pre_in, t_in, t_out = cyl
    M, J1 = red_only.shape[1], red_only.shape[3]
    red[:, :] = False
    for m in range(M):
        if not listed[r, m]:
            continue
        past = B > horizon[r, m]
        for p in range(2):
            for k in range(J1):
                if past:
                    rd = red_only[c, m, p, k]
                else:
                    rd = (c_pre_out[r, m, p, k] > B) or (pre_in[c, m, p, k] < B)
                    rd = rd or (npmax(c_in[r, m, p, k], B) < npmin(c_out[r, m, p, k], window[r, m, p, k]))
                    rd = rd or ((tk[r, m, p, k] < B) and (t_in[c, m, p, k] < npmin(t_out[c, m, p, k], B)))
                if rd:
                    red[p, k] = True
    return _columns(red, shape, dgrid, out)


@inline
def _bisect(corr, r, cyl, c, red_only, horizon, listed, shape, dgrid, L, stab, red, buf, green_row):
    """The recovery time (s) of row ``r`` (row ``c`` of the cylinder's arrays), its green candidates into
    ``green_row`` (:func:`pivot_search_into`)."""
    red_p, green_p, pivot = 0.0, L + 1.0, L
    while green_p - red_p > 0.5:
        if _green(corr, r, cyl, c, red_only, horizon, listed, shape, dgrid, pivot, red, buf):
            green_p = pivot
        else:
            red_p = pivot
        pivot = 0.5 * (red_p + green_p)
    rt = npmin(L, green_p + stab) if green_p <= L else red_p
    _green(corr, r, cyl, c, red_only, horizon, listed, shape, dgrid, rt, red, green_row)
    return rt


@kernel(void(types.UniTuple(A4, 5), IA, types.UniTuple(A4, 3), _R4, A2, B2, types.UniTuple(I, 2), boolean,
             types.UniTuple(F, 2), O, types.Array(boolean, 2, "C")), lazy=True)
def pivot_search_into(corr, rows, cyl, red_only, horizon, listed, shape, dgrid, times, rt_out, green_out):
    """For each row ``c`` (row ``rows[c]`` of the recovery's arrays): the recovery time (s) into ``rt_out[c]``
    and its green candidates into ``green_out[c]``. ``corr`` = the corrective volume's ``(prefix of last
    exits, tail entries, tail exits)``, the knot times and the detector windows ``(R, M, 2, J+1)``; ``cyl`` =
    the cylinder's ``(prefix of first entries, tail entries, tail exits)`` and ``red_only`` (red as the
    conflict detector over its window) of the rows, ``(len(rows), M, 2, J+1)``; ``horizon``/``listed`` (R, M)
    each intruder's time horizon (s) and whether the MID bands consider it; ``shape`` = ``(j_lo, j_hi)``;
    ``dgrid`` the DAIDALUS grid; ``times`` = ``(lookahead, recovery stability)`` s."""
    L, stab = times
    red = np.empty((2, red_only.shape[3]), np.bool_)
    buf = np.empty(green_out.shape[1], np.bool_)
    for c in range(rows.shape[0]):
        rt_out[c] = _bisect(corr, rows[c], cyl, c, red_only, horizon, listed, shape, dgrid, L, stab, red, buf,
                            green_out[c])


#: ``cylinder_prepare_into``'s records: the corrective volume's conflicts ``(tail_in, tail_out, seg_in, seg_out)``,
#: the lists ``(near, mid, alert2)``, the times ``(L, warn, corr)``, the outputs ``(g_near, g_mid)``, ``(listed,
#: horizon)``, ``(c_pre_out, window)``
_CONFLICTS = types.UniTuple(A, 4)
_LISTS = types.UniTuple(B2, 3)


@kernel(void(_CONFLICTS, boolean, _LISTS, A, types.UniTuple(F, 3), types.UniTuple(I, 2), boolean,
             types.UniTuple(_BW2, 2), types.Tuple((_BW2, O2)), types.UniTuple(_O4, 2), _BW1), lazy=True)
def cylinder_prepare_into(conflicts, hfm, lists, tk, times, shape, dgrid, greens, who, corr_out, saturated):
    """What the evaluator's path of ``bands.axis_bands`` (cylinder recovery) computes before the search, for
    R rows whose paths' corrective-volume conflicts are ``conflicts`` (flat over (R, M, 2, J+1) / (R, M, 2, J),
    every row with all ``shape`` = ``(j_lo, j_hi)`` candidates, knot times ``tk`` (J+1,)): the green columns
    ``greens`` = ``(g_near, g_mid)`` (R, K) (isolated ones dropped with ``dgrid``), ``who`` = ``(listed, horizon)``
    (R, M): the intruders the MID bands consider and their time horizons (s), ``corr_out`` = ``(c_pre_out,
    window)`` (R, M, 2, J+1): the last exit on the maneuver up to each knot and each candidate's detector
    window end (s), and whether the row is ``saturated`` (no NEAR-green or no MID-green candidate).
    ``lists`` = ``(near_list, mid_list, alert2)`` (R, M): the conflict lists (``hfm``) or alert level >= 2;
    ``times`` = ``(lookahead, warning, corrective alerting time)`` s."""
    tail_in, tail_out, seg_in, seg_out = conflicts
    near_list, mid_list, alert2 = lists
    L, warn, corr = times
    g_near, g_mid = greens
    listed, horizon = who
    c_pre_out, window = corr_out
    R, M, J1 = c_pre_out.shape[0], c_pre_out.shape[1], c_pre_out.shape[3]
    ti, to = np.empty(M * 2 * J1), np.empty(M * 2 * J1)
    red_near, red_mid = np.empty((2, J1), np.bool_), np.empty((2, J1), np.bool_)
    for r in range(R):
        red_near[:, :] = False
        red_mid[:, :] = False
        for m in range(M):
            mid_flag = mid_list[r, m] if hfm else alert2[r, m]
            hor = L if mid_flag else min(L, corr)
            horizon[r, m] = hor
            mid_seen = False
            for p in range(2):
                path = (r * M + m) * 2 + p
                ob = (m * 2 + p) * J1
                candidates_path(tail_in, tail_out, seg_in, seg_out, path * J1, path * (J1 - 1), J1, L, ti, to, ob)
                acc = -INF
                for k in range(J1):
                    if k > 0:  # (PathConflicts.prefix: np.maximum.accumulate of the segments' last exits)
                        s = seg_out[path * (J1 - 1) + k - 1]
                        acc = s if k == 1 else npmax(acc, s)
                    c_pre_out[r, m, p, k] = acc
                    window[r, m, p, k] = npmin(L, hor + tk[k])
                    tv = ti[ob + k]
                    if hfm:
                        rn = tv < (L if near_list[r, m] else npmin(L, warn + tk[k]))
                        rm = tv < (L if mid_list[r, m] else npmin(L, corr + tk[k]))
                        red_mid[p, k] = red_mid[p, k] or rm
                    else:
                        rm = tv < (L if alert2[r, m] else corr)
                        rn = tv < warn
                        red_mid[p, k] = red_mid[p, k] or (rn or rm)
                    red_near[p, k] = red_near[p, k] or rn
                    mid_seen = mid_seen or rm
            listed[r, m] = mid_flag or mid_seen
        any_near = _columns(red_near, shape, dgrid, g_near[r])
        any_mid = _columns(red_mid, shape, dgrid, g_mid[r])
        saturated[r] = not any_near or not any_mid


@kernel(void(types.UniTuple(A4, 5), IA, types.UniTuple(A, 3), A2, B2, types.UniTuple(I, 2), boolean,
             types.UniTuple(F, 2), boolean, _BW1, O, _BW2), lazy=True)
def cylinder_step_into(corr, rows, cyl, horizon, listed, shape, dgrid, times, search, some, rt_out, green_out):
    """One cylinder of the search for rows ``rows`` (of the recovery's R rows): ``cyl`` = the cylinder's
    ``(tail_in, tail_out, seg_in)`` of those rows' paths (flat over (len(rows), M, 2, J+1) / (len(rows), M, 2,
    J)); whether some candidate of row ``c`` is clear of it as the conflict detector over its window into
    ``some[c]`` (``CylinderRecovery._cylinder`` and ``_green``), and with ``search``, for the rows where one is,
    the recovery time and its green candidates into ``rt_out[c]`` / ``green_out[c]`` (:func:`pivot_search_into`;
    the other rows' green candidates are all False). ``corr``, ``horizon``, ``listed``, ``shape``, ``dgrid``,
    ``times``: as :func:`pivot_search_into`'s."""
    tail_in, tail_out, seg_in = cyl
    L, stab = times
    M, J1 = listed.shape[1], corr[0].shape[3]
    window = corr[4]
    pre_in, t_in, t_out = np.empty((1, M, 2, J1)), np.empty((1, M, 2, J1)), np.empty((1, M, 2, J1))
    red_only = np.empty((1, M, 2, J1), np.bool_)
    red = np.empty((2, J1), np.bool_)
    buf = np.empty(green_out.shape[1], np.bool_)
    for c in range(rows.shape[0]):
        r = rows[c]
        red[:, :] = False
        for m in range(M):
            for p in range(2):
                path = (c * M + m) * 2 + p
                acc = INF
                for k in range(J1):
                    if k > 0:  # (PathConflicts.prefix_in: np.minimum.accumulate of the segments' first entries)
                        s = seg_in[path * (J1 - 1) + k - 1]
                        acc = s if k == 1 else npmin(acc, s)
                    a, b = tail_in[path * J1 + k], tail_out[path * J1 + k]
                    w = window[r, m, p, k]
                    ro = (acc < w) or (a < npmin(b, w))
                    pre_in[0, m, p, k], t_in[0, m, p, k], t_out[0, m, p, k], red_only[0, m, p, k] = acc, a, b, ro
                    if ro and listed[r, m]:
                        red[p, k] = True
        some[c] = _columns(red, shape, dgrid, buf)
        green_out[c, :] = False
        rt_out[c] = -INF
        if search and some[c]:
            rt_out[c] = _bisect(corr, r, (pre_in, t_in, t_out), 0, red_only, horizon, listed, shape, dgrid, L, stab,
                                red, buf, green_out[c])


@kernel(void(types.UniTuple(_BW2, 3), IA, A2, A2, A2, types.Tuple((I, boolean, boolean, F)), types.Array(int8, 2, "C"),
             types.Array(int8, 2, "C"), types.UniTuple(O, 2), types.Array(int8, 1, "C")), lazy=True)
def cylinder_finish_into(greens, idx, values, delta, t_man, ax, region, gap, res, pref):
    """The regions, gap regions (``gap`` with columns; none when it has no row), resolutions and preferred
    sides of rows ``idx[c]`` of an axis's bands (written in place) from their ``greens`` = ``(g_near, g_mid,
    rec_green)`` (len(idx), K) and their candidates' ``values``/``delta``/``t_man`` (rows ``idx``): the end of
    the evaluator's path of ``bands.axis_bands`` with the cylinder recovery, then ``bands.resolutions``. ``ax``
    = ``(k0, horizontal, dgrid, pi_cut)``; ``res`` = ``(res_lo, res_hi)``."""
    g_near, g_mid, rec = greens
    k0, horizontal, dgrid, pi_cut = ax
    res_lo, res_hi = res
    K = g_near.shape[1]
    ok = np.empty(K, np.bool_)
    with_gap = gap.shape[0] > 0
    for c in range(idx.shape[0]):
        n = idx[c]
        for k in range(K):
            rg = NEAR if not g_near[c, k] else (MID if not g_mid[c, k] else NONE)
            if rec[c, k]:
                rg = RECOVERY
            region[n, k] = rg
            ok[k] = rg == NONE or rg == RECOVERY
            if horizontal and dgrid:
                ok[k] = ok[k] and abs(delta[n, k]) < pi_cut
        if with_gap:
            for k in range(K - 1):
                if rec[c, k] and rec[c, k + 1]:
                    gap[n, k] = RECOVERY
                elif not (g_near[c, k] and g_near[c, k + 1]):
                    gap[n, k] = NEAR
                elif not (g_mid[c, k] and g_mid[c, k + 1]):
                    gap[n, k] = MID
                else:
                    gap[n, k] = NONE
        cr = region[n, k0]
        conflict = cr == MID or cr == NEAR
        i_lo, f_lo = first_ok(ok, k0, -1, 0, K - 1)
        i_hi, f_hi = first_ok(ok, k0, 1, 0, K - 1)
        if conflict:
            res_lo[n] = values[n, i_lo] if f_lo else -INF
            res_hi[n] = values[n, i_hi] if f_hi else INF
        else:
            res_lo[n], res_hi[n] = np.nan, np.nan
        d_lo, d_hi = t_man[n, i_lo], t_man[n, i_hi]
        hi_first = d_hi <= d_lo + 1e-9 * npmax(d_lo, 1.0)
        if f_lo and f_hi:
            pr = 1 if hi_first else -1
        else:
            pr = 1 if f_hi else (-1 if f_lo else 0)
        pref[n] = pr if conflict else 0
