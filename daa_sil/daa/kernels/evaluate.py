"""Kernels of :class:`daa_sil.daa.trajectory.PathEvaluator`: straight tails, the chord certificates of
the maneuver between knots (blocks first), and the candidates' first entry / last exit.

Arrays are flat over ``(N, M, P, K)`` (knots last) or ``(N, M, P)`` (one value per path); the
numpy code they replace is kept as the ``*_reference`` methods of the evaluator. Records (tuples):
``s``/``v`` the relative position / velocity components ``(x, y, z)`` (flat arrays); ``win`` a path's
vertical window ``(has, lo, hi)``; ``vol`` the volume ``(D, D * D, ZTHR, TTHR, TCOA)`` of the certificates
and ``ivol`` ``(D, D * D, D ** 2, TTHR, ZTHR, TCOA)`` of the tails' intervals (Python products).
"""

from __future__ import annotations

from numba import boolean, int8, types, void

from daa_sil.daa.kernels.jit import inline_ir, kernel
from daa_sil.daa.kernels.pieces import CLEAR, INSIDE, UNDECIDED, classify
from daa_sil.daa.kernels.scalar import INF, interval, npmax, npmin, vertical_window
from daa_sil.daa.kernels.signatures import A, A3, IA, O, O4, F, I

_B1 = types.Array(boolean, 1, "A", readonly=True)
#: the records of the kernels below (module docstring)
XYZ = types.UniTuple(A, 3)
VOL = types.UniTuple(F, 5)
IVOL = types.UniTuple(F, 6)


@inline_ir
def tails_path(s, v, tk, ib, ob, K, K_all, win, last_only, t_end, ivol, out):
    """The tails of one path (:func:`tails_into`): its ``K`` knots at ``ib + k`` of ``s``/``v``/``tk``, its tails
    written at ``ob + k`` of ``out`` = ``(tail_in, tail_out)``, ``(inf, -inf)`` at its slots ``K`` .. ``K_all`` - 1
    past its last knot (not with ``last_only``); ``win`` its vertical window (inlined by numba)."""
    s0, s1, s2 = s
    v0, v1, v2 = v
    has_vwin, w_lo, w_hi = win
    D, DD, D2, TT, H, TC = ivol
    tail_in, tail_out = out
    if not last_only:
        for k in range(K, K_all):
            tail_in[ob + k], tail_out[ob + k] = INF, -INF
    for k in range(K - 1 if last_only else 0, K):
        i = ib + k
        t = tk[i]
        length = npmax(t_end - t, 0.0)
        if has_vwin:
            lo, hi = npmax(w_lo, t) - t, npmin(w_hi, t_end) - t
        else:
            lo, hi = vertical_window(s2[i], v2[i], 0.0, length, H, TC)
        a, b = interval(s0[i], s1[i], s2[i], v0[i], v1[i], v2[i], length, lo, hi, D, DD, D2, TT, H, TC)
        o = ob + k
        if last_only:
            if t <= t_end:
                tail_in[o], tail_out[o] = a + t, b + t
            else:
                tail_in[o], tail_out[o] = INF, -INF
        elif t > t_end:
            tail_in[o], tail_out[o] = INF, -INF
        else:
            tail_in[o], tail_out[o] = a + t, b + t


@kernel(void(XYZ, XYZ, A, I, IA, _B1, A, A, boolean, F, IVOL, types.UniTuple(O, 2)))
def tails_into(s, v, tk, K, kp, von, vlo, vhi, last_only, t_end, ivol, out):
    """Violation interval ``out`` = ``(tail_in, tail_out)`` of the straight tail from every knot (``last_only``:
    the last knot of each path) over ``[t_k, t_end]``, absolute s; path ``i`` has ``kp[i]`` of the ``K`` knots
    (its tails past them are ``(inf, -inf)``) and, when ``von[i]``, the vertical window ``vlo[i]``/``vhi[i]``."""
    n_paths = tk.shape[0] // K
    for path in range(n_paths):
        on = von[path]
        win = (on, vlo[path], vhi[path]) if on else (on, 0.0, 0.0)
        tails_path(s, v, tk, path * K, path * K, kp[path], K, win, last_only, t_end, ivol, out)


@inline_ir
def _piece(s, tk, ia, ib, t_win_end, acc, win, vol):
    """Code of the chord from flat knot ``ia`` to ``ib``; the window is clipped to ``[t_a, t_win_end]``
    (inlined by numba: the arrays are not reference-counted per segment)."""
    s0, s1, s2 = s
    a_h, a_v = acc
    has_vwin, w_lo, w_hi = win
    t0 = tk[ia]
    h = tk[ib] - t0
    lo, hi = 0.0, 0.0
    if has_vwin:
        lo, hi = npmax(w_lo, t0) - t0, npmin(w_hi, t_win_end) - t0
    return classify((s0[ia], s1[ia], s2[ia]), (s0[ib], s1[ib], s2[ib]), h, a_h * h * h * 0.125, a_h * h * 0.5,
                    a_v * h * h * 0.125, lo, hi, has_vwin, vol)


@inline_ir
def segments_path(s, tk, base, ob, K, S_all, block, acc, win, t_end, vol, out):
    """The segments of one path (:func:`segments_into`): its ``K`` knots at ``base + j`` of ``s``/``tk``, its
    codes and intervals written at ``ob + j`` of ``out`` = ``(code, seg_in, seg_out)``, CLEAR ``(inf, -inf)`` at
    its slots ``K - 1`` .. ``S_all`` - 1 past its last knot; ``acc`` = ``(a_h, a_v)`` (inlined by numba)."""
    code, seg_in, seg_out = out
    S = K - 1
    for j in range(max(S, 0), S_all):
        code[ob + j], seg_in[ob + j], seg_out[ob + j] = CLEAR, INF, -INF
    if S > block:
        b0 = 0
        while b0 < S:
            b1 = min(b0 + block, S)
            c = _piece(s, tk, base + b0, base + b1, tk[base + b1], acc, win, vol)
            for j in range(b0, b1):
                if c == UNDECIDED:  # the block's segments one by one (end time t0 + h, as the reference)
                    t0 = tk[base + j]
                    t1 = t0 + (tk[base + j + 1] - t0)
                    code[ob + j] = _piece(s, tk, base + j, base + j + 1, t1, acc, win, vol)
                else:
                    code[ob + j] = INSIDE if c == INSIDE else CLEAR
            b0 = b1
    else:
        for j in range(S):
            code[ob + j] = _piece(s, tk, base + j, base + j + 1, tk[base + j + 1], acc, win, vol)
    for j in range(S):
        i = ob + j
        if not (tk[base + j] < t_end):
            code[i] = CLEAR
        if code[i] == INSIDE:
            seg_in[i], seg_out[i] = tk[base + j], tk[base + j + 1]
        else:
            seg_in[i], seg_out[i] = INF, -INF


@kernel(void(XYZ, A, I, IA, I, A, A, _B1, A, A, F, VOL, types.Tuple((int8[:], O, O))))
def segments_into(s, tk, K, kp, block, acc_h, acc_v, von, vlo, vhi, t_end, vol, out):
    """Certificate code of the maneuver between knots j and j+1 of every path (``code`` flat over
    ``(N, M, P, K-1)``, the first of ``out`` = ``(code, seg_in, seg_out)``; path ``i`` has ``kp[i]`` of the ``K``
    knots, and its segments past them are CLEAR):
    with more than ``block`` segments, blocks of ``block`` segments first (an undecided block's segments are
    then certified one by one); INSIDE segments get ``seg_in``/``seg_out`` = their knot times, the others
    ``(inf, -inf)`` (every entry is written); segments starting after ``t_end`` are CLEAR; ``von[i]``: the
    path's vertical window is ``vlo[i]``/``vhi[i]``."""
    n_paths = tk.shape[0] // K
    for path in range(n_paths):
        on = von[path]
        win = (on, vlo[path], vhi[path]) if on else (on, 0.0, 0.0)
        segments_path(s, tk, path * K, path * (K - 1), kp[path], K - 1, block, (acc_h[path], acc_v[path]), win, t_end,
                      vol, out)


@inline_ir
def candidates_path(tail_in, tail_out, seg_in, seg_out, it, iseg, K, t_end, t_in, t_out, ob):
    """First violation / last exit of the candidates of one path (:func:`candidates_into`): its tails at
    ``it + k``, its segments at ``iseg + k - 1``, written at ``ob + k`` (inlined by numba)."""
    acc_in, acc_out = INF, -INF
    for k in range(K):
        a, b = tail_in[it + k], tail_out[it + k]
        if k > 0:
            j = iseg + k - 1
            acc_in = seg_in[j] if k == 1 else npmin(acc_in, seg_in[j])
            acc_out = seg_out[j] if k == 1 else npmax(acc_out, seg_out[j])
            a, b = npmin(a, acc_in), npmax(b, acc_out)
        if a <= t_end:
            t_in[ob + k], t_out[ob + k] = a, npmin(b, t_end)
        else:
            t_in[ob + k], t_out[ob + k] = INF, -INF


@kernel(void(A, A, A, A, I, F, O, O), lazy=True)
def candidates_into(tail_in, tail_out, seg_in, seg_out, K, t_end, t_in, t_out):
    """First violation / last exit of candidate k (maneuver to knot k, then straight) over ``[0, t_end]``
    (:meth:`daa_sil.daa.trajectory.PathConflicts.candidates`); no violation is ``(inf, -inf)``."""
    n_paths = tail_in.shape[0] // K
    for path in range(n_paths):
        candidates_path(tail_in, tail_out, seg_in, seg_out, path * K, path * (K - 1), K, t_end, t_in, t_out,
                        path * K)


@kernel(void(A3, A3, A3, A3, A3, A3, A3, A3, A3, O4, O4, O4, O4, O4, O4))
def relative_knots_into(ox, oy, oz, ovx, ovy, ovz, t, ipos, ivel, s0, s1, s2, v0, v1, v2):
    """Ownship minus intruder at the knots, ``(N, M, P, K)`` per component, from the ownship's knot states
    and times ``(N, P, K)`` and the intruders' positions / velocities ``(N, M, 3)`` (straight lines):
    ``s = own - (ipos + t ivel)``, ``v = ovel - ivel`` (``intervals.relative_at_knots_reference``)."""
    N, M, P, K = s0.shape
    for n in range(N):
        for m in range(M):
            ix, iy, iz = ipos[n, m, 0], ipos[n, m, 1], ipos[n, m, 2]
            jx, jy, jz = ivel[n, m, 0], ivel[n, m, 1], ivel[n, m, 2]
            for p in range(P):
                for k in range(K):
                    tk = t[n, p, k]
                    s0[n, m, p, k] = ox[n, p, k] - (ix + tk * jx)
                    s1[n, m, p, k] = oy[n, p, k] - (iy + tk * jy)
                    s2[n, m, p, k] = oz[n, p, k] - (iz + tk * jz)
                    v0[n, m, p, k] = ovx[n, p, k] - jx
                    v1[n, m, p, k] = ovy[n, p, k] - jy
                    v2[n, m, p, k] = ovz[n, p, k] - jz
