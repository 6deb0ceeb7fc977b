"""The bisection of DAIDALUS's shrinking-cylinder recovery for the rows of one cylinder, compiled: per row,
the earliest time B (to 0.5 s) at which some candidate avoids the cylinder on [0, B] and the corrective
volume after B, then the candidates that do so at the recovery time. The numpy reference is
:class:`daa_sil.daa.recovery.CylinderRecovery` (its ``_at_pivot``, ``_green`` and the loop of ``run``), with its
operations in their order; each row is bisected on its own (the reference halves the rows that are
still going and leaves the others as they are, so a row's steps are its own there too).
"""

from __future__ import annotations

import numpy as np
from numba import boolean, types, void

from daa_sil.daa.kernels.jit import inline, kernel
from daa_sil.daa.kernels.scalar import npmax, npmin
from daa_sil.daa.kernels.signatures import A2, A4, B2, IA, O, F, I

_R4 = types.Array(boolean, 4, "A", readonly=True)


@inline
def _green(corr, r, cyl, c, red_only, horizon, listed, shape, dgrid, B, red, out):
    """``CylinderRecovery._at_pivot`` of row ``r`` (row ``c`` of the cylinder's arrays) at time ``B`` (s): the
    candidates (K,) into ``out``, green where the candidate avoids the cylinder on [0, B] and the corrective
    volume after B (past an intruder's horizon, its cylinder only), isolated ones dropped on the DAIDALUS
    grid. Returns whether one is green. ``red`` (2, J+1) is a working array."""
    c_pre_out, c_in, c_out, tk, window = corr
    pre_in, t_in, t_out = cyl
    j_lo, j_hi = shape
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
        r = rows[c]
        red_p, green_p, pivot = 0.0, L + 1.0, L
        while green_p - red_p > 0.5:
            if _green(corr, r, cyl, c, red_only, horizon, listed, shape, dgrid, pivot, red, buf):
                green_p = pivot
            else:
                red_p = pivot
            pivot = 0.5 * (red_p + green_p)
        rt = npmin(L, green_p + stab) if green_p <= L else red_p
        rt_out[c] = rt
        _green(corr, r, cyl, c, red_only, horizon, listed, shape, dgrid, rt, red, green_out[c])
