"""The true relative state of a band axis's maneuver path or of a command's path at given times, and the
bisection of a crossing of the well-clear boundary on it, one compiled call per evaluation: the
kernels of the *unfused* resolution (``UndecidedPieces`` with ``fused=False``), which only the tests
take, between the numpy reference and the fused loop (:mod:`daa_sil.daa.kernels.resolve`).

Not loaded by :func:`daa_sil.daa.kernels.get` (every process that computes bands) but by
:func:`daa_sil.daa.kernels.get_unfused`, on first use: a SIL node or a campaign worker neither
compiles nor loads them. The numpy reference is :meth:`daa_sil.daa.undecided.UndecidedPieces._bisect` and the
paths' ``state_at``.
"""

from __future__ import annotations

from numba import boolean, float64, types, void

from daa_sil.daa.kernels.jit import kernel
from daa_sil.daa.kernels.motion import command_rel_state, rel_state
from daa_sil.daa.kernels.scalar import halve, wcv_soa
from daa_sil.daa.kernels.signatures import A, A2, A3, IA, O, F, I

_B1 = types.Array(boolean, 1, "A", readonly=True)


@kernel(void(I, F, A2, A2, A, types.Array(float64, 2, "C")))
def rel_states_into(axis, rate, kin, ipv, t, out):
    """Relative state of path row ``i`` at ``t[i]`` into ``out[:, i]`` (six rows)."""
    for i in range(t.shape[0]):
        out[0, i], out[1, i], out[2, i], out[3, i], out[4, i], out[5, i] = rel_state(axis, rate, kin, ipv, i, t[i])


#: the volume of the predicate ``(D * D, TTHR, ZTHR, TCOA)``
_VOL4 = types.UniTuple(F, 4)


@kernel(void(I, F, A2, A2, O, O, _B1, IA, IA, IA, _B1, _VOL4))
def bisect_into(axis, rate, kin, ipv, lo, hi, lo_in, steps, n_in, n_out, mixed, vol):
    """Halve row ``i``'s ``[lo, hi]`` ``steps[i]`` times keeping the predicate ``lo_in`` at ``lo``; with
    ``mixed[i]``, a row starting inside stops after ``n_out[i]`` halvings and one starting outside after
    ``n_in[i]`` (``_bisect``: the counts are the row's encounter's); ``vol`` = ``(D * D, TTHR, ZTHR, TCOA)``."""
    DD, TT, H, TC = vol
    for i in range(lo.shape[0]):
        a, b, flag = lo[i], hi[i], lo_in[i]
        for k in range(steps[i]):
            mid = 0.5 * (a + b)
            sx, sy, sz, vx, vy, vz = rel_state(axis, rate, kin, ipv, i, mid)
            same = wcv_soa(sx, sy, sz, vx, vy, vz, DD, TT, H, TC) == flag
            a, b = halve(a, b, mid, same, k, mixed[i], flag, n_in[i], n_out[i])
        lo[i], hi[i] = a, b


@kernel(void(A3, A2, F, F, F, A2, A, types.Array(float64, 2, "C")))
def command_rel_states_into(ph_rows, enc, max_turn, h_acc, v_acc, ipv, t, out):
    """Relative state of row ``i`` at ``t[i]`` into ``out[:, i]``."""
    for i in range(t.shape[0]):
        out[0, i], out[1, i], out[2, i], out[3, i], out[4, i], out[5, i] = command_rel_state(
            ph_rows, enc, ipv, i, t[i], max_turn, h_acc, v_acc)


@kernel(void(A3, A2, F, F, F, A2, O, O, _B1, IA, IA, IA, _B1, _VOL4))
def command_bisect_into(ph_rows, enc, max_turn, h_acc, v_acc, ipv, lo, hi, lo_in, steps, n_in, n_out, mixed, vol):
    """:func:`bisect_into` on command paths."""
    DD, TT, H, TC = vol
    for i in range(lo.shape[0]):
        a, b, flag = lo[i], hi[i], lo_in[i]
        for k in range(steps[i]):
            mid = 0.5 * (a + b)
            sx, sy, sz, vx, vy, vz = command_rel_state(ph_rows, enc, ipv, i, mid, max_turn, h_acc, v_acc)
            same = wcv_soa(sx, sy, sz, vx, vy, vz, DD, TT, H, TC) == flag
            a, b = halve(a, b, mid, same, k, mixed[i], flag, n_in[i], n_out[i])
        lo[i], hi[i] = a, b
