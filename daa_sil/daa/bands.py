"""DAIDALUS-style kinematic bands for track, vertical speed and ground speed (batched).

For each axis the candidates lie on a grid anchored at the current value (``config`` module
docstring). Candidate ``k`` on a side is flown kinematically: turn at the turn-rate limit (or
accelerate at the vertical / horizontal limit) until the candidate value is reached after
``k * knot`` s, then straight; intruders fly straight (``daa_spec.md`` §4.2). For each candidate
and intruder the first well-clear violation ``t_in`` over ``[0, lookahead]`` is computed
(:mod:`daa_sil.daa.trajectory`). Regions (``daa_spec.md`` §4.1, §4.3):

* NEAR if ``t_in < alert_time_warning_s`` for some intruder;
* MID if ``t_in < H_i`` for some intruder, with ``H_i = lookahead`` for *conflict aircraft* (alert
  level >= 2 now) and ``alert_time_corrective_s`` for the others (DAIDALUS peripheral aircraft);
* NONE otherwise. FAR (preventive) is not painted (DO-365 maps the preventive level to NONE).
* RECOVERY: when every candidate of an axis is MID or NEAR, the candidates whose first LoWC is
  later than ``sm_horizon_s`` (55 s: they stay safe, SM > 0) are relabelled RECOVERY; if there are
  none, the candidates whose last exit from a conflicting violation is within
  ``recovery_stability_s`` of the earliest one (a simplification of DAIDALUS' shrinking-cylinder
  search: the maneuvers that regain well clear soonest).

Resolutions (``daa_spec.md`` §4.4): when the current value (k = 0) is MID or NEAR, the closest
NONE/RECOVERY candidate on each side (``res_lo`` = left/down/slower, ``res_hi`` = right/up/faster,
nan if none or if the current value is not in conflict); the preferred side is the one reached
sooner (ties: right/up/faster).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..frames import wrap_2pi
from ..kinematics import AircraftState
from .alerting import alert_levels
from .config import (AXIS_HORIZONTAL, AXIS_NAMES, AXIS_SPEED, AXIS_VERTICAL, REGION_MID, REGION_NAMES, REGION_NEAR,
                     REGION_NONE, REGION_RECOVERY, DaaConfig)
from .trajectory import knot_path_conflicts


@dataclass
class AxisBands:
    """Candidates of one axis for N encounters; K candidates ordered from the low side to the high side.

    ``values`` (N, K) absolute (track rad [0, 2pi) / vs m/s / gs m/s); ``delta`` (N, K) signed change
    from the current value (rad or m/s; track: - = left); ``side`` (K,) -1/0/+1; ``t_man`` (N, K) s to
    reach; ``t_in`` (N, K) first LoWC with any intruder over the lookahead (inf = none); ``t_out``
    (N, K) last exit from a conflicting violation; ``region`` (N, K) REGION_* codes; ``res_lo``,
    ``res_hi`` (N,) resolutions (nan = none); ``preferred`` (N,) side -1/0/+1.
    """

    axis: int
    values: np.ndarray
    delta: np.ndarray
    side: np.ndarray
    t_man: np.ndarray
    t_in: np.ndarray
    t_out: np.ndarray
    region: np.ndarray
    res_lo: np.ndarray
    res_hi: np.ndarray
    preferred: np.ndarray

    @property
    def name(self) -> str:
        return AXIS_NAMES[self.axis]

    def intervals(self, i: int = 0) -> list[tuple[float, float, str]]:
        """Bands of encounter ``i`` as ``[(lo, hi, region_name), ...]`` in SI units, low side first.

        Contiguous candidates with the same region are merged; duplicates at a saturated limit
        collapse. Track intervals are in compass radians and may wrap through north.
        """
        vals, reg = self.values[i], self.region[i]
        keep = np.ones(len(vals), bool)
        keep[1:] = ~np.isclose(vals[1:], vals[:-1], rtol=0.0, atol=1e-9)
        vals, reg = vals[keep], reg[keep]
        out: list[tuple[float, float, str]] = []
        start = 0
        for j in range(1, len(vals) + 1):
            if j == len(vals) or reg[j] != reg[start]:
                out.append((float(vals[start]), float(vals[j - 1]), REGION_NAMES[int(reg[start])]))
                start = j
        return out


@dataclass
class Bands:
    """Bands of the three axes plus the alert levels ``(N, M)`` they were computed with."""

    trk: AxisBands
    vs: AxisBands
    gs: AxisBands
    alert: np.ndarray
    preset: str

    def axes(self) -> tuple[AxisBands, AxisBands, AxisBands]:
        return (self.trk, self.vs, self.gs)

    def axis(self, code: int) -> AxisBands:
        return {AXIS_HORIZONTAL: self.trk, AXIS_VERTICAL: self.vs, AXIS_SPEED: self.gs}[code]

    def in_conflict(self) -> np.ndarray:
        """(N,) bool: the current trajectory (k = 0) is in a conflict region (MID or worse)."""
        k0 = np.nonzero(self.trk.side == 0)[0][0]
        r = self.trk.region[:, k0]
        return (r >= REGION_MID) & (r != REGION_RECOVERY) | (r == REGION_RECOVERY)

    def __getitem__(self, idx) -> "Bands":
        def sub(a: AxisBands) -> AxisBands:
            return AxisBands(a.axis, a.values[idx], a.delta[idx], a.side, a.t_man[idx], a.t_in[idx], a.t_out[idx],
                             a.region[idx], a.res_lo[idx], a.res_hi[idx], a.preferred[idx])
        return Bands(sub(self.trk), sub(self.vs), sub(self.gs), self.alert[idx], self.preset)


def _side_order(arr, j_lo: int, j_hi: int):
    """(N, 2, J+1, ...) with path 0 = low side, 1 = high side -> (N, K) low..0..high."""
    lo = arr[:, 0, j_lo:0:-1]
    hi = arr[:, 1, 1:j_hi + 1]
    return np.concatenate([lo, arr[:, 1, :1], hi], axis=1)


def _path_sizes(own: AircraftState, axis: int, cfg: DaaConfig) -> tuple[int, int]:
    """Number of candidates on the low and high side of an axis for this batch (>= 0)."""
    if axis == AXIS_HORIZONTAL:
        j_lo = int(round(cfg.trk_range / cfg.trk_step))
        return j_lo, (j_lo - 1 if np.isclose(cfg.trk_range, np.pi) else j_lo)
    cur, lo, hi, step = ((own.vs, -cfg.max_vs, cfg.max_vs, cfg.vs_step) if axis == AXIS_VERTICAL
                         else (own.gs, cfg.min_gs, cfg.max_gs, cfg.gs_step))
    j_lo = int(np.ceil(np.max(cur - lo, initial=0.0) / step - 1e-9))
    j_hi = int(np.ceil(np.max(hi - cur, initial=0.0) / step - 1e-9))
    return max(j_lo, 0), max(j_hi, 0)


def _axis_paths(own: AircraftState, axis: int, cfg: DaaConfig, j: int
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Ownship on the low-side and high-side maneuver paths at knots 0..j.

    Returns position and velocity ``(N, 2, j+1, 3)``, the axis value ``(N, 2, j+1)`` and knot times
    ``(j+1,)``. Closed forms of :func:`daa_sil.kinematics.advance` for a constant-rate turn (the arc is
    built once in the body frame and rotated per encounter) and for a saturating acceleration.
    """
    sgn = np.array([-1.0, 1.0])[None, :, None]  # low side, high side
    x0, y0, z0 = (a[:, None, None] for a in (own.x, own.y, own.z))
    gs0, trk0, vs0 = (a[:, None, None] for a in (own.gs, own.trk, own.vs))
    st, ct = np.sin(trk0), np.cos(trk0)
    if axis == AXIS_HORIZONTAL:
        knot = cfg.knot_trk
        t = np.arange(j + 1) * knot
        th = cfg.turn_rate * t
        fwd = gs0 / cfg.turn_rate * np.sin(th)  # along the initial track
        lat = gs0 / cfg.turn_rate * (1.0 - np.cos(th))  # toward the turn side
        x = x0 + fwd * st + sgn * lat * ct
        y = y0 + fwd * ct - sgn * lat * st
        z = np.broadcast_to(z0 + vs0 * t, x.shape)
        c, s = np.cos(th), sgn * np.sin(th)
        vx, vy = gs0 * (st * c + ct * s), gs0 * (ct * c - st * s)
        vz = np.broadcast_to(vs0, x.shape)
        value = wrap_2pi(trk0 + sgn * th)
    else:
        vertical = axis == AXIS_VERTICAL
        knot, acc = (cfg.knot_vs, cfg.vertical_accel) if vertical else (cfg.knot_gs, cfg.horizontal_accel)
        lim = np.array([-cfg.max_vs, cfg.max_vs]) if vertical else np.array([cfg.min_gs, cfg.max_gs])
        lim = lim[None, :, None]
        t = np.arange(j + 1) * knot
        v0 = vs0 if vertical else gs0
        t_sat = np.maximum((lim - v0) * sgn / acc, 0.0)
        tc = np.minimum(t, t_sat)
        v_t = v0 + sgn * acc * tc
        dist = v0 * tc + 0.5 * sgn * acc * tc * tc + v_t * (t - tc)
        if vertical:
            x = np.broadcast_to(x0 + gs0 * st * t, v_t.shape)
            y = np.broadcast_to(y0 + gs0 * ct * t, v_t.shape)
            z = z0 + dist
            vx, vy, vz = (np.broadcast_to(a, v_t.shape) for a in (gs0 * st, gs0 * ct, v_t))
        else:
            x, y = x0 + dist * st, y0 + dist * ct
            z = np.broadcast_to(z0 + vs0 * t, v_t.shape)
            vx, vy, vz = v_t * st, v_t * ct, np.broadcast_to(vs0, v_t.shape)
        value = v_t
    pos = np.stack(np.broadcast_arrays(x, y, z), axis=-1)
    vel = np.stack(np.broadcast_arrays(vx, vy, vz), axis=-1)
    return pos, vel, value, t


def _closest(ok, side, want: int, cost):
    """Index of the cheapest ``ok`` candidate with ``side == want`` (k >= 1), and whether one exists."""
    c = np.where(ok & (side == want), cost, np.inf)
    idx = np.argmin(c, axis=-1)
    return idx, np.isfinite(np.take_along_axis(c, idx[:, None], -1)[:, 0])


def axis_bands(own: AircraftState, intr: AircraftState, axis: int, cfg: DaaConfig, alert: np.ndarray,
               sizes: "tuple[int, int] | None" = None) -> AxisBands:
    """Bands of one axis (AXIS_* code) for ownship ``(N,)`` and intruders ``(N, M)``; ``sizes`` = candidates
    per side (default from this batch)."""
    j_lo, j_hi = sizes if sizes is not None else _path_sizes(own, axis, cfg)
    pos, vel, values, t = _axis_paths(own, axis, cfg, max(j_lo, j_hi))
    t_in, t_out = knot_path_conflicts(pos, vel, t, intr, cfg.th, cfg.lookahead_s)
    # per-intruder regions: (N, M, 2, J+1)
    horizon = np.where(alert >= 2, cfg.lookahead_s, cfg.alert_time_corrective_s)[:, :, None, None]
    conflict = t_in < horizon
    near = t_in < cfg.alert_time_warning_s
    region_i = np.where(near, REGION_NEAR, np.where(conflict, REGION_MID, REGION_NONE))
    m = t_in.shape[1]
    region = region_i.max(axis=1) if m else np.zeros((own.shape[0],) + t_in.shape[2:], int)
    t_in_all = t_in.min(axis=1) if m else np.full(region.shape, np.inf)
    t_out_c = np.where(conflict, t_out, -np.inf).max(axis=1) if m else np.full(region.shape, -np.inf)
    cur = {AXIS_HORIZONTAL: own.trk, AXIS_VERTICAL: own.vs, AXIS_SPEED: own.gs}[axis][:, None, None]
    if axis == AXIS_HORIZONTAL:
        rate = cfg.turn_rate
        delta = np.broadcast_to(np.array([[-1.0], [1.0]]) * cfg.turn_rate * t, values.shape)
    else:
        rate = cfg.vertical_accel if axis == AXIS_VERTICAL else cfg.horizontal_accel
        delta = values - cur
    order = lambda a: _side_order(a, j_lo, j_hi)  # noqa: E731
    values, delta = order(values), order(delta)
    region, t_in_all, t_out_c = order(region), order(t_in_all), order(t_out_c)
    side = np.concatenate([-np.ones(j_lo, int), [0], np.ones(j_hi, int)])
    t_man = np.abs(delta) / rate
    # recovery: every candidate in conflict
    saturated = np.all(region >= REGION_MID, axis=1)
    late = t_in_all > cfg.sm_horizon_s  # LoWC only after the SM horizon: still "safe" (SM > 0)
    any_late = late.any(axis=1, keepdims=True)
    best_exit = np.min(t_out_c, axis=1, keepdims=True)
    rec = saturated[:, None] & np.where(any_late, late, t_out_c <= best_exit + cfg.recovery_stability_s)
    region = np.where(rec, REGION_RECOVERY, region).astype(np.int8)
    # resolutions
    k0 = j_lo
    cur_conflict = (region[:, k0] == REGION_MID) | (region[:, k0] == REGION_NEAR)
    ok = (region == REGION_NONE) | (region == REGION_RECOVERY)
    i_lo, f_lo = _closest(ok, side, -1, t_man)
    i_hi, f_hi = _closest(ok, side, +1, t_man)
    f_lo &= cur_conflict
    f_hi &= cur_conflict
    take = lambda a, i: np.take_along_axis(a, i[:, None], -1)[:, 0]  # noqa: E731
    res_lo = np.where(f_lo, take(values, i_lo), np.nan)
    res_hi = np.where(f_hi, take(values, i_hi), np.nan)
    pref = np.where(f_lo & f_hi, np.where(take(t_man, i_hi) <= take(t_man, i_lo), 1, -1),
                    np.where(f_hi, 1, np.where(f_lo, -1, 0))).astype(np.int8)
    return AxisBands(axis, values, delta, side, t_man, t_in_all, t_out_c, region, res_lo, res_hi, pref)


def compute_bands(own: AircraftState, intr: AircraftState, cfg: "DaaConfig | None" = None,
                  alert: "np.ndarray | None" = None) -> Bands:
    """Kinematic track, vertical-speed and ground-speed bands for ownship ``(N,)`` vs intruders ``(N, M)``.

    ``alert`` (N, M) are the current alert levels (computed with :func:`alert_levels` if omitted).
    """
    cfg = cfg or DaaConfig()
    if alert is None:
        alert = alert_levels(own, intr, cfg)
    n = own.shape[0]
    codes = (AXIS_HORIZONTAL, AXIS_VERTICAL, AXIS_SPEED)
    sizes = [_path_sizes(own, a, cfg) for a in codes]
    chunks = []
    for lo in range(0, max(n, 1), CHUNK):
        sl = slice(lo, min(lo + CHUNK, n))
        chunks.append([axis_bands(own[sl], intr[sl], a, cfg, alert[sl], sz) for a, sz in zip(codes, sizes)])
    axes = [chunks[0][k] if len(chunks) == 1 else _concat([c[k] for c in chunks]) for k in range(3)]
    return Bands(*axes, alert=alert, preset=cfg.th.name)


#: encounters per internal chunk (keeps the working arrays cache-sized; results do not depend on it)
CHUNK = 512


def _concat(parts: "list[AxisBands]") -> AxisBands:
    cat = lambda name: np.concatenate([getattr(p, name) for p in parts], axis=0)  # noqa: E731
    p0 = parts[0]
    return AxisBands(p0.axis, cat("values"), cat("delta"), p0.side, cat("t_man"), cat("t_in"), cat("t_out"),
                     cat("region"), cat("res_lo"), cat("res_hi"), cat("preferred"))
