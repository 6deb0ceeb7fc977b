"""The undecided pieces of a maneuver path resolved on the true state, in one compiled pass.

The numpy reference is :meth:`daa_sil.daa.undecided.UndecidedPieces.resolve_reference` (its
``_bisect``, ``_classify_part``, ``_clear2``, ``_split`` and ``_clip``). The kernel keeps its phase
structure, not only its per-piece arithmetic: the pieces of one depth are processed as one batch,
and what the reference decides for several pieces at once is decided per encounter, from that
encounter's pieces alone -- the number of halvings of a bisection (from the encounter's widest bracket,
per kind), the number of parts a split makes (from its longest piece), the clip sampling count, and
whether the vertical position error ``e_z`` is used (``np.any`` of its rows' vertical accelerations) --
so that an encounter's intervals are those of a call of its own. The rows come in encounter order and
every piece keeps its row's place, so an encounter's pieces are one run of every list the steps walk
(:mod:`daa_sil.daa.kernels.resolve_parts`). ``ceil(log2(x))`` of a bisection's halvings is read from a
table of the thresholds where numpy's ``log2`` passes each integer (``undecided.bisect_thresholds``), so
it is numpy's, not libm's.

Rows ``r`` are the undecided segments the call starts with; every piece split from a segment keeps
its row (the motion, acceleration bounds, jerk, kinks, vertical window and encounter of its path).
"""

from __future__ import annotations

import numpy as np
from numba import boolean, float64, int64, types, void

from daa_sil.daa.kernels.jit import kernel
from daa_sil.daa.kernels.pieces import CLEAR, clear2
from daa_sil.daa.kernels.resolve_parts import (SETTLE_SLACK, any_vertical, bisect, classify_part, clip, max_acc,
                                               motion_row, rel, run_end, settle, take, update)
from daa_sil.daa.kernels.scalar import wcv_soa
from daa_sil.daa.kernels.signatures import A, A2, A3, IA, O, F, I

_B1 = types.Array(boolean, 1, "A", readonly=True)
#: the records of :func:`resolve_into` (module docstring of :mod:`daa_sil.daa.kernels.resolve_parts`)
MOT = types.Tuple((I, I, F, A2, A3, A2, F, F, F))
WHO = types.Tuple((A2, IA, IA, IA))
ROWS = types.Tuple((IA, IA, A, A, A, A2, _B1, A, A))
KNOTS = types.UniTuple(A, 7)
FLAGS = types.UniTuple(boolean, 3)
LIMITS = types.Tuple((I, I, F, F))
DTS = types.UniTuple(F, 3)
VOL = types.UniTuple(F, 5)
OUT = types.UniTuple(O, 2)
WORK = types.Tuple((types.Array(float64, 1, "C"), types.Array(int64, 1, "C"), types.Array(boolean, 1, "C"),
                    types.Array(int64, 1, "C")))


@kernel(void(MOT, WHO, ROWS, KNOTS, FLAGS, A, LIMITS, DTS, VOL, OUT, WORK))
def resolve_into(mot, who, rows, knots, flags, thr, limits, dts, vol, out, work):
    """Resolve the undecided segments into ``out`` = ``(seg_in, seg_out)`` (the reference's docstring).

    ``mot``/``who``/``dts``/``vol``: the records of :mod:`~daa_sil.daa.kernels.resolve_parts` (row ``r``'s motion,
    intruder and encounter; the rows in encounter order). ``rows`` = ``(seg, ka, acc_h, acc_v, jerk, kink, von,
    vlo, vhi)``: per row its flat segment id, the flat index of its first knot into ``knots`` = ``(s0, s1, s2,
    v0, v1, v2, tk)`` (relative states and knot times), its path's acceleration bounds, jerk, kinks (R, Q) and
    vertical window (``von``: it has one). ``flags`` = ``(has_jerk, has_kink, exits)``; ``thr`` the halvings
    table; ``limits`` = ``(max_depth, max_split, 2 V_TOL, 8 P_TOL)``. ``work`` = ``(fbuf, ibuf, bbuf, need)``:
    the working arrays are taken from ``fbuf``/``ibuf``/``bbuf`` (float, int, bool; kept by the caller from call
    to call) as far as they reach, else allocated; ``need`` (3,) gets the sizes the call would have taken."""
    seg, ka, acc_h, acc_v, jerk, kink, von, vlo, vhi = rows
    s0, s1, s2, v0, v1, v2, tk = knots
    has_jerk, has_kink, exits = flags
    max_depth, max_split, v2tol, p8tol = limits
    D, DD, H, TT, TC = vol
    seg_in, seg_out = out
    fbuf, ibuf, bbuf, need = work
    grp = who[3]
    R = seg.shape[0]
    cur = np.zeros(3, np.int64)  # cursors into fbuf, ibuf, bbuf
    settle_t = take(fbuf, cur, 0, R)
    # each row's entry / exit (its segment's seg_in / seg_out), written back at the end: the updates
    # stay in these small arrays instead of reaching into the large ones scattered
    row_in, row_out = take(fbuf, cur, 0, R), take(fbuf, cur, 0, R)
    for r in range(R):
        settle_t[r] = settle(acc_h[r], acc_v[r], v2tol, p8tol)
        row_in[r], row_out[r] = seg_in[seg[r]], seg_out[seg[r]]
    # -- the pieces of the current depth (every piece keeps its row, so its segment) --------------------
    L = R
    row = take(ibuf, cur, 1, L)
    ta, tb = take(fbuf, cur, 0, L), take(fbuf, cur, 0, L)
    pa, pb = take(fbuf, cur, 0, 3 * L).reshape((3, L)), take(fbuf, cur, 0, 3 * L).reshape((3, L))
    ua, ub = take(fbuf, cur, 0, 2 * L).reshape((2, L)), take(fbuf, cur, 0, 2 * L).reshape((2, L))
    fa, fb = take(bbuf, cur, 2, L), take(bbuf, cur, 2, L)
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
                row_in[r], row_out[r] = update(row_in[r], row_out[r], ta[i], tb[i])
        split = take(bbuf, cur, 2, L)
        split[:] = False
        last = depth == max_depth - 1
        settled = take(bbuf, cur, 2, L)
        for i in range(L):
            settled[i] = ((tb[i] - ta[i]) <= settle_t[row[i]] * SETTLE_SLACK) or last
        # -- crossings: entries (start clear, end violating) and exits -----------------------------------
        nc = 0
        cross = take(ibuf, cur, 1, L)
        for i in range(L):
            if fa[i] != fb[i]:
                if not exits and fa[i]:  # an exit: first entry at the start; the last exit is not needed
                    r = row[i]
                    row_in[r], row_out[r] = update(row_in[r], row_out[r], ta[i], tb[i])
                else:
                    cross[nc] = i
                    nc += 1
        if nc:
            crs = cross[:nc]
            lo, hi = take(fbuf, cur, 0, nc), take(fbuf, cur, 0, nc)
            lo_in = take(bbuf, cur, 2, nc)
            crow = take(ibuf, cur, 1, nc)
            for c in range(nc):
                i = crs[c]
                lo[c], hi[c], lo_in[c], crow[c] = ta[i], tb[i], not fb[i], row[i]
            clear_pos, have_pos = take(fbuf, cur, 0, 3 * nc).reshape((3, nc)), take(bbuf, cur, 2, nc)
            bisect(mot, who, crow, lo, hi, lo_in, thr, dts, vol, clear_pos, have_pos)
            # certify the other side of the crossing clear: before an entry, after an exit
            c0 = 0
            while c0 < nc:
                c1 = run_end(grp, row, crs, c0, nc)
                anyv = any_vertical(acc_v, row, crs, c0, c1)
                for c in range(c0, c1):
                    i = crs[c]
                    r = row[i]
                    entry = fb[i]
                    if have_pos[c]:  # (the state there, computed by the bisection)
                        mx, my, mz = clear_pos[0, c], clear_pos[1, c], clear_pos[2, c]
                    else:
                        mx, my, mz, _, _, _ = rel(mot, motion_row(mot, who, r), lo[c] if entry else hi[c])
                    c_a, c_b = (ta[i], lo[c]) if entry else (hi[c], tb[i])
                    if entry:
                        p0, p1 = (pa[0, i], pa[1, i], pa[2, i]), (mx, my, mz)
                    else:
                        p0, p1 = (mx, my, mz), (pb[0, i], pb[1, i], pb[2, i])
                    code = classify_part((acc_h[r], acc_v[r]), anyv, (von[r], vlo[r], vhi[r]), c_a, c_b, p0, p1, vol)
                    if code == CLEAR or settled[i]:
                        tc = 0.5 * (lo[c] + hi[c])
                        row_in[r], row_out[r] = update(row_in[r], row_out[r], tc if entry else ta[i],
                                                       tb[i] if entry else tc)
                    else:
                        split[i] = True
                c0 = c1
        # -- both ends clear: a clip may lie inside unless certified clear --------------------------------
        nj = 0
        jj = take(ibuf, cur, 1, L)
        for i in range(L):
            if not fa[i] and not fb[i]:
                jj[nj] = i
                nj += 1
        if nj and depth > 0:  # (at depth 0 these are the segments the first-order test left undecided)
            keep = 0
            c0 = 0
            while c0 < nj:
                c1 = run_end(grp, row, jj, c0, nj)
                anyv = any_vertical(acc_v, row, jj, c0, c1)
                for c in range(c0, c1):
                    i = jj[c]
                    r = row[i]
                    code = classify_part((acc_h[r], acc_v[r]), anyv, (von[r], vlo[r], vhi[r]), ta[i], tb[i],
                                         (pa[0, i], pa[1, i], pa[2, i]), (pb[0, i], pb[1, i], pb[2, i]), vol)
                    if code != CLEAR:
                        jj[keep] = i
                        keep += 1
                c0 = c1
            nj = keep
        if nj and has_jerk:  # the tighter second-order certificate (true end velocities)
            keep = 0
            c0 = 0
            while c0 < nj:
                c1 = run_end(grp, row, jj, c0, nj)
                anyv = any_vertical(acc_v, row, jj, c0, c1)
                for c in range(c0, c1):
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
                    e_z = acc_v[r] * h * h * 0.125 if anyv else 0.0
                    if not clear2((pa[0, i], pa[1, i], pa[2, i]), (pb[0, i], pb[1, i], pb[2, i]), (ua[0, i], ua[1, i]),
                                  (ub[0, i], ub[1, i]), h, acc_h[r] * h * h * 0.125, e_v, e_z, vol):
                        jj[keep] = i
                        keep += 1
                c0 = c1
            nj = keep
        if nj:
            nf = 0
            final = take(ibuf, cur, 1, nj)
            for c in range(nj):
                i = jj[c]
                if settled[i]:
                    final[nf] = i
                    nf += 1
                else:
                    split[i] = True
            if nf:
                clip(mot, who, final[:nf], row, ta, tb, thr, dts, vol, row_in, row_out)
        # -- split what is left into the fewest equal parts that settle (each encounter's count) -----------
        ns = 0
        sp = take(ibuf, cur, 1, L)
        for i in range(L):
            if split[i]:
                sp[ns] = i
                ns += 1
        if ns == 0:
            break
        qs = take(ibuf, cur, 1, ns)  # parts of each piece split
        NL = 0
        c0 = 0
        while c0 < ns:
            c1 = run_end(grp, row, sp, c0, ns)
            mx_ratio = 0.0
            for c in range(c0, c1):
                i = sp[c]
                x = (tb[i] - ta[i]) / settle_t[row[i]]
                mx_ratio = x if c == c0 else max_acc(mx_ratio, x)
            cq = np.ceil(mx_ratio - 1e-9)
            qf = cq if cq > 2 else 2.0
            qf = qf if qf < max_split else float(max_split)
            q = int(qf)
            for c in range(c0, c1):
                qs[c] = q
            NL += q * (c1 - c0)
            c0 = c1
        n_row = take(ibuf, cur, 1, NL)
        n_ta, n_tb = take(fbuf, cur, 0, NL), take(fbuf, cur, 0, NL)
        n_pa, n_pb = take(fbuf, cur, 0, 3 * NL).reshape((3, NL)), take(fbuf, cur, 0, 3 * NL).reshape((3, NL))
        n_ua, n_ub = take(fbuf, cur, 0, 2 * NL).reshape((2, NL)), take(fbuf, cur, 0, 2 * NL).reshape((2, NL))
        n_fa, n_fb = take(bbuf, cur, 2, NL), take(bbuf, cur, 2, NL)
        o = 0
        for c in range(ns):
            i = sp[c]
            q = qs[c]
            r = row[i]
            t_prev, h = ta[i], tb[i] - ta[i]
            px, py, pz, wx, wy, f_prev = pa[0, i], pa[1, i], pa[2, i], ua[0, i], ua[1, i], fa[i]
            mrow = motion_row(mot, who, r)
            for k in range(q):
                if k < q - 1:
                    t_next = ta[i] + h * (float(k + 1) / q)
                    sx, sy, sz, vx, vy, vz = rel(mot, mrow, t_next)
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
