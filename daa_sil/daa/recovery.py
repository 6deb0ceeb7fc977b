"""Recovery bands: when every candidate of an axis conflicts, the candidates that leave the conflict
earliest (``earliest_exit``) or, DAIDALUS-style, those clear of a shrinking cylinder down to the
NMAC volume (``cylinder``). The rules are stated in docs/daa.md."""

from __future__ import annotations

import numpy as np

from daa_sil.daa import kernels
from daa_sil.daa.band_regions import axis_path_conflicts
from daa_sil.daa.scratch import scratch
from daa_sil.daa.band_types import AxisBands
from daa_sil.daa.config import AXIS_HORIZONTAL, DaaConfig
from daa_sil.daa.trajectory import ManeuverPaths, PathConflicts, PathEvaluator
from daa_sil.geometry.kinematics import AircraftState
from daa_sil.geometry.thresholds import Thresholds


#: False: the bisection of each cylinder's recovery time in numpy (``CylinderRecovery._at_pivot``, the oracle of
#: the compiled ``kernels.recovery.pivot_search_into``)
COMPILED = True
#: a placeholder for the flags a call does not read
_NO_FLAGS = np.zeros((1, 1), bool)


def drop_isolated(green: np.ndarray) -> np.ndarray:
    """``green`` (N, K) without isolated candidates (a run of one is not a band; DAIDALUS grid)."""
    left = np.zeros_like(green)
    right = np.zeros_like(green)
    left[:, 1:] = green[:, :-1]
    right[:, :-1] = green[:, 1:]
    return green & (left | right)


def _cylinder(h: float, v: float) -> Thresholds:
    return Thresholds(name=f"cylinder {h:.1f} m / {v:.1f} m", dthr=h, zthr=v, tthr=0.0, tcoa=0.0)


class CylinderRecovery:
    """DAIDALUS's shrinking-cylinder recovery search for the rows of one axis that saturate (module doc).

    ``paths``/``intr``: the saturated rows' maneuver paths and intruders; ``corrective``: their
    corrective-volume intervals; ``listed`` (R, M): the intruders the MID bands consider;
    ``horizon`` (R, M): their time horizons (the lookahead for conflict aircraft, the alerting time for
    peripheral ones). Each cylinder is evaluated only for the rows still searching.
    """

    def __init__(self, paths: ManeuverPaths, intr: AircraftState, corrective: PathConflicts, listed, horizon,
                 cfg: DaaConfig, order, runs, shape: "tuple[int, int] | None" = None, fused: bool = False):
        self.paths, self.intr, self.cfg, self.order, self.runs = paths, intr, cfg, order, runs
        self.shape = shape  #: (j_lo, j_hi) of ``order`` (the compiled bisection's column order)
        #: the cylinders evaluated in one pass per path (``band_regions.axis_path_conflicts``; False: the evaluator)
        self.fused = fused and paths.kin is not None and paths.kin[0] == "axis"
        L = cfg.lookahead_s
        shape = corrective.tail_in.shape
        self.tk = np.broadcast_to(corrective.t, shape)
        self.horizon = horizon[:, :, None, None]  # (R, M, 1, 1) aircraft time horizon
        self.window = np.minimum(L, self.horizon + self.tk)  # conflict-detector window end per candidate
        self.listed = listed[:, :, None, None]
        self.c_pre_out = corrective.prefix()[1]
        self.c_in, self.c_out = corrective.tail_in, corrective.tail_out

    def _green(self, red_i, rows) -> np.ndarray:
        red = np.any(red_i & self.listed[rows], axis=1)  # (r, 2, J+1)
        return self.runs(~self.order(red))

    def _cylinder(self, rows, h: float, v: float):
        """The (h, v) cylinder's first entries on the maneuvers, its tails, and 'red as the conflict
        detector over [0, window]' for rows ``rows``."""
        cyl = self._conflicts(rows, _cylinder(h, v))
        pre_in = cyl.prefix_in()
        red_only = (pre_in < self.window[rows]) | (cyl.tail_in < np.minimum(cyl.tail_out, self.window[rows]))
        return pre_in, cyl.tail_in, cyl.tail_out, red_only

    def _conflicts(self, rows, th: Thresholds) -> PathConflicts:
        """The intervals of volume ``th`` of the paths of rows ``rows`` over the lookahead."""
        paths, L = self.paths.subset(rows), self.cfg.lookahead_s
        if not self.fused:
            return PathEvaluator(paths, self.intr[rows], L).evaluate(th)
        n, m = rows.size, self.intr.shape[1]
        knots = paths.axis_times().shape[0]
        ti, to, si, so = axis_path_conflicts(paths, self.intr[rows], th, L, np.full(n, knots - 1, np.int64))
        shape = (n, m, 2, knots)
        seg = shape[:3] + (knots - 1,)
        return PathConflicts(si.reshape(seg), so.reshape(seg), ti.reshape(shape), to.reshape(shape),
                             np.broadcast_to(paths.axis_times(), shape), L)

    def _at_pivot(self, rows, cyl, pivot) -> np.ndarray:
        """Green where the candidate avoids the cylinder on [0, B] and the corrective volume after B."""
        pre_in, t_in, t_out, red_only = cyl
        B = pivot[:, None, None, None]
        tk, window = self.tk[rows], self.window[rows]
        red = (self.c_pre_out[rows] > B) | (pre_in < B)
        red |= np.maximum(self.c_in[rows], B) < np.minimum(self.c_out[rows], window)
        red |= (tk < B) & (t_in < np.minimum(t_out, B))
        red = np.where(B > self.horizon[rows], red_only, red)  # past the aircraft's horizon: the cylinder only
        return self._green(red, rows)

    def _search_reference(self, sr, cs) -> tuple[np.ndarray, np.ndarray]:
        """``(recovery time (s), green (len(sr), K))`` of rows ``sr`` with their cylinder ``cs``: bisect (to 0.5 s)
        the earliest time B at which some candidate avoids the cylinder on [0, B] and the corrective volume
        after B; the recovery time is B + the stability time (at most the lookahead)."""
        L = self.cfg.lookahead_s
        red_p = np.zeros(sr.size)
        green_p = np.full(sr.size, L + 1.0)
        pivot = np.full(sr.size, L)
        going = green_p - red_p > 0.5
        while going.any():
            solid = ~self._at_pivot(sr, cs, pivot).any(axis=1)
            red_p = np.where(going & solid, pivot, red_p)
            green_p = np.where(going & ~solid, pivot, green_p)
            pivot = np.where(going, 0.5 * (red_p + green_p), pivot)
            going = green_p - red_p > 0.5
        rt = np.where(green_p <= L, np.minimum(L, green_p + self.cfg.recovery_stability_s), red_p)
        return rt, self._at_pivot(sr, cs, rt)

    def _search(self, sr, cs) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`_search_reference` in one compiled pass (``kernels.recovery.pivot_search_into``)."""
        pre_in, t_in, t_out, red_only = cs
        j_lo, j_hi = self.shape
        rt, green = np.empty(sr.size), np.empty((sr.size, j_lo + j_hi + 1), bool)
        corr = (self.c_pre_out, self.c_in, self.c_out, self.tk, self.window)
        kernels.get().pivot_search_into(
            tuple(np.asarray(a, float) for a in corr), np.asarray(sr, np.int64), (pre_in, t_in, t_out),
            np.asarray(red_only, bool), self.horizon[:, :, 0, 0], np.ascontiguousarray(self.listed[:, :, 0, 0]),
            (int(j_lo), int(j_hi)), bool(self.runs is drop_isolated), (float(self.cfg.lookahead_s),
                                                                        float(self.cfg.recovery_stability_s)), rt, green)
        return rt, green

    def run(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(recovery green (R, K), time, nfactor, h, v); rows without recovery have no green candidate
        and time -inf."""
        cfg, th = self.cfg, self.cfg.th
        n_rows = self.listed.shape[0]
        k = self.c_in.shape[2] and self.order(np.zeros((1,) + self.c_in.shape[2:], bool)).shape[1]
        green = np.zeros((n_rows, k), bool)
        r_time = np.full(n_rows, -np.inf)
        nfac = np.zeros(n_rows, np.int16)
        r_h, r_v = np.full(n_rows, -np.inf), np.full(n_rows, -np.inf)
        everyone = np.arange(n_rows)
        nmac = self._cylinder(everyone, th.nmac_h, th.nmac_v)
        active = self._green(nmac[3], everyone).any(axis=1)
        h, v = cfg.recovery_cylinder
        n = 0
        L = cfg.lookahead_s
        while active.any() and (h > th.nmac_h or v > th.nmac_v):
            rows = np.flatnonzero(active)
            cyl = self._cylinder(rows, h, v)
            some = self._green(cyl[3], rows).any(axis=1)
            if some.any():
                sr = rows[some]
                cs = tuple(a[some] for a in cyl)
                rt, g = self._search(sr, cs) if COMPILED and self.shape is not None else self._search_reference(sr, cs)
                ok = g.any(axis=1)
                done = sr[ok]
                green[done], r_time[done], nfac[done], r_h[done], r_v[done] = g[ok], rt[ok], n, h, v
                active[done] = False
                if not cfg.ca_bands:
                    active[sr] = False
            if not cfg.ca_bands:
                active[rows[~some]] = False
            n += 1
            h = max(th.nmac_h, h * (1.0 - cfg.ca_factor))
            v = max(th.nmac_v, v * (1.0 - cfg.ca_factor))
        return green, r_time, nfac, r_h, r_v


def cylinder_search(paths: ManeuverPaths, intr: AircraftState, conflicts: tuple, lists: tuple, cfg: DaaConfig,
                    shape: tuple[int, int]) -> tuple:
    """The cylinder recovery of R rows of one band axis, compiled (``kernels.recovery``'s
    ``cylinder_prepare_into``, ``cylinder_step_into`` per cylinder): the numbers of the evaluator's path of
    :func:`daa_sil.daa.bands.axis_bands` (its regions before the recovery, then :class:`CylinderRecovery`),
    without its arrays. ``paths``/``intr``: the rows' maneuver paths and intruders (R, M), every row with all
    ``shape`` = ``(j_lo, j_hi)`` candidates; ``conflicts``: their paths' corrective-volume conflicts ``(tail_in,
    tail_out, seg_in, seg_out)`` (R, M, 2, J+1) / (R, M, 2, J) (``band_regions.axis_path_conflicts``);
    ``lists`` = ``(near_list, mid_list, alert2)`` (R, M): the conflict lists (with
    ``cfg.horizon_from_maneuver``) or alert level >= 2. Returns ``(g_near, g_mid, recovery green)`` (R, K) and
    ``(recovery time, nfactor, h, v)`` (R,) (nan / -1 / nan / nan for a row that is not saturated)."""
    k = kernels.get()
    r_n, m = intr.shape
    j_lo, j_hi = shape
    n_col = j_lo + j_hi + 1
    tk = paths.axis_times()
    j1 = tk.shape[0]
    tail_in, tail_out, seg_in, seg_out = (np.ascontiguousarray(a, float) for a in conflicts)
    dgrid = bool(cfg.daidalus_grid)
    L = float(cfg.lookahead_s)
    g_near, g_mid = np.empty((r_n, n_col), bool), np.empty((r_n, n_col), bool)
    listed, horizon = np.empty((r_n, m), bool), np.empty((r_n, m))
    c_pre_out, window = np.empty((r_n, m, 2, j1)), np.empty((r_n, m, 2, j1))
    saturated = np.empty(r_n, bool)
    k.cylinder_prepare_into((tail_in.reshape(-1), tail_out.reshape(-1), seg_in.reshape(-1), seg_out.reshape(-1)),
                            bool(cfg.horizon_from_maneuver), tuple(np.asarray(a, bool) for a in lists), tk,
                            (L, float(cfg.alert_time_warning_s), float(cfg.alert_time_corrective_s)),
                            (int(j_lo), int(j_hi)), dgrid, (g_near, g_mid), (listed, horizon), (c_pre_out, window),
                            saturated)
    green = np.zeros((r_n, n_col), bool)
    r_time = np.where(saturated, -np.inf, np.nan)
    nfac = np.where(saturated, 0, -1).astype(np.int16)
    r_h, r_v = r_time.copy(), r_time.copy()
    sat = np.flatnonzero(saturated & (m > 0))
    if not sat.size:
        return (g_near, g_mid, green), (r_time, nfac, r_h, r_v)
    corr = (c_pre_out, tail_in.reshape(r_n, m, 2, j1), tail_out.reshape(r_n, m, 2, j1),
            np.broadcast_to(tk, (r_n, m, 2, j1)), window)
    times = (L, float(cfg.recovery_stability_s))

    def step(rows: np.ndarray, h: float, v: float, search: bool):
        sub_p, sub_i = (paths, intr) if rows.size == r_n else (paths.subset(rows), intr[rows])
        with scratch() as ws:
            ti, to, si, _ = axis_path_conflicts(sub_p, sub_i, _cylinder(h, v), L, np.full(rows.size, j1 - 1, np.int64),
                                                ws.take)
            some, rt, g = np.empty(rows.size, bool), np.empty(rows.size), np.empty((rows.size, n_col), bool)
            k.cylinder_step_into(corr, rows, (ti, to, si), horizon, listed, (int(j_lo), int(j_hi)), dgrid, times,
                                 search, some, rt, g)
        return some, rt, g

    th = cfg.th
    active = np.zeros(r_n, bool)
    active[sat] = step(sat, th.nmac_h, th.nmac_v, False)[0]
    h, v = cfg.recovery_cylinder
    n = 0
    while active.any() and (h > th.nmac_h or v > th.nmac_v):  # (the loop of CylinderRecovery.run)
        rows = np.flatnonzero(active)
        some, rt, g = step(rows, h, v, True)
        if some.any():
            ok = g.any(axis=1)
            done = rows[ok]
            green[done], r_time[done], nfac[done], r_h[done], r_v[done] = g[ok], rt[ok], n, h, v
            active[done] = False
            if not cfg.ca_bands:
                active[rows[some]] = False
        if not cfg.ca_bands:
            active[rows[~some]] = False
        n += 1
        h = max(th.nmac_h, h * (1.0 - cfg.ca_factor))
        v = max(th.nmac_v, v * (1.0 - cfg.ca_factor))
    return (g_near, g_mid, green), (r_time, nfac, r_h, r_v)


def recover_rows(paths: ManeuverPaths, intr: AircraftState, axis: int, cfg: DaaConfig, alert, lists, conf: tuple,
                 fast: np.ndarray, shape: tuple[int, int], ab: AxisBands) -> None:
    """Rows ``fast`` of the cylinder-recovery bands ``ab`` of ``axis`` made as the evaluator's path of
    :func:`daa_sil.daa.bands.axis_bands` makes them, in place: their recovery searched by :func:`cylinder_search`
    from their one-pass conflicts ``conf`` (rows ``fast`` only), then their regions, gap regions and resolutions
    (``kernels.recovery.cylinder_finish_into``); their candidates' values and conflicts are the one-pass
    kernels' (the same numbers). ``paths``/``intr``/``alert``/``lists``: the batch's (N rows); each row of
    ``fast`` has every candidate of the batch, ``shape`` = ``(j_lo, j_hi)``."""
    if cfg.horizon_from_maneuver:
        flags = (lists[0][fast], lists[1][fast], _NO_FLAGS)
    else:
        flags = (_NO_FLAGS, _NO_FLAGS, np.asarray(alert)[fast] >= 2)
    all_rows = fast.size == intr.shape[0]
    sub_p, sub_i = (paths, intr) if all_rows else (paths.subset(fast), intr[fast])
    greens, (rt, nf, hh, vv) = cylinder_search(sub_p, sub_i, conf, flags, cfg, shape)
    gap = ab.gap_region if ab.gap_region is not None else np.empty((0, max(ab.region.shape[1] - 1, 0)), np.int8)
    kernels.get().cylinder_finish_into(
        greens, fast.astype(np.int64), np.asarray(ab.values, float), np.asarray(ab.delta, float),
        np.asarray(ab.t_man, float), (int(shape[0]), axis == AXIS_HORIZONTAL, bool(cfg.daidalus_grid), np.pi - 1e-9),
        ab.region, gap, (ab.res_lo, ab.res_hi), ab.preferred)
    ab.recovery_time[fast], ab.recovery_nfactor[fast], ab.recovery_h[fast], ab.recovery_v[fast] = rt, nf, hh, vv
