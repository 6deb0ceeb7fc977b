"""The undecided pieces of a maneuver path resolved on the true state, in one compiled pass.

The numpy reference is :meth:`daa_sil.daa.undecided.UndecidedPieces.resolve_reference` (its
``_bisect``, ``_classify_part``, ``_clear2``, ``_split`` and ``_clip``). The kernel keeps its phase
structure, not only its per-piece arithmetic: the pieces of one depth are processed as one batch,
and what the reference decides for several pieces at once is decided per encounter (group), from that
encounter's pieces alone -- the number of halvings of a bisection (from the encounter's widest bracket,
per kind), the number of parts a split makes (from its longest piece), the clip sampling count, and
whether the vertical position error ``e_z`` is used (``np.any`` of its rows' vertical accelerations) --
so that an encounter's intervals are those of a call of its own. ``ceil(log2(x))`` of a bisection's
halvings is read from a table of the thresholds where numpy's ``log2`` passes each integer
(``undecided.bisect_thresholds``), so it is numpy's, not libm's.

Rows ``r`` are the undecided segments the call starts with; every piece split from a segment keeps
its row (the motion, acceleration bounds, jerk, kinks, vertical window and encounter of its path).
"""

from __future__ import annotations

import math

import numpy as np
from numba import boolean, float64, int64, types, void

from daa_sil.daa.kernels.jit import inline, inline_ir, kernel
from daa_sil.daa.kernels.motion import axis_rel, axis_row, command_rel, command_row, intruder_row, row_limit_time
from daa_sil.daa.kernels.pieces import CLEAR, classify, clear2
from daa_sil.daa.kernels.scalar import INF, halve, npmax, npmin, wcv_soa
from daa_sil.daa.kernels.signatures import A, A2, A3, IA, O, F, I, B

_B1 = types.Array(boolean, 1, "A", readonly=True)


#: motion kinds: a band axis's path (kernels.motion.rel_state) or a command (command_rel_state)
KIND_AXIS, KIND_COMMAND = 0, 1
#: ``settle_time * (1 + 1e-9)`` of the reference, the factor computed in Python
SETTLE_SLACK = 1.0 + 1e-9


#: placeholders for the motion of the kind of path a call does not use (:func:`_motion_row`)
_NO_AXIS_ROW = (0.0,) * 9
_NO_COMMAND_ROW = ((0.0,) * 9, (0.0,) * 9, (0.0,) * 9, (0.0,) * 7)


@inline
def _motion_row(kind, axis, rate, kin, ph, enc, ipv, mi, ii, r):
    """Row ``r``'s motion (row ``mi[r]`` of ``kin`` with its time to its limit, s, or of ``ph``/``enc``) and
    intruder (row ``ii[r]`` of ``ipv``) as tuples of floats, for :func:`_rel` (loaded once per row)."""
    if kind == KIND_AXIS:
        arow = axis_row(kin, mi[r])
        return arow, row_limit_time(axis, rate, arow), _NO_COMMAND_ROW, intruder_row(ipv, ii[r])
    return _NO_AXIS_ROW, 0.0, command_row(ph, enc, mi[r]), intruder_row(ipv, ii[r])


@inline
def _take(buf, cur, j, n):
    """``n`` elements of ``buf`` from cursor ``cur[j]`` (a fresh array when ``buf`` is too small); the cursor
    moves by ``n`` either way, so that at the end it tells how large ``buf`` should be."""
    off = cur[j]
    cur[j] = off + n
    if off + n <= buf.shape[0]:
        return buf[off:off + n]
    return np.empty(n, buf.dtype)


@inline_ir
def _rel(kind, axis, rate, mrow, max_turn, h_acc, v_acc, t):
    """Relative state at ``t`` of the row whose :func:`_motion_row` is ``mrow``."""
    arow, cap, crow, iv = mrow
    if kind == KIND_AXIS:
        return axis_rel(axis, rate, arow, cap, iv, t)
    return command_rel(crow, iv, t, max_turn, h_acc, v_acc)


@inline
def _settle(ah, av, v2, p8):
    """certify.settle_time of one path (``v2`` = 2 V_TOL, ``p8`` = 8 P_TOL, Python products)."""
    t_v = v2 / ah if ah > 0 else INF
    a = npmax(ah, av)
    t_p = math.sqrt(p8 / a) if a > 0 else INF
    return npmin(t_v, t_p)


@inline
def _max_acc(acc, x):
    """One step of ``np.max`` (nan wins)."""
    if acc != acc:
        return acc
    if x != x or x > acc:
        return x
    return acc


@inline
def _halvings(wmax, dt, thr):
    """``int(np.ceil(np.log2(max(wmax, dt) / dt)))`` (``thr[n]``: smallest x with log2(x) > n)."""
    x = (dt if dt > wmax else wmax) / dt
    n = 0
    while n < thr.shape[0] and x >= thr[n]:
        n += 1
    return n


@inline
def _update(a, b, t_in, t_out):
    """``np.minimum.at`` / ``np.maximum.at`` of one entry ``(a, b)`` -> its new ``(a, b)``."""
    return (a if (a != a or a < t_in) else t_in), (b if (b != b or b > t_out) else t_out)


@inline
def _own_halvings(steps, mixed, flag, n_in, n_out, a, b):
    """The halvings of :func:`_bisect` that can move the bracket ``[a, b]`` (s) of a row starting inside
    (``flag``) or outside: in a ``mixed`` batch :func:`~daa_sil.daa.kernels.scalar.halve` leaves a bracket
    unchanged from its kind's count on, and the predicate evaluated there is not kept (its state is
    kept only when an end moves), so those steps are skipped; all ``steps`` when an end is nan (an
    unchanged nan end compares unequal to itself, as the full loop would see it)."""
    if mixed and a == a and b == b:
        return n_out if flag else n_in
    return steps


@inline
def _bisect(kind, axis, rate, kin, ph, enc, max_turn, h_acc, v_acc, ipv, mi, ii, row, lo, hi, lo_in, grp, n_grp, thr,
            dt_in, dt_out, DD, TT, H, TC, clear_pos, have_pos):
    """``UndecidedPieces._bisect`` of the rows ``row`` (one batch): ``lo``/``hi`` halved in place, each
    encounter (``grp`` of a row, ``n_grp`` of them) with the halvings of its own widest brackets. The relative
    position at the end of the final bracket outside the volume (``lo`` of an entry, ``hi`` of an exit) goes
    to ``clear_pos`` (3, n) when a halving put that end there (``have_pos``; else it is still the start's)."""
    n = lo.shape[0]
    w_in, w_out = np.zeros(n_grp), np.zeros(n_grp)
    any_in, any_out = np.zeros(n_grp, np.bool_), np.zeros(n_grp, np.bool_)
    for i in range(n):
        g = grp[row[i]]
        if lo_in[i]:
            w_out[g] = _max_acc(w_out[g], hi[i] - lo[i])
            any_out[g] = True
        else:
            w_in[g] = _max_acc(w_in[g], hi[i] - lo[i])
            any_in[g] = True
    g_in, g_out = np.zeros(n_grp, np.int64), np.zeros(n_grp, np.int64)
    g_mixed = np.zeros(n_grp, np.bool_)
    for g in range(n_grp):
        if any_in[g] or any_out[g]:
            g_in[g], g_out[g] = _halvings(w_in[g], dt_in, thr), _halvings(w_out[g], dt_out, thr)
            g_mixed[g] = g_in[g] != g_out[g] and any_in[g] and any_out[g]
    for i in range(n):
        a, b, flag = lo[i], hi[i], lo_in[i]
        r = row[i]
        g = grp[r]
        n_in, n_out, mixed = g_in[g], g_out[g], g_mixed[g]
        steps = max(n_in, n_out)
        mrow = _motion_row(kind, axis, rate, kin, ph, enc, ipv, mi, ii, r)
        have_pos[i] = False
        for k in range(_own_halvings(steps, mixed, flag, n_in, n_out, a, b)):
            mid = 0.5 * (a + b)
            sx, sy, sz, vx, vy, vz = _rel(kind, axis, rate, mrow, max_turn, h_acc, v_acc, mid)
            inside = wcv_soa(sx, sy, sz, vx, vy, vz, DD, TT, H, TC)
            a2, b2 = halve(a, b, mid, inside == flag, k, mixed, flag, n_in, n_out)
            if not inside and (a2 != a or b2 != b):  # the end outside moved to mid
                clear_pos[0, i], clear_pos[1, i], clear_pos[2, i] = sx, sy, sz
                have_pos[i] = True
            a, b = a2, b2
        lo[i], hi[i] = a, b


@inline
def _any_nonzero(acc_v, row, sel, grp, n_grp):
    """Per encounter: ``np.any`` of the vertical accelerations of its rows among pieces ``sel``."""
    out = np.zeros(n_grp, np.bool_)
    for i in sel:
        if acc_v[row[i]] != 0.0:
            out[grp[row[i]]] = True
    return out


@inline
def _classify_part(a_h, a_v, anyv, has_vwin, w_lo, w_hi, ta, tb, x0, y0, z0, x1, y1, z1, D, DD, H, TT, TC):
    """``UndecidedPieces._classify_part`` of one piece (``anyv``: ``np.any`` of its encounter's a_v)."""
    h = tb - ta
    lo, hi = 0.0, 0.0
    if has_vwin:
        lo, hi = npmax(w_lo, ta) - ta, npmin(w_hi, tb) - ta
    e_z = a_v * h * h * 0.125 if anyv else 0.0
    return classify(x0, y0, z0, x1, y1, z1, h, a_h * h * h * 0.125, a_h * h * 0.5, e_z, lo, hi, has_vwin,
                    D, DD, H, TT, TC)


@inline
def _clip(kind, axis, rate, kin, ph, enc, max_turn, h_acc, v_acc, ipv, mi, ii, final, row, ta, tb, grp, n_grp, thr,
          dt_in, dt_out, clip_dt, DD, TT, H, TC, row_in, row_out):
    """``UndecidedPieces._clip`` of pieces ``final``: sampled every ``clip_dt`` (each encounter's count from
    its longest piece), the first and last violating samples bracketed and bisected (entries, then exits,
    each as one batch)."""
    nf = final.shape[0]
    hmax = np.zeros(n_grp)
    seen = np.zeros(n_grp, np.bool_)
    for c in range(nf):
        i = final[c]
        g = grp[row[i]]
        hmax[g] = (tb[i] - ta[i]) if not seen[g] else _max_acc(hmax[g], tb[i] - ta[i])
        seen[g] = True
    b1, t1 = np.empty(nf), np.empty(nf)  # entry brackets (before, first sample inside)
    t2, a2 = np.empty(nf), np.empty(nf)  # exit brackets (last sample inside, after)
    hrow = np.empty(nf, np.int64)
    nh = 0
    for c in range(nf):
        i = final[c]
        r = row[i]
        qf = np.ceil(hmax[grp[r]] / clip_dt - 1e-9)
        if not (qf >= 1):
            continue
        q = int(qf)
        mrow = _motion_row(kind, axis, rate, kin, ph, enc, ipv, mi, ii, r)
        h = tb[i] - ta[i]
        first, lastk = -1, -1
        t_prev_first, t_first, t_last, t_after = ta[i], 0.0, 0.0, tb[i]
        t_prev = ta[i]
        pending_after = False
        for k in range(q):
            t = ta[i] + h * ((float(k) + 0.5) / q)
            if pending_after:
                t_after = t
                pending_after = False
            sx, sy, sz, vx, vy, vz = _rel(kind, axis, rate, mrow, max_turn, h_acc, v_acc, t)
            if wcv_soa(sx, sy, sz, vx, vy, vz, DD, TT, H, TC):
                if first < 0:
                    first, t_first = k, t
                    t_prev_first = t_prev if k > 0 else ta[i]
                lastk, t_last = k, t
                t_after = tb[i]
                pending_after = k < q - 1
            t_prev = t
        if first >= 0:
            b1[nh], t1[nh], t2[nh], a2[nh] = t_prev_first, t_first, t_last, t_after
            hrow[nh] = r
            nh += 1
    if nh == 0:
        return
    l1, h1, l2, h2, hr = b1[:nh].copy(), t1[:nh].copy(), t2[:nh].copy(), a2[:nh].copy(), hrow[:nh].copy()
    pos, have = np.empty((3, nh)), np.empty(nh, np.bool_)  # (not read)
    _bisect(kind, axis, rate, kin, ph, enc, max_turn, h_acc, v_acc, ipv, mi, ii, hr, l1, h1, np.zeros(nh, np.bool_),
            grp, n_grp, thr, dt_in, dt_out, DD, TT, H, TC, pos, have)
    _bisect(kind, axis, rate, kin, ph, enc, max_turn, h_acc, v_acc, ipv, mi, ii, hr, l2, h2, np.ones(nh, np.bool_),
            grp, n_grp, thr, dt_in, dt_out, DD, TT, H, TC, pos, have)
    for c in range(nh):
        r = hr[c]
        row_in[r], row_out[r] = _update(row_in[r], row_out[r], 0.5 * (l1[c] + h1[c]), 0.5 * (l2[c] + h2[c]))


@kernel(void(I, I, F, A2, A3, A2, F, F, F, A2, IA, IA,
             A, A, A, A, A, A, A, IA, IA,
             A, A, B, A, B, A2, _B1, A, A,
             IA, I, B, A, I, I, F, F, F, F, F,
             F, F, F, F, F, O, O, types.Array(float64, 1, "C"), types.Array(int64, 1, "C"),
             types.Array(boolean, 1, "C"), types.Array(int64, 1, "C")))
def resolve_into(kind, axis, rate, kin, ph, enc, max_turn, h_acc, v_acc, ipv, mi, ii,
                 s0, s1, s2, v0, v1, v2, tk, seg, ka,
                 acc_h, acc_v, has_jerk, jerk, has_kink, kink, von, vlo, vhi, grp, n_grp,
                 exits, thr, max_depth, max_split, dt_in, dt_out, clip_dt, v2tol, p8tol,
                 D, DD, H, TT, TC, seg_in, seg_out, fbuf, ibuf, bbuf, need):
    """Resolve the undecided segments ``seg`` (flat segment ids; ``ka`` their first knots' flat indices
    into the knot arrays ``s*``/``v*``/``tk``) into ``seg_in``/``seg_out`` (the reference's docstring).
    Row ``r``'s motion is row ``mi[r]`` of ``kin_all`` (``kind`` axis) or of ``ph_all``/``enc_all`` (command),
    against intruder row ``ii[r]`` of ``ipv_all``; ``acc_h`` ... ``vhi`` are per row (``von``: the row's path has a
    vertical window ``vlo``/``vhi``), ``grp`` each row's encounter, numbered 0 .. ``n_grp`` - 1 (an encounter's
    batch-wide choices are made from its own pieces). The working arrays are
    taken from ``fbuf``/``ibuf``/``bbuf`` (float, int, bool; arrays kept by the caller from call to call) as far
    as they reach, else allocated; ``need`` (3,) gets the sizes the call would have taken from each."""
    R = seg.shape[0]
    cur = np.zeros(3, np.int64)  # cursors into fbuf, ibuf, bbuf
    settle = _take(fbuf, cur, 0, R)
    # each row's entry / exit (its segment's seg_in / seg_out), written back at the end: the updates
    # stay in these small arrays instead of reaching into the large ones scattered
    row_in, row_out = _take(fbuf, cur, 0, R), _take(fbuf, cur, 0, R)
    for r in range(R):
        settle[r] = _settle(acc_h[r], acc_v[r], v2tol, p8tol)
        row_in[r], row_out[r] = seg_in[seg[r]], seg_out[seg[r]]
    # -- the pieces of the current depth (every piece keeps its row, so its segment) --------------------
    L = R
    row = _take(ibuf, cur, 1, L)
    ta, tb = _take(fbuf, cur, 0, L), _take(fbuf, cur, 0, L)
    pa, pb = _take(fbuf, cur, 0, 3 * L).reshape((3, L)), _take(fbuf, cur, 0, 3 * L).reshape((3, L))
    ua, ub = _take(fbuf, cur, 0, 2 * L).reshape((2, L)), _take(fbuf, cur, 0, 2 * L).reshape((2, L))
    fa, fb = _take(bbuf, cur, 2, L), _take(bbuf, cur, 2, L)
    for r in range(R):
        a = ka[r]
        t0 = tk[a]
        h = tk[a + 1] - t0
        row[r], ta[r], tb[r] = r, t0, t0 + h
        pa[0, r], pa[1, r], pa[2, r] = s0[a], s1[a], s2[a]
        pb[0, r], pb[1, r], pb[2, r] = s0[a + 1], s1[a + 1], s2[a + 1]
        ua[0, r], ua[1, r], ub[0, r], ub[1, r] = v0[a], v1[a], v0[a + 1], v1[a + 1]
        fa[r] = wcv_soa(s0[a], s1[a], s2[a], v0[a], v1[a], v2[a], DD, TT, H, TC)
        fb[r] = wcv_soa(s0[a + 1], s1[a + 1], s2[a + 1], v0[a + 1], v1[a + 1], v2[a + 1], DD, TT, H, TC)
    for depth in range(max_depth):
        if L == 0:
            break
        for i in range(L):
            if fa[i] and fb[i]:
                r = row[i]
                row_in[r], row_out[r] = _update(row_in[r], row_out[r], ta[i], tb[i])
        split = _take(bbuf, cur, 2, L)
        split[:] = False
        last = depth == max_depth - 1
        settled = _take(bbuf, cur, 2, L)
        for i in range(L):
            settled[i] = ((tb[i] - ta[i]) <= settle[row[i]] * SETTLE_SLACK) or last
        # -- crossings: entries (start clear, end violating) and exits -----------------------------------
        nc = 0
        cross = _take(ibuf, cur, 1, L)
        for i in range(L):
            if fa[i] != fb[i]:
                if not exits and fa[i]:  # an exit: first entry at the start; the last exit is not needed
                    r = row[i]
                    row_in[r], row_out[r] = _update(row_in[r], row_out[r], ta[i], tb[i])
                else:
                    cross[nc] = i
                    nc += 1
        if nc:
            crs = cross[:nc]
            lo, hi = _take(fbuf, cur, 0, nc), _take(fbuf, cur, 0, nc)
            lo_in = _take(bbuf, cur, 2, nc)
            crow = _take(ibuf, cur, 1, nc)
            for c in range(nc):
                i = crs[c]
                lo[c], hi[c], lo_in[c], crow[c] = ta[i], tb[i], not fb[i], row[i]
            clear_pos, have_pos = _take(fbuf, cur, 0, 3 * nc).reshape((3, nc)), _take(bbuf, cur, 2, nc)
            _bisect(kind, axis, rate, kin, ph, enc, max_turn, h_acc, v_acc, ipv, mi, ii, crow, lo, hi, lo_in, grp,
                    n_grp, thr, dt_in, dt_out, DD, TT, H, TC, clear_pos, have_pos)
            # certify the other side of the crossing clear: before an entry, after an exit
            anyv = _any_nonzero(acc_v, row, crs, grp, n_grp)
            for c in range(nc):
                i = crs[c]
                r = row[i]
                entry = fb[i]
                if have_pos[c]:  # (the state there, computed by the bisection)
                    mx, my, mz = clear_pos[0, c], clear_pos[1, c], clear_pos[2, c]
                else:
                    mrow = _motion_row(kind, axis, rate, kin, ph, enc, ipv, mi, ii, r)
                    mx, my, mz, _, _, _ = _rel(kind, axis, rate, mrow, max_turn, h_acc, v_acc,
                                               lo[c] if entry else hi[c])
                c_a, c_b = (ta[i], lo[c]) if entry else (hi[c], tb[i])
                if entry:
                    x0, y0, z0, x1, y1, z1 = pa[0, i], pa[1, i], pa[2, i], mx, my, mz
                else:
                    x0, y0, z0, x1, y1, z1 = mx, my, mz, pb[0, i], pb[1, i], pb[2, i]
                code = _classify_part(acc_h[r], acc_v[r], anyv[grp[r]], von[r], vlo[r], vhi[r], c_a, c_b,
                                      x0, y0, z0, x1, y1, z1, D, DD, H, TT, TC)
                if code == CLEAR or settled[i]:
                    tc = 0.5 * (lo[c] + hi[c])
                    row_in[r], row_out[r] = _update(row_in[r], row_out[r], tc if entry else ta[i],
                                                    tb[i] if entry else tc)
                else:
                    split[i] = True
        # -- both ends clear: a clip may lie inside unless certified clear --------------------------------
        nj = 0
        jj = _take(ibuf, cur, 1, L)
        for i in range(L):
            if not fa[i] and not fb[i]:
                jj[nj] = i
                nj += 1
        if nj and depth > 0:  # (at depth 0 these are the segments the first-order test left undecided)
            anyv = _any_nonzero(acc_v, row, jj[:nj], grp, n_grp)
            keep = 0
            for c in range(nj):
                i = jj[c]
                r = row[i]
                code = _classify_part(acc_h[r], acc_v[r], anyv[grp[r]], von[r], vlo[r], vhi[r], ta[i], tb[i],
                                      pa[0, i], pa[1, i], pa[2, i], pb[0, i], pb[1, i], pb[2, i], D, DD, H, TT, TC)
                if code != CLEAR:
                    jj[keep] = i
                    keep += 1
            nj = keep
        if nj and has_jerk:  # the tighter second-order certificate (true end velocities)
            anyv = _any_nonzero(acc_v, row, jj[:nj], grp, n_grp)
            keep = 0
            for c in range(nj):
                i = jj[c]
                r = row[i]
                h = tb[i] - ta[i]
                e_v = jerk[r] * h * h * 0.125
                if has_kink:
                    across = False
                    for e in range(kink.shape[1]):
                        kt = kink[r, e]
                        across = across or ((kt > ta[i]) and (kt < tb[i]))
                    e_v = e_v + (acc_h[r] * h * 0.5 if across else 0.0)
                e_z = acc_v[r] * h * h * 0.125 if anyv[grp[r]] else 0.0
                if not clear2(pa[0, i], pa[1, i], pa[2, i], pb[0, i], pb[1, i], pb[2, i], ua[0, i], ua[1, i],
                              ub[0, i], ub[1, i], h, acc_h[r] * h * h * 0.125, e_v, e_z, D, DD, H, TT, TC):
                    jj[keep] = i
                    keep += 1
            nj = keep
        if nj:
            nf = 0
            final = _take(ibuf, cur, 1, nj)
            for c in range(nj):
                i = jj[c]
                if settled[i]:
                    final[nf] = i
                    nf += 1
                else:
                    split[i] = True
            if nf:
                _clip(kind, axis, rate, kin, ph, enc, max_turn, h_acc, v_acc, ipv, mi, ii, final[:nf], row, ta, tb,
                      grp, n_grp, thr, dt_in, dt_out, clip_dt, DD, TT, H, TC, row_in, row_out)
        # -- split what is left into the fewest equal parts that settle ------------------------------------
        ns = 0
        for i in range(L):
            if split[i]:
                ns += 1
        if ns == 0:
            break
        mx_ratio = np.zeros(n_grp)  # each encounter's longest piece, in settle times
        seen = np.zeros(n_grp, np.bool_)
        for i in range(L):
            if split[i]:
                g = grp[row[i]]
                x = (tb[i] - ta[i]) / settle[row[i]]
                mx_ratio[g] = x if not seen[g] else _max_acc(mx_ratio[g], x)
                seen[g] = True
        g_q = np.zeros(n_grp, np.int64)
        for g in range(n_grp):
            if seen[g]:
                c = np.ceil(mx_ratio[g] - 1e-9)
                qf = c if c > 2 else 2.0
                qf = qf if qf < max_split else float(max_split)
                g_q[g] = int(qf)
        NL = 0
        for i in range(L):
            if split[i]:
                NL += g_q[grp[row[i]]]
        n_row = _take(ibuf, cur, 1, NL)
        n_ta, n_tb = _take(fbuf, cur, 0, NL), _take(fbuf, cur, 0, NL)
        n_pa, n_pb = _take(fbuf, cur, 0, 3 * NL).reshape((3, NL)), _take(fbuf, cur, 0, 3 * NL).reshape((3, NL))
        n_ua, n_ub = _take(fbuf, cur, 0, 2 * NL).reshape((2, NL)), _take(fbuf, cur, 0, 2 * NL).reshape((2, NL))
        n_fa, n_fb = _take(bbuf, cur, 2, NL), _take(bbuf, cur, 2, NL)
        o = 0
        for i in range(L):
            if not split[i]:
                continue
            r = row[i]
            q = g_q[grp[r]]
            t_prev, h = ta[i], tb[i] - ta[i]
            px, py, pz, wx, wy, f_prev = pa[0, i], pa[1, i], pa[2, i], ua[0, i], ua[1, i], fa[i]
            mrow = _motion_row(kind, axis, rate, kin, ph, enc, ipv, mi, ii, r)
            for k in range(q):
                if k < q - 1:
                    t_next = ta[i] + h * (float(k + 1) / q)
                    sx, sy, sz, vx, vy, vz = _rel(kind, axis, rate, mrow, max_turn, h_acc, v_acc, t_next)
                    f_next = wcv_soa(sx, sy, sz, vx, vy, vz, DD, TT, H, TC)
                else:
                    t_next = tb[i]
                    sx, sy, sz, vx, vy, f_next = pb[0, i], pb[1, i], pb[2, i], ub[0, i], ub[1, i], fb[i]
                n_row[o], n_ta[o], n_tb[o] = r, t_prev, t_next
                n_pa[0, o], n_pa[1, o], n_pa[2, o] = px, py, pz
                n_pb[0, o], n_pb[1, o], n_pb[2, o] = sx, sy, sz
                n_ua[0, o], n_ua[1, o], n_ub[0, o], n_ub[1, o] = wx, wy, vx, vy
                n_fa[o], n_fb[o] = f_prev, f_next
                t_prev, px, py, pz, wx, wy, f_prev = t_next, sx, sy, sz, vx, vy, f_next
                o += 1
        L = NL
        row, ta, tb, pa, pb, ua, ub, fa, fb = n_row, n_ta, n_tb, n_pa, n_pb, n_ua, n_ub, n_fa, n_fb
    for r in range(R):
        seg_in[seg[r]], seg_out[seg[r]] = row_in[r], row_out[r]
    need[0], need[1], need[2] = cur[0], cur[1], cur[2]
