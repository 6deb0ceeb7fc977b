"""The compiled resolution of undecided segments (:func:`daa_sil.daa.kernels.resolve.resolve_into`) as a
call: its tolerances, its records made from the segments' arrays, its working arrays kept from call to
call, and the table of numpy's ``log2`` thresholds the bisections count their halvings with. The numpy
reference and the pieces' bookkeeping are :mod:`daa_sil.daa.undecided`."""

from __future__ import annotations

import functools

import numpy as np

from daa_sil.daa import kernels
from daa_sil.daa.certify import P_TOL, V_TOL
from daa_sil.daa.scratch import scratch

#: most parts an undecided segment is split into (as many as its parts' chords need to meet V_TOL / P_TOL)
MAX_SPLIT = 16
#: s, how closely an entry into / an exit from the volume on the true path is located (bisection brackets;
#: entries decide when a candidate conflicts, exits only rank recovery candidates)
BISECT_DT_IN = 0.04
BISECT_DT_OUT = 0.1
#: s, sampling interval of the true predicate inside a short piece whose ends are clear but which is not
#: certified clear (a clip of the volume shorter than this can be missed)
CLIP_DT = 0.01
#: most rounds of splitting an undecided piece
MAX_DEPTH = 8


def resolve_segments(kin: tuple, ipv: np.ndarray, m: int, p: int, path: np.ndarray, s: tuple, v: tuple,
                     tk: np.ndarray, flat_seg: np.ndarray, ka: np.ndarray, acc_h: np.ndarray, acc_v: np.ndarray,
                     jerk, kink, vwin, exits: bool, th, seg_in: np.ndarray, seg_out: np.ndarray) -> None:
    """:meth:`UndecidedPieces.resolve` in one call of :func:`daa_sil.daa.kernels.resolve.resolve_into`.

    ``kin`` the paths' motion (:attr:`daa_sil.daa.trajectory.ManeuverPaths.kin`), ``ipv`` (N * M, 6) the
    intruders' positions and velocities at t = 0 (m, m/s), ``m``/``p`` intruders and paths per encounter;
    per undecided segment (row): ``path`` its flat (n, m, p) path, ``flat_seg`` its flat segment id (into
    ``seg_in``/``seg_out``, updated), ``ka`` the flat index of its first knot into the relative states
    ``s``/``v`` (three flat component arrays each) and knot times ``tk`` (s), ``acc_h``/``acc_v`` (m/s^2),
    ``jerk`` (m/s^3) and ``kink`` (s) of its path (None: none), ``vwin`` its path's vertical window
    ``(lo, hi, on)`` (s; ``on`` whether the path has one, None: every path; ``vwin`` None: none). The rows of
    one encounter (``path // (m * p)``) make their batch-wide choices together, apart from the others."""
    r = path.size
    n = path // (m * p)
    if r > 1 and (n[1:] < n[:-1]).any():
        raise ValueError("resolve_segments: the segments must come in encounter order (ascending flat ids)")
    if kin[0] == "axis":
        rows = n * p + path % p
        mot = (0, kin[1], kin[2], kin[3].reshape(-1, kin[3].shape[-1]), _NO_PHASES, _NO_ROWS, 0.0, 0.0, 0.0)
    else:
        rows = n
        mot = (1, 0, 0.0, _NO_ROWS, kin[1], kin[2], *kin[3:])
    none = np.zeros(r)
    if vwin is None:
        vlo, vhi, von = none, none, np.zeros(r, bool)
    else:
        vlo, vhi = vwin[0], vwin[1]
        von = np.ones(r, bool) if vwin[2] is None else np.asarray(vwin[2], bool)
    i64 = lambda a: a.astype(np.int64, copy=False)  # noqa: E731
    who = (ipv, i64(rows), i64(path // p), i64(n))
    per_row = (flat_seg.astype(np.int64, copy=False), ka.astype(np.int64, copy=False), acc_h, acc_v,
               none if jerk is None else np.asarray(jerk, float),
               none[:, None] if kink is None else np.asarray(kink, float).reshape(r, -1), von, vlo, vhi)
    D = float(th.dthr)
    need = np.zeros(3, np.int64)
    with scratch() as ws:
        work = tuple(ws.buffer(name, dtype) for name, dtype in zip(_WORK, _WORK_TYPES))
        kernels.get().resolve_into(
            mot, who, per_row, (*s, *v, tk), (jerk is not None, kink is not None, bool(exits)), bisect_thresholds(),
            _LIMITS, _TIMES, (D, D * D, float(th.zthr), float(th.tthr), float(th.tcoa)), (seg_in, seg_out),
            (*work, need))
        for name, size, dtype, buf in zip(_WORK, need, _WORK_TYPES, work):  # large enough for the next call this size
            if size > buf.size:
                ws.take(name, int(size), dtype)


#: the resolution kernel's limits and times (its records ``(MAX_DEPTH, MAX_SPLIT, 2 V_TOL, 8 P_TOL)`` and
#: ``(BISECT_DT_IN, BISECT_DT_OUT, CLIP_DT)``)
_LIMITS = (MAX_DEPTH, MAX_SPLIT, 2.0 * V_TOL, 8.0 * P_TOL)
_TIMES = (BISECT_DT_IN, BISECT_DT_OUT, CLIP_DT)
#: the resolution kernel's working arrays (:mod:`daa_sil.daa.scratch`, kept from call to call): floats, ints, flags
_WORK = ("resolve_f", "resolve_i", "resolve_b")
_WORK_TYPES = (np.float64, np.int64, np.bool_)

#: placeholder motion rows for the kind of path a call does not use
_NO_ROWS = np.zeros((0, 9))
_NO_PHASES = np.zeros((0, 3, 9))


@functools.lru_cache(maxsize=None)
def bisect_thresholds(count: int = 64) -> np.ndarray:
    """``thr[n]`` (n < ``count``): the smallest float ``x`` with ``np.log2(x) > n``, so that the number of
    ``thr`` at or below ``x`` is ``int(np.ceil(np.log2(x)))`` for ``1 <= x < 2**count`` -- numpy's log2,
    whatever its last bit, found by bisecting the floats between ``2**n`` and ``2**(n + 1)``."""
    out = np.empty(count)
    for n in range(count):
        a, b = int(np.float64(2.0 ** n).view(np.int64)), int(np.float64(2.0 ** (n + 1)).view(np.int64))
        if not (np.log2(np.int64(a).view(np.float64)) <= n < np.log2(np.int64(b).view(np.float64))):
            raise ArithmeticError(f"numpy's log2 is not exact at 2**{n} / 2**{n + 1}")
        while b - a > 1:
            mid = (a + b) // 2
            if np.log2(np.int64(mid).view(np.float64)) > n:
                b = mid
            else:
                a = mid
        out[n] = np.int64(b).view(np.float64)
    out.setflags(write=False)
    return out


__all__ = ["MAX_SPLIT", "BISECT_DT_IN", "BISECT_DT_OUT", "CLIP_DT", "MAX_DEPTH", "resolve_segments",
           "bisect_thresholds"]
