"""Recovery bands: when every candidate of an axis conflicts, the candidates that leave the conflict
earliest (``earliest_exit``) or, DAIDALUS-style, those clear of a shrinking cylinder down to the
NMAC volume (``cylinder``). The rules are stated in docs/daa.md."""

from __future__ import annotations

import numpy as np

from daa_sil.daa.config import (
    DaaConfig,
)
from daa_sil.daa.trajectory import ManeuverPaths, PathConflicts, PathEvaluator
from daa_sil.geometry.kinematics import AircraftState
from daa_sil.geometry.thresholds import Thresholds


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
                 cfg: DaaConfig, order, runs):
        self.paths, self.intr, self.cfg, self.order, self.runs = paths, intr, cfg, order, runs
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
        cyl = PathEvaluator(self.paths.subset(rows), self.intr[rows], self.cfg.lookahead_s).evaluate(_cylinder(h, v))
        pre_in = cyl.prefix()[0]
        red_only = (pre_in < self.window[rows]) | (cyl.tail_in < np.minimum(cyl.tail_out, self.window[rows]))
        return pre_in, cyl.tail_in, cyl.tail_out, red_only

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
                rt = np.where(green_p <= L, np.minimum(L, green_p + cfg.recovery_stability_s), red_p)
                g = self._at_pivot(sr, cs, rt)
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
