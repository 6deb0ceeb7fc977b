"""Elementwise kernels over 1-D component arrays: one loop, no temporaries.

Each writes into output arrays the caller allocates; array arguments may be strided views (a
scalar broadcast with ``np.broadcast_to`` costs nothing). The Python wrappers with the numpy
signatures are :func:`daa_sil.daa.intervals.interval_soa`, :func:`daa_sil.daa.intervals.wcv_soa`,
:func:`daa_sil.daa.certify.classify_pieces` and :func:`daa_sil.daa.certify.clear_second_order`.
"""

from __future__ import annotations

from numba import boolean, float64, int8, types, void

from daa_sil.daa.kernels.jit import kernel
from daa_sil.daa.kernels.pieces import classify, clear2
from daa_sil.daa.kernels.scalar import interval, vertical_window, wcv_soa

#: input arrays: any layout, read-only accepted (a mutable array converts to it)
A = types.Array(float64, 1, "A", readonly=True)
#: output arrays
O = float64[:]
F = float64


@kernel(void(A, A, A, A, A, A, A, A, A, boolean, F, F, F, F, F, F, O, O))
def interval_into(sx, sy, sz, vx, vy, vz, length, wlo, whi, has_win, D, DD, D2, TT, H, TC, t_in, t_out):
    """Violation interval of each straight line over ``[0, length]`` (vertical window ``wlo``/``whi``
    when ``has_win``) into ``t_in``/``t_out``."""
    for i in range(sx.shape[0]):
        if has_win:
            lo, hi = wlo[i], whi[i]
        else:
            lo, hi = vertical_window(sz[i], vz[i], 0.0, length[i], H, TC)
        t_in[i], t_out[i] = interval(sx[i], sy[i], sz[i], vx[i], vy[i], vz[i], length[i], lo, hi,
                                     D, DD, D2, TT, H, TC)


@kernel(void(A, A, A, A, A, A, F, F, F, F, boolean[:]))
def wcv_soa_into(sx, sy, sz, vx, vy, vz, DD, TT, H, TC, out):
    """Instantaneous well-clear violation of each relative state into ``out``."""
    for i in range(sx.shape[0]):
        out[i] = wcv_soa(sx[i], sy[i], sz[i], vx[i], vy[i], vz[i], DD, TT, H, TC)


@kernel(void(A, A, A, A, A, A, A, A, A, A, A, A, boolean, F, F, F, F, F, int8[:]))
def classify_into(x0, y0, z0, x1, y1, z1, h, e_p, e_v, e_z, wlo, whi, has_win, D, DD, H, TT, TC, out):
    """CLEAR / INSIDE / UNDECIDED code of each chord piece into ``out``."""
    for i in range(x0.shape[0]):
        lo, hi = (wlo[i], whi[i]) if has_win else (0.0, 0.0)
        out[i] = classify(x0[i], y0[i], z0[i], x1[i], y1[i], z1[i], h[i], e_p[i], e_v[i], e_z[i], lo, hi, has_win,
                          D, DD, H, TT, TC)


@kernel(void(A, A, A, A, A, A, A, A, A, A, A, A, A, A, F, F, F, F, F, boolean[:]))
def clear2_into(x0, y0, z0, x1, y1, z1, u0x, u0y, u1x, u1y, h, e_p, e_v, e_z, D, DD, H, TT, TC, out):
    """Second-order CLEAR certificate of each piece into ``out``."""
    for i in range(x0.shape[0]):
        out[i] = clear2(x0[i], y0[i], z0[i], x1[i], y1[i], z1[i], u0x[i], u0y[i], u1x[i], u1y[i], h[i], e_p[i],
                        e_v[i], e_z[i], D, DD, H, TT, TC)
