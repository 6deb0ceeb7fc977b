"""Resolving the pieces of a maneuver path that the chord certificates left undecided, on the true
state: both ends violating give the exact entry and exit, one end violating a bisection, both ends
clear a second-order certificate or sampling every CLIP_DT (the rules in docs/daa.md)."""

from __future__ import annotations

import numpy as np

from daa_sil.daa.certify import CLEAR, settle_time, classify_pieces, clear_second_order
from daa_sil.daa.intervals import as_vector, wcv_soa
from daa_sil.daa import kernels
# the tolerances and the compiled call (offered here too: the tests and the evaluator read them from here)
from daa_sil.daa.resolve_call import (BISECT_DT_IN, BISECT_DT_OUT, CLIP_DT, MAX_DEPTH, MAX_SPLIT, bisect_thresholds,
                                      resolve_segments)

def segment_knots(flat_seg: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Path (flat n, m, p) and first-knot flat index of the knot-to-knot segments ``flat_seg`` (flat indices
    over (N, M, P, K - 1)) of paths with ``k`` knots."""
    path = flat_seg // (k - 1)
    return path, flat_seg + path  # = path * k + (flat_seg - path * (k - 1))


def piece_index(flat_seg: np.ndarray, k: int, t_flat: np.ndarray):
    """:func:`segment_knots` of the segments ``flat_seg``, and their start (s) and duration (s) at knot times
    ``t_flat`` (N*M*P*K)."""
    path, ka = segment_knots(flat_seg, k)
    t0 = t_flat[ka]
    return path, ka, t0, t_flat[ka + 1] - t0


class UndecidedPieces:
    """The true paths of a :class:`daa_sil.daa.trajectory.PathEvaluator`, as far as resolving undecided
    pieces needs them, and the resolution itself (:meth:`resolve`).

    ``paths`` the ownship's :class:`~daa_sil.daa.trajectory.ManeuverPaths`; ``ipos``/``ivel`` (N, M, 3) the
    intruders' positions (m) and velocities (m/s) at t = 0; ``s``/``v`` the relative positions and
    velocities at the knots per component (N, M, P, K); ``t_flat`` the knot times (s) flat; ``tables`` the
    per-path lookups (encounter ``n``, path ``p``, flat ``nm``, ``acc_h``, ``acc_v``, ``jerk``, ``kink``);
    ``vwin`` the per-path vertical windows (or None) and ``vwin_on`` which flat paths have one (None: all);
    ``exits`` whether last exits are searched; ``compiled`` / ``fused`` the compiled pieces and the fused
    loop (False: the numpy reference).

    What the resolution decides for several pieces at once -- a bisection's number of halvings, a split's
    number of parts, the clip sampling count, whether the vertical error bound is used -- is decided per
    encounter (``tables["n"]``), from that encounter's pieces alone: each encounter's intervals are those of
    a call of its own, whatever else shares the call.
    """

    def __init__(self, paths, ipos: np.ndarray, ivel: np.ndarray, s, v, t_flat: np.ndarray, tables: dict,
                 vwin, exits: bool, compiled: bool = True, fused: bool = True, vwin_on=None):
        self.paths, self.ipos, self.ivel, self.s, self.v = paths, ipos, ivel, s, v
        self.t_flat, self.tables, self.vwin, self.exits = t_flat, tables, vwin, exits
        self.vwin_on = vwin_on
        self.compiled, self.fused = compiled, fused
        self._ipv = None  # intruder position and velocity per flat (n, m), (N * M, 6)
        self._intr_flat = None  # intruder position / velocity components, flat (N * M)

    def pieces(self, flat_seg):
        """:func:`piece_index` of segments ``flat_seg`` of these paths."""
        return piece_index(flat_seg, self.s[0].shape[-1], self.t_flat)

    def _kin_rows(self, path):
        """``(state kernel, bisection kernel, their leading arguments)`` for flat paths ``path``, or None when
        the paths' motion is not given as data or the evaluator runs the numpy reference."""
        kin = self.paths.kin
        if not self.compiled or kin is None:
            return None
        tab = self.tables
        if self._ipv is None:  # intruder position and velocity per flat (n, m), (N * M, 6)
            self._ipv = np.concatenate([self.ipos, self.ivel], axis=-1).reshape(-1, 6)
        n, ipv = tab["n"][path], self._ipv[tab["nm"][path]]
        k = kernels.get_unfused()
        if kin[0] == "axis":
            return k.rel_states_into, k.bisect_into, (kin[1], kin[2], kin[3][n, tab["p"][path]], ipv)
        return k.command_rel_states_into, k.command_bisect_into, (kin[1][n], kin[2][n], *kin[3:], ipv)

    def _mover(self, path):
        """``f(t)``: the true relative state (6 component arrays) of flat paths ``path`` at times ``t``."""
        rows = self._kin_rows(path)
        if rows is not None:
            def f_compiled(t):
                out = np.empty((6, path.size))
                rows[0](*rows[2], as_vector(t, path.size), out)
                return tuple(out)
            return f_compiled
        tab = self.tables
        own = self.paths.state_at(tab["n"][path], tab["p"][path])
        nm = tab["nm"][path]
        if self._intr_flat is None:  # intruder position / velocity components, flat (N * M)
            self._intr_flat = [np.ascontiguousarray(a[..., i]).reshape(-1) for a in (self.ipos, self.ivel) for i in range(3)]
        ipx, ipy, ipz, ivx, ivy, ivz = (a[nm] for a in self._intr_flat)

        def f(t):
            ox, oy, oz, ovx, ovy, ovz = own(t)
            return ox - (ipx + t * ivx), oy - (ipy + t * ivy), oz - (ipz + t * ivz), ovx - ivx, ovy - ivy, ovz - ivz
        return f

    def _state(self, path, t):
        """True relative state (6 component arrays) of flat paths ``path`` at times ``t``."""
        return self._mover(path)(t)

    def _group(self, path) -> np.ndarray:
        """The encounter (index into this evaluation's N) of each flat path ``path``: the rows whose batch-wide
        choices are made together (each encounter's are what a call of its own makes)."""
        return self.tables["n"][path]

    def _halvings(self, path, lo, hi, lo_in):
        """Per row: ``(steps, n_in, n_out, mixed)`` of :meth:`_bisect`, each encounter's from its own rows: the
        halvings of an entry (exit) from the widest entry (exit) bracket of the encounter, and ``mixed`` when
        the encounter bisects both kinds with different counts."""
        g = self._group(path)
        steps, n_in, n_out = (np.zeros(lo.size, np.int64) for _ in range(3))
        mixed = np.zeros(lo.size, bool)
        for e in np.unique(g):
            sel = g == e
            w, flag = hi[sel] - lo[sel], lo_in[sel]

            def count(mask, dt):
                return int(np.ceil(np.log2(max(np.max(w[mask], initial=0.0), dt) / dt)))
            a, b = count(~flag, BISECT_DT_IN), count(flag, BISECT_DT_OUT)
            n_in[sel], n_out[sel], steps[sel] = a, b, max(a, b)
            mixed[sel] = a != b and flag.any() and not flag.all()
        return steps, n_in, n_out, mixed

    def _bisect(self, th, path, lo, hi, lo_in):
        """Bracket ``(lo, hi)`` (s) of a crossing of the violation boundary on the true path between times
        ``lo`` and ``hi`` (the predicate is ``lo_in`` at ``lo`` and the opposite at ``hi``; bool or array), at
        most BISECT_DT_IN (an entry) or BISECT_DT_OUT (an exit) wide. The number of halvings is the
        encounter's (:meth:`_halvings`)."""
        lo, hi = lo.copy(), hi.copy()
        lo_in = np.broadcast_to(np.asarray(lo_in, bool), lo.shape)
        steps, n_in, n_out, mixed = self._halvings(path, lo, hi, lo_in)
        rows = self._kin_rows(path)
        if rows is not None:
            D = float(th.dthr)
            rows[1](*rows[2], lo, hi, lo_in, steps, n_in, n_out, mixed,
                    (D * D, float(th.tthr), float(th.zthr), float(th.tcoa)))
            return lo, hi
        f = self._mover(path)
        own = np.where(mixed, np.where(lo_in, n_out, n_in), steps)  # the halvings that may move each bracket
        for k in range(int(steps.max()) if lo.size else 0):
            mid = 0.5 * (lo + hi)
            same = wcv_soa(*f(mid), th) == lo_in
            live = k < own
            lo = np.where(same & live, mid, lo)
            hi = np.where(~same & live, mid, hi)
        return lo, hi

    def _any_v(self, pth) -> np.ndarray:
        """Per row: does any row of its encounter among ``pth`` have a vertical acceleration (``np.any`` of a
        call of its own: whether the vertical error bound is used)."""
        g = self._group(pth)
        any_g = np.zeros(self.s[0].shape[0], bool)
        any_g[g[self.tables["acc_v"][pth] != 0]] = True
        return any_g[g]

    def _per_encounter_max(self, pth, x) -> np.ndarray:
        """Per row: ``np.max`` of ``x`` over the rows of its encounter (nan wins)."""
        g = self._group(pth)
        out = np.full(self.s[0].shape[0], -np.inf)
        np.maximum.at(out, g, x)
        return out[g]

    def resolve(self, flat_seg, th, seg_in, seg_out) -> None:
        """Undecided segments on the true path (module docstring); updates the flat ``seg_in``/``seg_out``.
        One compiled pass (:func:`daa_sil.daa.kernels.resolve.resolve_into`) when the paths' motion is
        given as data; else, and as its test oracle, :meth:`resolve_reference`."""
        kin = self.paths.kin
        if not self.compiled or kin is None or not self.fused:
            self.resolve_reference(flat_seg, th, seg_in, seg_out)
            return
        _, m, p, k = self.s[0].shape
        path, ka = segment_knots(flat_seg, k)
        tab = self.tables
        if self._ipv is None:
            self._ipv = np.concatenate([self.ipos, self.ivel], axis=-1).reshape(-1, 6)
        jerk, kink = tab["jerk"], tab["kink"]
        resolve_segments(kin, self._ipv, m, p, path, tuple(c.reshape(-1) for c in self.s),
                         tuple(c.reshape(-1) for c in self.v), self.t_flat, flat_seg, ka, tab["acc_h"][path],
                         tab["acc_v"][path], None if jerk is None else jerk[path],
                         None if kink is None else kink[path],
                         None if self.vwin is None else (self.vwin[0].reshape(-1)[path], self.vwin[1].reshape(-1)[path],
                                                         None if self.vwin_on is None else self.vwin_on[path]),
                         self.exits, th, seg_in, seg_out)

    def resolve_reference(self, flat_seg, th, seg_in, seg_out) -> None:
        """:meth:`resolve` in numpy, one depth of pieces at a time.

        The predicate is exact at both ends (true states). Both violate: first entry at the start, last
        exit at the end. One violates: the boundary is found by bisection on the true path and the other
        side is certified CLEAR. Neither violates (a possible clip inside), or the certificate fails: the
        piece is split into parts (each with exact end flags) and examined again; a both-clear part as
        short as V_TOL / P_TOL allow is sampled every CLIP_DT for a clip of the volume (:meth:`_clip`).
        """
        path, ka, t0, h = self.pieces(flat_seg)
        s = [c.reshape(-1) for c in self.s]
        v = [c.reshape(-1) for c in self.v]
        sa, sb = [c[ka] for c in s], [c[ka + 1] for c in s]
        va, vb = [c[ka] for c in v], [c[ka + 1] for c in v]
        f0, f1 = wcv_soa(*sa, *va, th), wcv_soa(*sb, *vb, th)
        pieces = (flat_seg, path, t0, t0 + h, sa, sb, f0, f1, va[:2], vb[:2])
        tab = self.tables
        for depth in range(MAX_DEPTH):
            sid, pth, ta, tb, pa, pb, fa, fb, ua, ub = pieces
            if not sid.size:
                return
            both = fa & fb
            if both.any():
                _update(seg_in, seg_out, sid[both], ta[both], tb[both])
            split = np.zeros(sid.size, bool)
            last = depth == MAX_DEPTH - 1
            settled = ((tb - ta) <= settle_time(tab["acc_h"][pth], tab["acc_v"][pth]) * (1.0 + 1e-9)) | last
            cross = np.flatnonzero(fa != fb)  # entries (start clear, end violating) and exits (start violating)
            if cross.size and not self.exits:  # an exit: first entry at the start; the last exit is not needed
                ex = cross[fa[cross]]
                _update(seg_in, seg_out, sid[ex], ta[ex], tb[ex])
                cross = cross[fb[cross]]
            if cross.size:
                entry = fb[cross]
                lo, hi = self._bisect(th, pth[cross], ta[cross], tb[cross], lo_in=~entry)
                # certify that the other side of the crossing is clear: before an entry, after an exit
                mid_state = self._state(pth[cross], np.where(entry, lo, hi))
                c_a, c_b = np.where(entry, ta[cross], hi), np.where(entry, lo, tb[cross])
                p_a = [np.where(entry, pa[c][cross], mid_state[c]) for c in range(3)]
                p_b = [np.where(entry, mid_state[c], pb[c][cross]) for c in range(3)]
                ok = (self._classify_part(th, pth[cross], c_a, c_b, p_a, p_b) == CLEAR) | settled[cross]
                t_cross = 0.5 * (lo + hi)
                good, e, tc = cross[ok], entry[ok], t_cross[ok]
                _update(seg_in, seg_out, sid[good], np.where(e, tc, ta[good]), np.where(e, tb[good], tc))
                split[cross[~ok]] = True
            j = np.flatnonzero(~fa & ~fb)  # both ends clear: a clip may lie inside unless certified clear
            if j.size and depth > 0:  # (at depth 0 these are the segments the first-order test left undecided)
                code = self._classify_part(th, pth[j], ta[j], tb[j], [c[j] for c in pa], [c[j] for c in pb])
                j = j[code != CLEAR]
            if j.size and tab["jerk"] is not None:  # the tighter second-order certificate (true end velocities)
                j = j[~self._clear2(th, pth[j], ta[j], tb[j], [c[j] for c in pa], [c[j] for c in pb],
                                    [c[j] for c in ua], [c[j] for c in ub])]
            if j.size:
                final = j[settled[j]]
                if final.size:
                    self._clip(th, sid[final], pth[final], ta[final], tb[final],
                               [c[final] for c in pa], [c[final] for c in pb], seg_in, seg_out)
                split[j[~settled[j]]] = True
            idx = np.flatnonzero(split)
            if not idx.size:
                return
            pieces = self._split(th, *(a[idx] for a in (sid, pth, ta, tb)), [c[idx] for c in pa], [c[idx] for c in pb],
                                 fa[idx], fb[idx], [c[idx] for c in ua], [c[idx] for c in ub])

    def _classify_part(self, th, pth, ta, tb, pa, pb) -> np.ndarray:
        tab = self.tables
        h = tb - ta
        a_h, a_v = tab["acc_h"][pth], tab["acc_v"][pth]
        e_z = np.where(self._any_v(pth), a_v * h * h * 0.125, 0.0)
        args = (*pa, *pb, h, th, a_h * h * h * 0.125, a_h * h * 0.5, e_z)
        if self.vwin is None:
            return classify_pieces(*args)
        vlo, vhi = self.vwin[0].reshape(-1)[pth], self.vwin[1].reshape(-1)[pth]
        code = classify_pieces(*args, (np.maximum(vlo, ta) - ta, np.minimum(vhi, tb) - ta))
        if self.vwin_on is None:
            return code
        on = self.vwin_on[pth]  # (a path whose vertical speed changes has no window: its own chord's)
        return code if on.all() else np.where(on, code, classify_pieces(*args))

    def _clear2(self, th, pth, ta, tb, pa, pb, ua, ub) -> np.ndarray:
        """Second-order CLEAR certificate of pieces (see :func:`clear_second_order`)."""
        tab = self.tables
        h = tb - ta
        a_h, a_v, jerk = tab["acc_h"][pth], tab["acc_v"][pth], tab["jerk"][pth]
        e_v = jerk * h * h * 0.125
        if tab["kink"] is not None:
            kt = tab["kink"][pth]
            across = (kt > ta) & (kt < tb) if kt.ndim == 1 else ((kt > ta[:, None]) & (kt < tb[:, None])).any(axis=-1)
            e_v = e_v + np.where(across, a_h * h * 0.5, 0.0)
        e_z = np.where(self._any_v(pth), a_v * h * h * 0.125, 0.0)
        return clear_second_order(*pa, *pb, *ua, *ub, h, th, a_h * h * h * 0.125, e_v, e_z)

    def _split(self, th, sid, pth, ta, tb, pa, pb, fa, fb, ua, ub):
        """Split pieces into the fewest equal parts that settle (at least 2, at most MAX_SPLIT; the count is
        the encounter's, from its longest piece), with exact states and flags at the new ends."""
        tab = self.tables
        settle = settle_time(tab["acc_h"][pth], tab["acc_v"][pth])
        ratio = self._per_encounter_max(pth, (tb - ta) / settle)
        q = np.minimum(MAX_SPLIT, np.maximum(2, np.ceil(ratio - 1e-9))).astype(np.int64)  # (nan: 2, as min/max)
        q = np.where(np.isnan(ratio), 2, q)
        L = sid.size
        inner = q - 1  # new ends inside each piece
        rep = np.repeat(np.arange(L), inner)
        k = np.arange(rep.size) - np.repeat(np.cumsum(inner) - inner, inner) + 1  # 1 .. q - 1
        ts = ta[rep] + (tb - ta)[rep] * (k / q[rep])
        st = self._state(pth[rep], ts)
        flag = wcv_soa(*st, th)
        # every piece's q + 1 ends in a row: start, the inner ends, end
        first = np.cumsum(q + 1) - (q + 1)
        slot = first[rep] + k
        last = first + q

        def ends(a0, inner_vals, a1):
            out = np.empty(int((q + 1).sum()), np.asarray(a0).dtype)
            out[first], out[slot], out[last] = a0, inner_vals, a1
            return out
        times = ends(ta, ts, tb)
        pos = [ends(pa[c], st[c], pb[c]) for c in range(3)]
        flags = ends(fa, flag, fb)
        vel = [ends(ua[c], st[3 + c], ub[c]) for c in range(2)]
        start = np.ones(times.size, bool)
        start[last] = False
        stop = np.ones(times.size, bool)
        stop[first] = False
        rp = lambda a: np.repeat(a, q)  # noqa: E731
        return (rp(sid), rp(pth), times[start], times[stop], [c[start] for c in pos], [c[stop] for c in pos],
                flags[start], flags[stop], [c[start] for c in vel], [c[stop] for c in vel])

    def _clip(self, th, sid, pth, ta, tb, pa, pb, seg_in, seg_out) -> None:
        """Short pieces whose ends are clear but which are not certified clear (a clip of the volume may
        lie inside): the true predicate sampled every CLIP_DT (the sample count is the encounter's, from its
        longest piece), and around the first and last violating samples the entry and exit found by
        bisection on the true path."""
        h = tb - ta
        with np.errstate(invalid="ignore"):
            qf = np.ceil(self._per_encounter_max(pth, h) / CLIP_DT - 1e-9)
        rows_all, t_first, t_last, before, after = [], [], [], [], []
        for qv in np.unique(qf[qf >= 1]):  # (each encounter's pieces share one count)
            q = int(qv)
            sel = np.flatnonzero(qf == qv)
            frac = (np.arange(q) + 0.5) / q
            ts = ta[sel, None] + h[sel, None] * frac[None, :]  # (L, q)
            L = sel.size
            hit = wcv_soa(*self._state(np.repeat(pth[sel], q), ts.ravel()), th).reshape(L, q)
            rows = np.flatnonzero(hit.any(axis=1))
            if not rows.size:
                continue
            first = np.argmax(hit[rows], axis=1)
            last = q - 1 - np.argmax(hit[rows, ::-1], axis=1)
            rows_all.append(sel[rows])
            t_first.append(ts[rows, first])
            t_last.append(ts[rows, last])
            before.append(np.where(first > 0, ts[rows, np.maximum(first - 1, 0)], ta[sel[rows]]))
            after.append(np.where(last < q - 1, ts[rows, np.minimum(last + 1, q - 1)], tb[sel[rows]]))
        if not rows_all:
            return
        rows = np.concatenate(rows_all)
        order = np.argsort(rows, kind="stable")  # (the pieces' order, as one batch)
        rows = rows[order]
        cat = lambda parts: np.concatenate(parts)[order]  # noqa: E731
        t_first, t_last, before, after = cat(t_first), cat(t_last), cat(before), cat(after)
        l1, h1 = self._bisect(th, pth[rows], before, t_first, lo_in=False)
        l2, h2 = self._bisect(th, pth[rows], t_last, after, lo_in=True)
        _update(seg_in, seg_out, sid[rows], 0.5 * (l1 + h1), 0.5 * (l2 + h2))


def _update(seg_in, seg_out, sid, t_in, t_out) -> None:
    """seg_in[sid] = min(seg_in[sid], t_in), seg_out[sid] = max(...) (repeated ids allowed)."""
    np.minimum.at(seg_in, sid, t_in)
    np.maximum.at(seg_out, sid, t_out)


__all__ = ["UndecidedPieces", "segment_knots", "piece_index", "resolve_segments", "bisect_thresholds",
           "MAX_SPLIT", "BISECT_DT_IN", "BISECT_DT_OUT", "CLIP_DT", "MAX_DEPTH"]
