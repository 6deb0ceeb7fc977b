"""A band axis's paths against their intruders in one pass per path: the relative states at the knots,
the vertical window, the chord certificates of the segments and the straight tails, without storing
the relative states (``(N, M, 2, J+1)`` per component); and the relative states at the two knots of
given segments (what the resolution of the undecided ones reads).

The same operations as ``motion.axis_relative_knots_into`` followed by the evaluator's
``segments_into`` and ``tails_into`` (they share ``evaluate.segments_path`` / ``tails_path`` and
``motion.axis_knot``), with the vertical window of ``wellclear.vertical_window`` in its scalar form;
:class:`daa_sil.daa.trajectory.PathEvaluator` is the reference the tests compare with.
"""

from __future__ import annotations

import numpy as np
from numba import boolean, types, void

from daa_sil.daa.kernels.evaluate import segments_path, tails_path
from daa_sil.daa.kernels.jit import kernel
from daa_sil.daa.kernels.motion import axis_knot, axis_row, row_limit_time, turn_sincos
from daa_sil.daa.kernels.scalar import vertical_window
from daa_sil.daa.kernels.signatures import A, A2, A3, IA, I8, O, F, I


#: ``paths`` = ``(axis, rate, kin, t, nseg)``, ``intr`` = ``(ipos, ivel)``, ``acc`` = ``(acc_h, acc_v)``, the volume
#: ``(D, D * D, D ** 2, ZTHR, TTHR, TCOA)``, the outputs ``(code, seg_in, seg_out)``, ``(tail_in, tail_out)``,
#: ``(vlo, vhi)``
_PATHS = types.Tuple((I, F, A3, A, IA))
_VOL6 = types.UniTuple(F, 6)


@kernel(void(_PATHS, types.UniTuple(A3, 2), types.UniTuple(A2, 2), boolean, I, F, _VOL6, types.Tuple((I8, O, O)),
             types.UniTuple(O, 2), types.UniTuple(O, 2)))
def axis_conflicts_into(paths, intr, acc, vz_const, block, t_end, vol, seg_out_t, tail_out_t, win_out):
    """Paths ``kin`` (N, 2, 9) at knot times ``t`` (J+1,), encounter ``n``'s two paths up to knot ``nseg[n]``
    (``paths`` = ``(axis, rate, kin, t, nseg)``), against intruders ``(ipos, ivel)`` (N, M, 3): segment codes
    and intervals ``(code, seg_in, seg_out)`` (flat over (N, M, 2, J), as ``segments_into``; undecided segments
    are left at ``(inf, -inf)``, those past a path's last knot are CLEAR), tail intervals ``(tail_in,
    tail_out)`` (flat over (N, M, 2, J+1), as ``tails_into``; ``(inf, -inf)`` past a path's last knot) over
    ``[0, t_end]``, and with ``vz_const`` each path's vertical window ``(vlo, vhi)`` (flat over (N, M, 2); else
    not written); ``acc`` = ``(acc_h, acc_v)`` (N, 2) the paths' acceleration bounds (m/s^2); ``vol`` =
    ``(D, D * D, D ** 2, ZTHR, TTHR, TCOA)``."""
    axis, rate, kin, t, nseg = paths
    ipos, ivel = intr
    acc_h, acc_v = acc
    D, DD, D2, H, TT, TC = vol
    vlo, vhi = win_out
    cvol, ivol = (D, DD, H, TT, TC), (D, DD, D2, TT, H, TC)
    N, P, M, K = kin.shape[0], kin.shape[1], ipos.shape[1], t.shape[0]
    sth, cth = turn_sincos(rate, t)
    ox, oy, oz, ovx, ovy, ovz = np.empty(K), np.empty(K), np.empty(K), np.empty(K), np.empty(K), np.empty(K)
    s0, s1, s2, v0, v1, v2 = np.empty(K), np.empty(K), np.empty(K), np.empty(K), np.empty(K), np.empty(K)
    for n in range(N):
        Kn = nseg[n] + 1  # this encounter's knots
        for p in range(P):
            row = axis_row(kin[n], p)
            cap = row_limit_time(axis, rate, row)
            for k in range(Kn):
                ox[k], oy[k], oz[k], ovx[k], ovy[k], ovz[k] = axis_knot(axis, rate, row, cap, sth[k], cth[k], t[k])
            a_h, a_v = acc_h[n, p], acc_v[n, p]
            for m in range(M):
                ix, iy, iz = ipos[n, m, 0], ipos[n, m, 1], ipos[n, m, 2]
                jx, jy, jz = ivel[n, m, 0], ivel[n, m, 1], ivel[n, m, 2]
                for k in range(Kn):
                    tk = t[k]
                    s0[k] = ox[k] - (ix + tk * jx)
                    s1[k] = oy[k] - (iy + tk * jy)
                    s2[k] = oz[k] - (iz + tk * jz)
                    v0[k] = ovx[k] - jx
                    v1[k] = ovy[k] - jy
                    v2[k] = ovz[k] - jz
                path = (n * M + m) * P + p
                w_lo, w_hi = 0.0, 0.0
                if vz_const:
                    w_lo, w_hi = vertical_window(s2[0], v2[0], 0.0, t_end, H, TC)
                    vlo[path], vhi[path] = w_lo, w_hi
                win = (vz_const, w_lo, w_hi)
                if K > 1:
                    segments_path((s0, s1, s2), t, 0, path * (K - 1), Kn, K - 1, block, (a_h, a_v), win, t_end, cvol,
                                  seg_out_t)
                tails_path((s0, s1, s2), (v0, v1, v2), t, 0, path * K, Kn, K, win, False, t_end, ivol, tail_out_t)


@kernel(void(I, F, A3, A, A3, A3, IA, O, O, O, O, O, O, O))
def axis_segment_knots_into(axis, rate, kin, t, ipos, ivel, seg, s0, s1, s2, v0, v1, v2, tk):
    """The relative states (ownship - intruder) and times at the two knots of segments ``seg`` (flat over
    (N, M, 2, J)) of the paths of :func:`axis_conflicts_into`, the first knot of segment ``r`` at ``2 r``,
    the second at ``2 r + 1`` (the numbers ``motion.axis_relative_knots_into`` gives there)."""
    P, M, K = kin.shape[1], ipos.shape[1], t.shape[0]
    S = K - 1
    sth, cth = turn_sincos(rate, t)
    for r in range(seg.shape[0]):
        path = seg[r] // S
        j = seg[r] - path * S
        p = path % P
        nm = path // P
        n, m = nm // M, nm % M
        row = axis_row(kin[n], p)
        cap = row_limit_time(axis, rate, row)
        ix, iy, iz = ipos[n, m, 0], ipos[n, m, 1], ipos[n, m, 2]
        jx, jy, jz = ivel[n, m, 0], ivel[n, m, 1], ivel[n, m, 2]
        for e in range(2):
            k = j + e
            ax, ay, az, avx, avy, avz = axis_knot(axis, rate, row, cap, sth[k], cth[k], t[k])
            tkk = t[k]
            i = 2 * r + e
            s0[i] = ax - (ix + tkk * jx)
            s1[i] = ay - (iy + tkk * jy)
            s2[i] = az - (iz + tkk * jz)
            v0[i] = avx - jx
            v1[i] = avy - jy
            v2[i] = avz - jz
            tk[i] = tkk
