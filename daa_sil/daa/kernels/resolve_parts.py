"""The steps of the resolution of undecided pieces (:mod:`daa_sil.daa.kernels.resolve`), compiled into its
kernel: a row's motion and relative state, the bisection of boundary crossings, the certificate of a part
of a piece, and the sampling of short clear-ended pieces for clips.

Records (tuples) group what the steps read, so that no function takes more than 16 parameters:

* ``mot`` the paths' motion ``(kind, axis, rate, kin, ph, enc, max_turn, h_acc, v_acc)``: a band axis's
  paths (``kind`` :data:`KIND_AXIS`, rows of ``kin``, axis code and rate) or commands (rows of the phases
  ``ph`` and constants ``enc``, with the performance limits);
* ``who`` ``(ipv, mi, ii, grp)``: the intruders' positions and velocities (rows of ``ipv``), and per row
  ``r`` its path's motion row ``mi[r]``, its intruder row ``ii[r]`` and its encounter ``grp[r]``;
* ``dts`` ``(dt_in, dt_out, clip_dt)`` s: bisection tolerances of an entry and an exit, clip sampling;
* ``vol`` the volume ``(D, D * D, ZTHR, TTHR, TCOA)``.

Every choice the numpy reference makes for several pieces at once is made per encounter: the pieces a
step is given are in encounter order (rows sorted by encounter, pieces kept in their rows' order), so
each encounter's pieces are one run, and the run's own widest bracket, longest piece or vertical
accelerations decide for it (the reference: ``UndecidedPieces``).
"""

from __future__ import annotations

import math

import numpy as np

from daa_sil.daa.kernels.jit import inline, inline_ir
from daa_sil.daa.kernels.motion import axis_rel, axis_row, command_rel, command_row, intruder_row, row_limit_time
from daa_sil.daa.kernels.pieces import classify
from daa_sil.daa.kernels.scalar import INF, halve, npmax, npmin, wcv_soa

#: motion kinds: a band axis's path (kernels.motion.rel_state) or a command (command_rel_state)
KIND_AXIS, KIND_COMMAND = 0, 1
#: ``settle_time * (1 + 1e-9)`` of the reference, the factor computed in Python
SETTLE_SLACK = 1.0 + 1e-9

#: placeholders for the motion of the kind of path a call does not use (:func:`motion_row`)
_NO_AXIS_ROW = (0.0,) * 9
_NO_COMMAND_ROW = ((0.0,) * 9, (0.0,) * 9, (0.0,) * 9, (0.0,) * 7)


@inline
def motion_row(mot, who, r):
    """Row ``r``'s motion (row ``mi[r]`` of ``kin`` with its time to its limit, s, or of ``ph``/``enc``) and
    intruder (row ``ii[r]`` of ``ipv``) as tuples of floats, for :func:`rel` (loaded once per row)."""
    kind, axis, rate, kin, ph, enc, _, _, _ = mot
    ipv, mi, ii, _ = who
    if kind == KIND_AXIS:
        arow = axis_row(kin, mi[r])
        return arow, row_limit_time(axis, rate, arow), _NO_COMMAND_ROW, intruder_row(ipv, ii[r])
    return _NO_AXIS_ROW, 0.0, command_row(ph, enc, mi[r]), intruder_row(ipv, ii[r])


@inline_ir
def rel(mot, mrow, t):
    """Relative state at ``t`` of the row whose :func:`motion_row` is ``mrow``."""
    kind, axis, rate, _, _, _, max_turn, h_acc, v_acc = mot
    arow, cap, crow, iv = mrow
    if kind == KIND_AXIS:
        return axis_rel(axis, rate, arow, cap, iv, t)
    return command_rel(crow, iv, t, max_turn, h_acc, v_acc)


@inline
def take(buf, cur, j, n):
    """``n`` elements of ``buf`` from cursor ``cur[j]`` (a fresh array when ``buf`` is too small); the cursor
    moves by ``n`` either way, so that at the end it tells how large ``buf`` should be."""
    off = cur[j]
    cur[j] = off + n
    if off + n <= buf.shape[0]:
        return buf[off:off + n]
    return np.empty(n, buf.dtype)


@inline
def settle(ah, av, v2, p8):
    """certify.settle_time of one path (``v2`` = 2 V_TOL, ``p8`` = 8 P_TOL, Python products)."""
    t_v = v2 / ah if ah > 0 else INF
    a = npmax(ah, av)
    t_p = math.sqrt(p8 / a) if a > 0 else INF
    return npmin(t_v, t_p)


@inline
def max_acc(acc, x):
    """One step of ``np.max`` (nan wins)."""
    if acc != acc:
        return acc
    if x != x or x > acc:
        return x
    return acc


@inline
def halvings(wmax, dt, thr):
    """``int(np.ceil(np.log2(max(wmax, dt) / dt)))`` (``thr[n]``: smallest x with log2(x) > n)."""
    x = (dt if dt > wmax else wmax) / dt
    n = 0
    while n < thr.shape[0] and x >= thr[n]:
        n += 1
    return n


@inline
def update(a, b, t_in, t_out):
    """``np.minimum.at`` / ``np.maximum.at`` of one entry ``(a, b)`` -> its new ``(a, b)``."""
    return (a if (a != a or a < t_in) else t_in), (b if (b != b or b > t_out) else t_out)


@inline
def run_end(grp, row, sel, c0, n):
    """End (exclusive) of the run of pieces ``sel[c0:]`` (indices into ``row``) of one encounter."""
    g = grp[row[sel[c0]]]
    c1 = c0 + 1
    while c1 < n and grp[row[sel[c1]]] == g:
        c1 += 1
    return c1


@inline
def any_vertical(acc_v, row, sel, c0, c1):
    """``np.any`` of the vertical accelerations of the rows of pieces ``sel[c0:c1]`` (one encounter)."""
    for c in range(c0, c1):
        if acc_v[row[sel[c]]] != 0.0:
            return True
    return False


@inline
def _own_halvings(steps, mixed, flag, n_in, n_out, a, b):
    """The halvings of :func:`bisect` that can move the bracket ``[a, b]`` (s) of a row starting inside
    (``flag``) or outside: in a ``mixed`` batch :func:`~daa_sil.daa.kernels.scalar.halve` leaves a bracket
    unchanged from its kind's count on, and the predicate evaluated there is not kept (its state is
    kept only when an end moves), so those steps are skipped; all ``steps`` when an end is nan (an
    unchanged nan end compares unequal to itself, as the full loop would see it)."""
    if mixed and a == a and b == b:
        return n_out if flag else n_in
    return steps


@inline
def bisect(mot, who, row, lo, hi, lo_in, thr, dts, vol, clear_pos, have_pos):
    """``UndecidedPieces._bisect`` of the rows ``row`` (one batch, in encounter order): ``lo``/``hi`` halved in
    place, each encounter with the halvings of its own widest brackets. The relative position at the end of
    the final bracket outside the volume (``lo`` of an entry, ``hi`` of an exit) goes to ``clear_pos`` (3, n)
    when a halving put that end there (``have_pos``; else it is still the start's)."""
    D, DD, H, TT, TC = vol
    dt_in, dt_out, _ = dts
    grp = who[3]
    n = lo.shape[0]
    i0 = 0
    while i0 < n:
        g = grp[row[i0]]
        w_in, w_out = 0.0, 0.0
        any_in, any_out = False, False
        i1 = i0
        while i1 < n and grp[row[i1]] == g:
            if lo_in[i1]:
                w_out = max_acc(w_out, hi[i1] - lo[i1])
                any_out = True
            else:
                w_in = max_acc(w_in, hi[i1] - lo[i1])
                any_in = True
            i1 += 1
        n_in, n_out = halvings(w_in, dt_in, thr), halvings(w_out, dt_out, thr)
        mixed = n_in != n_out and any_in and any_out
        steps = max(n_in, n_out)
        for i in range(i0, i1):
            a, b, flag = lo[i], hi[i], lo_in[i]
            mrow = motion_row(mot, who, row[i])
            have_pos[i] = False
            for k in range(_own_halvings(steps, mixed, flag, n_in, n_out, a, b)):
                mid = 0.5 * (a + b)
                sx, sy, sz, vx, vy, vz = rel(mot, mrow, mid)
                inside = wcv_soa(sx, sy, sz, vx, vy, vz, DD, TT, H, TC)
                a2, b2 = halve(a, b, mid, inside == flag, k, mixed, flag, n_in, n_out)
                if not inside and (a2 != a or b2 != b):  # the end outside moved to mid
                    clear_pos[0, i], clear_pos[1, i], clear_pos[2, i] = sx, sy, sz
                    have_pos[i] = True
                a, b = a2, b2
            lo[i], hi[i] = a, b
        i0 = i1


@inline
def classify_part(acc, anyv, win, ta, tb, p0, p1, vol):
    """``UndecidedPieces._classify_part`` of one piece from ``ta`` to ``tb`` (s) between relative positions
    ``p0`` and ``p1``: ``acc`` its path's ``(a_h, a_v)``, ``anyv`` ``np.any`` of its encounter's a_v, ``win``
    its path's vertical window ``(has, lo, hi)``."""
    a_h, a_v = acc
    has_vwin, w_lo, w_hi = win
    h = tb - ta
    lo, hi = 0.0, 0.0
    if has_vwin:
        lo, hi = npmax(w_lo, ta) - ta, npmin(w_hi, tb) - ta
    e_z = a_v * h * h * 0.125 if anyv else 0.0
    return classify(p0, p1, h, a_h * h * h * 0.125, a_h * h * 0.5, e_z, lo, hi, has_vwin, vol)


@inline
def _sample(mot, mrow, ta, tb, q, vol):
    """Sample a piece from ``ta`` to ``tb`` (s) every ``(tb - ta) / q`` for the true predicate: ``(found,
    (before, first inside), (last inside, after))`` brackets of its first and last violating samples."""
    D, DD, H, TT, TC = vol
    h = tb - ta
    first = -1
    t_prev_first, t_first, t_last, t_after = ta, 0.0, 0.0, tb
    t_prev = ta
    pending_after = False
    for k in range(q):
        t = ta + h * ((float(k) + 0.5) / q)
        if pending_after:
            t_after = t
            pending_after = False
        sx, sy, sz, vx, vy, vz = rel(mot, mrow, t)
        if wcv_soa(sx, sy, sz, vx, vy, vz, DD, TT, H, TC):
            if first < 0:
                first, t_first = k, t
                t_prev_first = t_prev if k > 0 else ta
            t_last = t
            t_after = tb
            pending_after = k < q - 1
        t_prev = t
    return first >= 0, (t_prev_first, t_first), (t_last, t_after)


@inline
def clip(mot, who, final, row, ta, tb, thr, dts, vol, row_in, row_out):
    """``UndecidedPieces._clip`` of pieces ``final`` (in encounter order): sampled every ``clip_dt`` (each
    encounter's count from its longest piece), the first and last violating samples bracketed and
    bisected (entries, then exits, each as one batch)."""
    clip_dt = dts[2]
    grp = who[3]
    nf = final.shape[0]
    b1, t1 = np.empty(nf), np.empty(nf)  # entry brackets (before, first sample inside)
    t2, a2 = np.empty(nf), np.empty(nf)  # exit brackets (last sample inside, after)
    hrow = np.empty(nf, np.int64)
    nh = 0
    c0 = 0
    while c0 < nf:
        c1 = run_end(grp, row, final, c0, nf)
        hmax = 0.0
        for c in range(c0, c1):
            i = final[c]
            hmax = (tb[i] - ta[i]) if c == c0 else max_acc(hmax, tb[i] - ta[i])
        qf = np.ceil(hmax / clip_dt - 1e-9)
        if qf >= 1:
            q = int(qf)
            for c in range(c0, c1):
                i = final[c]
                r = row[i]
                found, entry, exit_ = _sample(mot, motion_row(mot, who, r), ta[i], tb[i], q, vol)
                if found:
                    b1[nh], t1[nh] = entry
                    t2[nh], a2[nh] = exit_
                    hrow[nh] = r
                    nh += 1
        c0 = c1
    if nh == 0:
        return
    l1, h1, l2, h2, hr = b1[:nh].copy(), t1[:nh].copy(), t2[:nh].copy(), a2[:nh].copy(), hrow[:nh].copy()
    pos, have = np.empty((3, nh)), np.empty(nh, np.bool_)  # (not read)
    bisect(mot, who, hr, l1, h1, np.zeros(nh, np.bool_), thr, dts, vol, pos, have)
    bisect(mot, who, hr, l2, h2, np.ones(nh, np.bool_), thr, dts, vol, pos, have)
    for c in range(nh):
        r = hr[c]
        row_in[r], row_out[r] = update(row_in[r], row_out[r], 0.5 * (l1[c] + h1[c]), 0.5 * (l2[c] + h2[c]))
