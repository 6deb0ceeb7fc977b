"""Conflict detection along kinematic ownship trajectories against straight-line intruders.

A *maneuver path* is the ownship flying a maneuver (turn at the turn-rate limit, accelerate at the
horizontal or vertical limit, or a multi-axis command), sampled at knot times
``t_0 = 0 < t_1 < ... < t_J``. Candidate ``k`` of the path flies the path up to knot ``k`` and then
continues straight with the knot-``k`` velocity. Two parts are evaluated:

* **tails** (straight after knot ``k``): the exact closed form of
  :func:`daa_sil.geometry.wellclear.violation_interval` (re-stated on contiguous component arrays in
  :func:`daa_sil.daa.intervals.interval_soa`, identical numbers, about 2x faster);
* **the maneuver between knots** on the true trajectory (arc, parabola), not on its chords. A piece of
  duration ``h`` is within ``A h^2 / 8`` of its chord in position and ``A h / 2`` in velocity (``A`` the
  path's acceleration bound); with these bounds :func:`daa_sil.daa.certify.classify_pieces` certifies it *clear* (no
  instant of the true path violates) or *inside* (every instant does), blocks of :data:`BLOCK`
  segments first. A segment left undecided is resolved with the exact predicate on the true state
  (:mod:`daa_sil.daa.undecided`): both ends violating give its first entry and last exit exactly;
  one end violating, the boundary by bisection (``BISECT_DT_IN``, ``BISECT_DT_OUT``) with the other
  side certified clear; both ends clear, a second-order certificate
  (:func:`daa_sil.daa.certify.clear_second_order`) or, for the few it cannot clear, sampling every
  ``CLIP_DT``.

This replaces the chords of the previous version in **every preset**: a chord's velocity is wrong by
up to half a knot step (2.4 m/s for 5 deg at 55 m/s) and it missed short violations during turns
(issue 15, example 4). It is a correctness fix, not a choice of semantics, so ``do365`` and
``paper`` get it as well as ``daidalus``; their bands change only where the chords were wrong. We
also differ here from DAIDALUS, whose straight *coast* segments keep each knot's velocity for a
whole knot interval (``docs/daa.md``, "Differences from DAIDALUS we keep").

The certificates use the form ``|s + (TTHR/2) v| <= sqrt(DTHR^2 + (TTHR/2)^2 |v|^2)`` of the tau_mod
test, with d_cpa and closing bounded separately; they are exact for TCOA = 0 (every preset). Times
are absolute (s from now); no violation is ``(inf, -inf)``.
"""

from __future__ import annotations

import numpy as np

from daa_sil.geometry import wellclear as wc
from daa_sil.geometry.kinematics import (AircraftState)
from daa_sil.geometry.thresholds import Thresholds
from daa_sil.daa.intervals import relative_at_knots, row_blocks, interval_soa
from daa_sil.daa.certify import CLEAR, INSIDE, UNDECIDED, classify_pieces
from daa_sil.daa import kernels
from daa_sil.daa.undecided import UndecidedPieces, piece_index
from daa_sil.daa.paths import ManeuverPaths, PathConflicts, StateAt  # (the data, defined apart; offered here too)

#: knot-to-knot segments examined together first (a block far from the volume is clear as a whole)
BLOCK = 4
_NONE = np.zeros(0)

class PathEvaluator:
    """Relative geometry of maneuver paths against straight-line intruders, evaluated for any volume.

    Built once per (paths, intruders); :meth:`evaluate` then gives :class:`PathConflicts` for a
    well-clear volume or a cylinder (a :class:`~daa_sil.geometry.thresholds.Thresholds` with TTHR = 0).
    ``tails``: True (every knot), ``"last"`` (only the last knot's) or False. ``exits=False``: the last
    exits are not searched (a segment that starts violating ends its violation at its end; use it when
    only first entries matter, as for SM).
    """

    def __init__(self, paths: ManeuverPaths, intr: AircraftState, t_end: float, tails: "bool | str" = True,
                 exits: bool = True):
        n, p, k = paths.shape
        m = intr.shape[1]
        self.paths, self.t_end, self.with_tails, self.exits = paths, float(t_end), tails, exits
        self.shape = (n, m, p, k)
        knot_t = paths.knot_times()
        self.t = knot_t[:, None]  # (N, 1, P, K)
        self.intr = intr
        self.ipos, self.ivel = intr.position(), intr.velocity()  # (N, M, 3)
        #: relative position ownship - intruder at the knots and relative velocity of the tails, per
        #: component (N, M, P, K), contiguous
        if paths.pos is None:  # a band axis's paths: straight from their motion (axis_relative_knots_into)
            self.s, self.v = [np.empty(self.shape) for _ in range(3)], [np.empty(self.shape) for _ in range(3)]
            kin = paths.kin
            kernels.get().axis_relative_knots_into(kin[1], kin[2], kin[3], paths.axis_times(), self.ipos, self.ivel,
                                                   *self.s, *self.v)
        else:
            self.s, self.v = relative_at_knots(paths.pos, paths.vel, knot_t, self.ipos, self.ivel, self.shape)
        self._vwin = None
        self._vwin_flat_cache = None  #: :meth:`_vwin_flat` of the current ``_vwin``
        self._kp = None  #: :meth:`_knots_per_path`, made once
        #: use the compiled kernels (False: the numpy reference, see :meth:`evaluate_reference`); ``fused``:
        #: resolve undecided pieces in one compiled loop (False: the numpy loop over compiled pieces)
        self.compiled, self.fused = True, True

    def evaluate(self, th: Thresholds) -> PathConflicts:
        """Segment and tail intervals for volume ``th`` (see :class:`PathConflicts`), compiled kernels."""
        return self._evaluate(th, compiled=True)

    def evaluate_reference(self, th: Thresholds) -> PathConflicts:
        """:meth:`evaluate` with the numpy tails and chord certificates (the kernels' test oracle)."""
        return self._evaluate(th, compiled=False)

    def _evaluate(self, th: Thresholds, compiled: bool) -> PathConflicts:
        self.compiled = compiled
        n, m, p, k = self.shape
        seg_shape = (n, m, p, max(k - 1, 0))
        if not compiled and self._reference_groups() is not None:
            return self._evaluate_by_groups(th)
        self._vwin = None
        self._vwin_flat_cache = None
        if self.paths.vz_const_any():  # relative altitude linear in time on a path: one vertical window each
            self._vwin = wc.vertical_window(self.s[2][..., :1], self.v[2][..., :1], 0.0, self.t_end, th.zthr, th.tcoa)
        full_tails = self.with_tails is True
        tail = (lambda fill: np.empty(self.shape)) if full_tails else (lambda fill: np.full(self.shape, fill))  # noqa: E731
        seg = (lambda fill: np.empty(seg_shape)) if compiled else (lambda fill: np.full(seg_shape, fill))  # noqa: E731
        pc = PathConflicts(seg(np.inf), seg(-np.inf), tail(np.inf), tail(-np.inf), self.t, self.t_end)
        if compiled:
            if k > 1:
                self._segments_compiled(th, pc)
            if self.with_tails:
                self._tails_compiled(th, pc)
            return pc
        if k > 1:
            self._segments(th, np.broadcast_to(self.t, self.shape), pc)
        if self.with_tails:
            want = None
            if self.with_tails == "last":
                want = np.zeros(self.shape, bool)
                want[..., -1] = True
            self._tails(th, pc, want)
        return pc

    def _reference_groups(self) -> "list[tuple[int, bool, np.ndarray]] | None":
        """``[(knots, vz_const, encounters)]`` when the paths' knot counts (``n_seg``) or vertical windows
        (``vz_const`` per encounter) differ between encounters, else None."""
        ns, vz = self.paths.n_seg, self.paths.vz_const
        n, _, _, k = self.shape
        if (ns is None or np.all(ns == k - 1)) and np.ndim(vz) == 0:
            return None
        knots = np.full(n, k, np.int64) if ns is None else np.asarray(ns, np.int64) + 1
        flat = np.broadcast_to(np.asarray(vz, bool), (n,))
        key = knots * 2 + flat
        return [(int(v) // 2, bool(v % 2), np.flatnonzero(key == v)) for v in np.unique(key)]

    def _evaluate_by_groups(self, th: Thresholds) -> PathConflicts:
        """:meth:`evaluate_reference` of paths whose encounters have their own knot counts or vertical
        windows: each set of encounters alike evaluated on its own (what each encounter gets in a call of
        its own), the knots past its count clear and without tails."""
        n, m, p, k = self.shape
        fill = lambda shape, v: np.full(shape, v)  # noqa: E731
        seg = (n, m, p, max(k - 1, 0))
        pc = PathConflicts(fill(seg, np.inf), fill(seg, -np.inf), fill(self.shape, np.inf), fill(self.shape, -np.inf),
                           self.t, self.t_end)
        for knots, vz, enc in self._reference_groups():
            paths = self.paths.subset(enc).truncated(knots, vz)
            ev = PathEvaluator(paths, self.intr[enc], self.t_end, self.with_tails, self.exits)
            ev.fused = self.fused
            sub = ev.evaluate_reference(th)
            pc.seg_in[enc, ..., :knots - 1], pc.seg_out[enc, ..., :knots - 1] = sub.seg_in, sub.seg_out
            if self.with_tails == "last":  # (the tail of each path's own last knot)
                pc.tail_in[enc, ..., knots - 1] = sub.tail_in[..., -1]
                pc.tail_out[enc, ..., knots - 1] = sub.tail_out[..., -1]
            elif self.with_tails:
                pc.tail_in[enc, ..., :knots], pc.tail_out[enc, ..., :knots] = sub.tail_in, sub.tail_out
        return pc

    def _vwin_flat(self):
        """(lo, hi, on): the per-path vertical windows and which paths have one, as flat arrays (made once per
        evaluation)."""
        if self._vwin_flat_cache is None:
            n_paths = self.shape[0] * self.shape[1] * self.shape[2]
            if self._vwin is None:
                self._vwin_flat_cache = _NONE, _NONE, np.zeros(n_paths, bool)
            else:
                self._vwin_flat_cache = (self._vwin[0].reshape(-1), self._vwin[1].reshape(-1), self._vwin_on(n_paths))
        return self._vwin_flat_cache

    def _vwin_on(self, n_paths: int) -> np.ndarray:
        """(n_paths,) bool: which flat paths have a vertical window (their vertical speed is constant)."""
        vz = self.paths.vz_const
        if np.ndim(vz) == 0:
            return np.full(n_paths, bool(vz))
        n, m, p, _ = self.shape
        return np.ascontiguousarray(np.broadcast_to(np.asarray(vz, bool)[:, None, None], (n, m, p))).reshape(-1)

    def _knots_per_path(self) -> np.ndarray:
        """(n_paths,) int64: each flat path's own number of knots (``n_seg + 1``, or all; made once)."""
        if self._kp is None:
            n, m, p, k = self.shape
            ns = self.paths.n_seg
            if ns is None:
                self._kp = np.full(n * m * p, k, np.int64)
            elif m * p == 1:
                self._kp = np.asarray(ns, np.int64) + 1
            else:
                self._kp = np.ascontiguousarray(np.broadcast_to((np.asarray(ns, np.int64) + 1)[:, None, None],
                                                                (n, m, p))).reshape(-1)
        return self._kp

    def _tails_compiled(self, th: Thresholds, pc: PathConflicts) -> None:
        """:meth:`_tails` (every knot, or the last one with ``tails="last"``) in one compiled pass."""
        lo, hi, on = self._vwin_flat()
        D = float(th.dthr)
        kernels.get().tails_into(tuple(c.reshape(-1) for c in self.s), tuple(c.reshape(-1) for c in self.v),
                                 self._flat_times(), self.shape[3], self._knots_per_path(), on, lo, hi,
                                 self.with_tails == "last", self.t_end,
                                 (D, D * D, D ** 2, float(th.tthr), float(th.zthr), float(th.tcoa)),
                                 (pc.tail_in.reshape(-1), pc.tail_out.reshape(-1)))

    def _segments_compiled(self, th: Thresholds, pc: PathConflicts) -> None:
        """:meth:`_segments` with the certificates in one compiled pass (undecided pieces: :meth:`UndecidedPieces.resolve`)."""
        n, m, p, k = self.shape
        lo, hi, on = self._vwin_flat()
        tab = self._path_tables()
        code = np.empty(n * m * p * (k - 1), np.int8)
        seg_in, seg_out = pc.seg_in.reshape(-1), pc.seg_out.reshape(-1)
        D = float(th.dthr)
        kernels.get().segments_into(tuple(c.reshape(-1) for c in self.s), self._flat_times(), k, self._knots_per_path(),
                                    BLOCK, tab["acc_h"], tab["acc_v"], on, lo, hi, self.t_end,
                                    (D, D * D, float(th.zthr), float(th.tthr), float(th.tcoa)), (code, seg_in, seg_out))
        todo = np.flatnonzero(code == UNDECIDED)
        if todo.size:
            self._undecided().resolve(todo, th, seg_in, seg_out)

    def _tails(self, th: Thresholds, pc: PathConflicts, want: "np.ndarray | None") -> None:
        """Tail intervals of every knot (``want`` None) or of the knots where ``want``."""
        if want is None:  # every knot, in cache-sized blocks of encounters
            n, m, p, k = self.shape
            tt_all = np.broadcast_to(self.t, self.shape)
            for sl in row_blocks(n, m * p * k):
                tt = tt_all[sl]
                tk = tt.reshape(-1)
                win = None
                if self._vwin is not None:
                    win = ((np.maximum(self._vwin[0][sl], tt) - tt).reshape(-1),
                           (np.minimum(self._vwin[1][sl], self.t_end) - tt).reshape(-1))
                t_in, t_out = interval_soa(*(c[sl].reshape(-1) for c in self.s), *(c[sl].reshape(-1) for c in self.v),
                                           np.maximum(self.t_end - tk, 0.0), th, win)
                t_in += tk
                t_out += tk
                late = tk > self.t_end
                if late.any():
                    t_in[late], t_out[late] = np.inf, -np.inf
                pc.tail_in[sl] = t_in.reshape(tt.shape)
                pc.tail_out[sl] = t_out.reshape(tt.shape)
            return
        sel = np.flatnonzero(want)  # the chosen knots
        if not sel.size:
            return
        comp = [c.reshape(-1)[sel] for c in self.s]
        vel = [c.reshape(-1)[sel] for c in self.v]
        tk = self._flat_times()[sel]
        win = None
        if self._vwin is not None:
            path = sel // self.shape[3]
            lo, hi = self._vwin[0].reshape(-1)[path], self._vwin[1].reshape(-1)[path]
            win = (np.maximum(lo, tk) - tk, np.minimum(hi, self.t_end) - tk)
        t_in, t_out = interval_soa(*comp, *vel, np.maximum(self.t_end - tk, 0.0), th, win)
        ok = tk <= self.t_end
        pc.tail_in.reshape(-1)[sel] = np.where(ok, t_in + tk, np.inf)
        pc.tail_out.reshape(-1)[sel] = np.where(ok, t_out + tk, -np.inf)

    def _classify_between(self, th: Thresholds, tt, ja, jb) -> np.ndarray:
        """Codes ``(N, M, P, len(ja))`` of the pieces from knot ``ja[i]`` to knot ``jb[i]`` of every path."""
        t0, t1 = tt[..., ja], tt[..., jb]
        h = t1 - t0
        s0 = [np.ascontiguousarray(c[..., ja]).ravel() for c in self.s]
        s1 = [np.ascontiguousarray(c[..., jb]).ravel() for c in self.s]
        acc_h = self.paths.acc_h[:, None, :, None]
        e_p = np.ascontiguousarray(np.broadcast_to(acc_h * h * h * 0.125, h.shape)).ravel()
        e_v = np.ascontiguousarray(np.broadcast_to(acc_h * h * 0.5, h.shape)).ravel()
        any_v = self._any_v_encounter()[:, None, None, None]  # (each encounter's np.any, as in a call of its own)
        e_z = np.ascontiguousarray(np.broadcast_to(np.where(any_v, self.paths.acc_v[:, None, :, None] * h * h * 0.125,
                                                            0.0), h.shape)).ravel()
        win = None
        if self._vwin is not None:
            lo, hi = self._vwin
            win = (np.ascontiguousarray(np.maximum(lo, t0) - t0).ravel(), np.ascontiguousarray(np.minimum(hi, t1) - t0).ravel())
        code = classify_pieces(*s0, *s1, np.ascontiguousarray(h).ravel(), th, e_p, e_v, e_z, win)
        return code.reshape(h.shape)

    def _segments(self, th: Thresholds, tt: np.ndarray, pc: PathConflicts) -> None:
        """Fill ``pc.seg_in``/``pc.seg_out`` (module docstring)."""
        n, m, p, k = self.shape
        seg_shape = (n, m, p, k - 1)
        live = tt[..., :-1] < self.t_end
        j = np.arange(k - 1)
        if k - 1 > BLOCK:  # coarse pass: blocks of BLOCK segments decided at once (most are far away)
            edges = np.r_[np.arange(0, k - 1, BLOCK), k - 1]
            bcode = self._classify_between(th, tt, edges[:-1], edges[1:])
            per_seg = np.repeat(bcode, np.diff(edges), axis=-1)
            code = np.where(per_seg == INSIDE, INSIDE, CLEAR).astype(np.int8)
            fb = np.flatnonzero(bcode == UNDECIDED)  # undecided blocks: classify their segments
            if fb.size:
                nb = edges.size - 1
                path, b = np.divmod(fb, nb)
                width = np.diff(edges)[b]
                offs = np.arange(BLOCK)
                seg = (path * (k - 1) + edges[b])[:, None] + offs[None, :]
                fine = seg[offs[None, :] < width[:, None]]
                code.ravel()[fine] = self._classify_flat(th, fine, seg_shape)
        else:
            code = self._classify_between(th, tt, j, j + 1)
        code[~live] = CLEAR
        inside = code == INSIDE
        np.copyto(pc.seg_in, tt[..., :-1], where=inside)
        np.copyto(pc.seg_out, tt[..., 1:], where=inside)
        todo = np.flatnonzero(code == UNDECIDED)
        if todo.size:
            self._undecided().resolve(todo, th, pc.seg_in.reshape(-1), pc.seg_out.reshape(-1))

    def _any_v_encounter(self) -> np.ndarray:
        """(N,) bool: does some path of the encounter accelerate vertically (whether the vertical error bound
        is used: ``np.any`` of a call of its own)."""
        return np.any(np.asarray(self.paths.acc_v) != 0, axis=-1)

    def _undecided(self) -> UndecidedPieces:
        """The true paths as the resolution of undecided pieces reads them (this evaluation's window)."""
        on = None
        if self._vwin is not None and np.ndim(self.paths.vz_const):
            on = self._vwin_on(int(np.prod(self.shape[:3])))
        return UndecidedPieces(self.paths, self.ipos, self.ivel, self.s, self.v, self._flat_times(),
                               self._path_tables(), self._vwin, self.exits, self.compiled, self.fused, on)

    def _flat_times(self) -> np.ndarray:
        """Knot times as a flat contiguous (N*M*P*K) array (cached)."""
        if getattr(self, "_tt_flat", None) is None:
            self._tt_flat = np.ascontiguousarray(np.broadcast_to(self.t, self.shape)).ravel()
        return self._tt_flat

    def _path_tables(self):
        """Per path (flat n, m, p) lookups, cached: encounter, path index, flat (n, m), acceleration
        bounds and the vertical window bounds."""
        if getattr(self, "_tables", None) is None:
            n, m, p, k = self.shape
            nn, mm, pp = (a.ravel() for a in np.indices((n, m, p)))
            P = self.paths
            self._tables = dict(n=nn, p=pp, nm=nn * m + mm, acc_h=P.acc_h[nn, pp], acc_v=P.acc_v[nn, pp],
                                jerk=None if P.jerk_h is None else P.jerk_h[nn, pp],
                                kink=None if P.kink_t is None else P.kink_t[nn, pp])
        return self._tables

    def _classify_flat(self, th, flat_seg, seg_shape) -> np.ndarray:
        path, ka, t0, h = piece_index(flat_seg, self.shape[3], self._flat_times())
        tab = self._path_tables()
        a_h, a_v = tab["acc_h"][path], tab["acc_v"][path]
        win = None
        if self._vwin is not None:
            lo, hi = self._vwin[0].reshape(-1)[path], self._vwin[1].reshape(-1)[path]
            win = (np.maximum(lo, t0) - t0, np.minimum(hi, t0 + h) - t0)
        e_z = np.where(self._any_v_encounter()[tab["n"][path]], a_v * h * h * 0.125, 0.0)
        s = [c.reshape(-1) for c in self.s]
        return classify_pieces(s[0][ka], s[1][ka], s[2][ka], s[0][ka + 1], s[1][ka + 1], s[2][ka + 1], h, th,
                               a_h * h * h * 0.125, a_h * h * 0.5, e_z, win)


def path_conflicts(paths: ManeuverPaths, intr: AircraftState, th: Thresholds, t_end: float,
                   tails: "bool | str" = True, exits: bool = True) -> PathConflicts:
    """:class:`PathConflicts` of ``paths`` against intruders ``(N, M)`` for volume ``th`` over ``[0, t_end]``."""
    return PathEvaluator(paths, intr, t_end, tails, exits).evaluate(th)


__all__ = ["BLOCK", "ManeuverPaths", "PathConflicts", "PathEvaluator", "StateAt", "path_conflicts"]
