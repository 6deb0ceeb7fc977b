"""DAIDALUS-style kinematic bands for track, vertical speed and ground speed (batched).

For each axis the candidates lie on a grid anchored at the current value (:mod:`daa_sil.daa.config`).
Candidate ``k`` on a side is flown kinematically: turn at the turn-rate limit (or accelerate at the
vertical / horizontal limit) until the candidate value is reached after ``t_k = k * knot`` s, then
straight; intruders fly straight. For each candidate and intruder the first well-clear violation
``t_in`` over ``[0, lookahead]`` is computed on the true trajectory (:mod:`daa_sil.daa.trajectory`).
``docs/daa.md`` states every rule below in full.

Regions. A candidate is NEAR (warning) if it is red for the NEAR level of some intruder, else MID
(corrective) if red for the MID level of some intruder, else NONE (FAR, the preventive level, is not
painted: DO-365 maps it to no band). "Red for a level" depends on ``cfg.horizon_from_maneuver``:

* ``False`` (``do365``, ``paper``; DAIDALUS v1 / v2.0.1): MID if ``t_in < lookahead`` for an intruder
  at alert level >= 2 and ``t_in < alert_time_corrective_s`` for the others; NEAR if
  ``t_in < alert_time_warning_s``, horizons counted from now.
* ``True`` (``daidalus``; DAIDALUS v2.0.4 with ``bands_add_time_to_maneuver = false``): per level, an
  intruder whose straight-line conflict starts within that level's alerting time (a *conflict
  aircraft*) is red when ``t_in < lookahead``; any other intruder when ``t_in < alerting time + t_k``.

With ``cfg.daidalus_grid`` a conflict-free run of a single candidate is not a band (DAIDALUS builds
bands as intervals between candidates and drops zero-width ones).

Recovery (every candidate of an axis MID or worse), ``cfg.recovery``:

* ``"earliest_exit"`` (``do365``, ``paper``): the candidates whose first LoWC is later than
  ``sm_horizon_s`` (they stay safe, SM > 0) are relabelled RECOVERY; if there are none, those whose last
  exit from a conflicting violation is within ``recovery_stability_s`` of the earliest one.
* ``"cylinder"`` (``daidalus``): DAIDALUS's search. If every candidate hits the NMAC cylinder, the axis
  is saturated. Otherwise, starting from the (``min_horizontal_recovery``, ``min_vertical_recovery``)
  cylinder: bisect (0.5 s) for the earliest time ``t_r`` at which some candidate avoids the cylinder on
  ``[0, t_r]`` and the corrective volume after ``t_r``; the RECOVERY band is the set of candidates that do
  so for ``t_r + recovery_stability_s``. If none does, shrink the cylinder by ``1 - ca_factor`` (never
  below NMAC, ``ca_bands``) and repeat. ``recovery_nfactor`` counts the shrinks.

Resolutions: when the current value (k = 0) is MID or NEAR, the first NONE/RECOVERY candidate scanning
away from it on each side (``res_lo`` = left/down/slower, ``res_hi`` = right/up/faster), ``-inf``/``+inf``
when a side has none, ``nan`` when the current value is not in conflict (DAIDALUS conventions). The
preferred side is the one reached sooner; equal distances (up to rounding) go right/up/faster.

Which preset gets which rule (issue 15), and why:

* the exact tie-break -- every preset: "faster / right / up wins ties" was the documented rule, and
  comparing floating-point maneuver times broke it at random;
* the v2.0.4 band horizons, the shrinking-cylinder recovery and the DAIDALUS grid -- ``daidalus``
  only: they are DAIDALUS's semantics, while ``do365`` and ``paper`` keep the v1-style horizons and the
  earliest-exit recovery the paper study was built and validated with (both are defensible readings of
  DO-365; changing them would change the study's numbers, not fix an error);
* the true trajectory (:mod:`daa_sil.daa.trajectory`) -- every preset (a correctness fix).
"""

from __future__ import annotations

from dataclasses import fields

import numpy as np

from daa_sil.geometry.kinematics import TWO_PI, AircraftState
from .alerting import alert_levels, conflict_lists
from .config import (AXIS_HORIZONTAL, AXIS_SPEED, AXIS_VERTICAL, REGION_MID, REGION_NEAR, REGION_NONE, REGION_RECOVERY,
                     DaaConfig)
from .trajectory import PathConflicts, PathEvaluator
from daa_sil.daa.recovery import CylinderRecovery, drop_isolated, recover_rows
from daa_sil.daa.axis_paths import maneuver_paths, candidate_counts, row_counts, speed_limits
from daa_sil.daa.band_regions import axis_conflict_regions, axis_path_conflicts, axis_regions, regions_of_conflicts
from daa_sil.daa.scratch import scratch
from daa_sil.daa.band_types import AxisBands, Bands, column_sides, gap_regions  # (the types, defined apart)

#: False: every axis in numpy (the oracle of :func:`daa_sil.daa.band_regions.axis_regions`)
COMPILED = True
#: False (with COMPILED): the conflicts through :class:`PathEvaluator` and its (N, M, 2, J+1) arrays, then
#: :func:`daa_sil.daa.band_regions.axis_regions` (the oracle of :func:`~daa_sil.daa.band_regions.axis_conflict_regions`)
FUSED = True
#: False (with COMPILED and FUSED): the cylinder recovery's rows made again on the evaluator's path (the
#: oracle of :func:`daa_sil.daa.recovery.cylinder_search` and ``kernels.recovery.cylinder_finish_into``)
CYLINDER_COMPILED = True


def _side_order(arr, j_lo: int, j_hi: int):
    """(N, 2, J+1, ...) with path 0 = low side, 1 = high side -> (N, K) low..0..high."""
    lo = arr[:, 0, j_lo:0:-1]
    hi = arr[:, 1, 1:j_hi + 1]
    return np.concatenate([lo, arr[:, 1, :1], hi], axis=1)


def _over_intruders(a: np.ndarray, reduce) -> np.ndarray:
    """``reduce(a, axis=1)`` (a view for one intruder)."""
    return a[:, 0] if a.shape[1] == 1 else reduce(a, axis=1)


def _candidate_values(own: AircraftState, axis: int, cfg: DaaConfig, sgn: np.ndarray, t: np.ndarray):
    """Values ``(N, K)``, signed changes ``(N, K)`` and the axis rate of the candidates reached on side
    ``sgn`` (K,) after ``t`` (K,) s of maneuvering (the same numbers as the paths' axis values)."""
    n = own.shape[0]
    if axis == AXIS_HORIZONTAL:
        th = sgn * (cfg.turn_rate * t)
        value = own.trk[:, None] + th[None, :]
        value = np.where(value < 0.0, value + TWO_PI, np.where(value >= TWO_PI, value - TWO_PI, value))
        return value, np.repeat(th[None, :], n, axis=0), cfg.turn_rate
    vertical = axis == AXIS_VERTICAL
    acc, lim = speed_limits(vertical, cfg, sgn)
    v0 = (own.vs if vertical else own.gs)[:, None]
    tc = np.minimum(t, np.maximum((lim - v0) * sgn / acc, 0.0))
    value = v0 + sgn * acc * tc
    return value, value - v0, acc


def _first_on_side(ok, side, want: int, k0: int):
    """Index of the first ``ok`` candidate scanning away from column ``k0`` toward side ``want``, and
    whether one exists (candidates ordered low side, k0, high side)."""
    part = ok[:, k0 + 1:] if want > 0 else ok[:, k0 - 1::-1] if k0 > 0 else ok[:, :0]
    if part.shape[1] == 0:
        return np.full(ok.shape[0], k0), np.zeros(ok.shape[0], bool)
    j = np.argmax(part, axis=1)
    found = part[np.arange(ok.shape[0]), j]
    return (k0 + 1 + j) if want > 0 else (k0 - 1 - j), found


def axis_bands(own: AircraftState, intr: AircraftState, axis: int, cfg: DaaConfig, alert: np.ndarray,
               sizes: "tuple[int, int] | None" = None,
               lists: "tuple[np.ndarray, np.ndarray] | None" = None, evaluator: bool = False) -> AxisBands:
    """Bands of one axis (AXIS_* code) for ownship ``(N,)`` and intruders ``(N, M)``; ``sizes`` = the columns
    per side (at least the batch's :func:`candidate_counts`, the default); ``lists`` = (NEAR, MID)
    conflict-aircraft flags ``(N, M)`` used with ``cfg.horizon_from_maneuver`` (default
    :func:`daa_sil.daa.alerting.conflict_lists`).

    Each encounter's bands are those of a call of its own: its own candidates per side
    (:func:`daa_sil.daa.axis_paths.row_counts`; a speed axis's depend on the current speed), its paths
    evaluated to its own last knot, its regions, recovery and resolutions over its own candidates. The
    columns past an encounter's candidates repeat its outermost candidate on that side.

    The cylinder recovery (``daidalus``) runs on the evaluator's path (``evaluator``); the one-pass kernels
    make every row's bands first, and only the rows whose axis saturates (no conflict-free candidate)
    are made again on that path (:func:`_cylinder_rows`): a row's bands do not depend on its batch."""
    j_lo, j_hi = sizes if sizes is not None else candidate_counts(own, axis, cfg)
    n, m = intr.shape
    rows = row_counts(own, axis, cfg)
    fused = COMPILED and FUSED and not evaluator
    if fused and cfg.recovery == "cylinder":
        return _cylinder_rows(own, intr, axis, cfg, alert, lists, rows, j_lo, j_hi)
    fused = fused and cfg.recovery != "cylinder"
    if not fused and n and not (np.all(rows[0] == j_lo) and np.all(rows[1] == j_hi)):
        return _by_counts(own, intr, axis, cfg, alert, lists, rows, j_lo, j_hi)
    paths, _ = maneuver_paths(own, axis, cfg, max(j_lo, j_hi), with_values=False)
    side = column_sides(j_lo, j_hi)
    if fused and paths.kin is not None:  # one pass per path, then per row
        values, delta, t_man, *rest = axis_conflict_regions(paths, own, intr, axis, cfg, alert, lists, j_lo, j_hi,
                                                            rows)
        return AxisBands(axis, values, delta, side, t_man, *rest)
    t = np.asarray(paths.t, float)[0, 0]
    ev = PathEvaluator(paths, intr, cfg.lookahead_s)
    pc = ev.evaluate(cfg.th)
    t_in, t_out = pc.candidates()  # (N, M, 2, J+1)
    if COMPILED and cfg.recovery != "cylinder":  # the rest of this function in one compiled pass
        values, delta, t_man, *rest = axis_regions(t_in, t_out, alert, lists, t, own, intr, axis, cfg, j_lo, j_hi)
        return AxisBands(axis, values, delta, side, t_man, *rest)
    L = cfg.lookahead_s
    tk = t[None, None, None, :]
    if cfg.horizon_from_maneuver:
        if lists is None:
            lists = conflict_lists(own, intr, cfg)
        near_list, mid_list = (np.asarray(a, bool)[:, :, None, None] for a in lists)
        red_near_i = t_in < np.where(near_list, L, np.minimum(L, cfg.alert_time_warning_s + tk))
        red_mid_i = t_in < np.where(mid_list, L, np.minimum(L, cfg.alert_time_corrective_s + tk))
    else:
        horizon = np.where(np.asarray(alert) >= 2, L, cfg.alert_time_corrective_s)[:, :, None, None]
        red_mid_i = t_in < horizon
        red_near_i = t_in < cfg.alert_time_warning_s
        mid_list = None
    order = lambda a: _side_order(a, j_lo, j_hi)  # noqa: E731
    runs = drop_isolated if cfg.daidalus_grid else (lambda g: g)
    red_near = order(_over_intruders(red_near_i, np.any)) if m else np.zeros((n, j_lo + j_hi + 1), bool)
    red_mid = order(_over_intruders((red_near_i | red_mid_i) if not cfg.horizon_from_maneuver else red_mid_i, np.any)) \
        if m else np.zeros((n, j_lo + j_hi + 1), bool)
    g_near, g_mid = runs(~red_near), runs(~red_mid)
    region = np.full(red_near.shape, REGION_NONE, np.int8)
    region[~g_mid] = REGION_MID
    region[~g_near] = REGION_NEAR
    t_in_all = order(_over_intruders(t_in, np.min)) if m else np.full(region.shape, np.inf)
    t_out_c = order(_over_intruders(np.where(red_mid_i | red_near_i, t_out, -np.inf), np.max)) if m \
        else np.full(region.shape, -np.inf)
    # candidate values in the column order (low side outward-in, current, high side)
    knot = np.r_[np.arange(j_lo, 0, -1), np.arange(j_hi + 1)]
    sgn = np.r_[-np.ones(j_lo), np.ones(j_hi + 1)]
    values, delta, rate = _candidate_values(own, axis, cfg, sgn, t[knot])
    if axis != AXIS_HORIZONTAL and cfg.daidalus_grid:  # a candidate past a limit is shown at the limit
        lo, hi = (-cfg.max_vs, cfg.max_vs) if axis == AXIS_VERTICAL else (cfg.min_gs, cfg.max_gs)
        values = np.clip(values, lo, hi)
    t_man = np.abs(delta) / rate
    k0 = j_lo
    # -- recovery: every candidate MID or worse ---------------------------------------------------------
    rec_time = np.full(n, np.nan)
    rec_n = np.full(n, -1, np.int16)
    rec_h, rec_v = np.full(n, np.nan), np.full(n, np.nan)
    gap = None
    if cfg.recovery == "cylinder":
        saturated = ~g_near.any(axis=1) | ~g_mid.any(axis=1)
    else:
        saturated = np.all(region >= REGION_MID, axis=1)
    rows = np.flatnonzero(saturated & (m > 0))
    if cfg.recovery == "cylinder":
        rec_green = np.zeros(region.shape, bool)
        if rows.size:
            if mid_list is None:
                mid_flag = np.asarray(alert)[rows] >= 2
            else:
                mid_flag = mid_list[rows, :, 0, 0]
            listed = mid_flag | red_mid_i[rows].any(axis=(2, 3))
            horizon = np.where(mid_flag, L, min(L, cfg.alert_time_corrective_s))
            corr = PathConflicts(pc.seg_in[rows], pc.seg_out[rows], pc.tail_in[rows], pc.tail_out[rows],
                                 pc.t[rows], pc.t_end)
            g, rt, nf, hh, vv = CylinderRecovery(paths.subset(rows), intr[rows], corr, listed, horizon, cfg, order,
                                                 runs, (j_lo, j_hi), fused=COMPILED and FUSED).run()
            rec_green[rows] = g
            rec_time[rows], rec_n[rows], rec_h[rows], rec_v[rows] = rt, nf, hh, vv
        region = np.where(rec_green, REGION_RECOVERY, region).astype(np.int8)
        both = lambda a: a[:, :-1] & a[:, 1:]  # noqa: E731
        gap = np.where(both(rec_green), REGION_RECOVERY,
                       np.where(~both(g_near), REGION_NEAR, np.where(~both(g_mid), REGION_MID, REGION_NONE))
                       ).astype(np.int8)
    else:
        late = t_in_all > cfg.sm_horizon_s  # LoWC only after the SM horizon: still "safe" (SM > 0)
        any_late = late.any(axis=1, keepdims=True)
        best_exit = np.min(t_out_c, axis=1, keepdims=True)
        rec = saturated[:, None] & np.where(any_late, late, t_out_c <= best_exit + cfg.recovery_stability_s)
        region = np.where(rec, REGION_RECOVERY, region).astype(np.int8)
        if cfg.daidalus_grid:
            both = lambda a: a[:, :-1] & a[:, 1:]  # noqa: E731
            gap = np.where(both(rec), REGION_RECOVERY,
                           np.where(~both(g_near), REGION_NEAR, np.where(~both(g_mid), REGION_MID, REGION_NONE))
                           ).astype(np.int8)
    # -- resolutions ------------------------------------------------------------------------------------
    res_lo, res_hi, pref = resolutions(region, values, delta, side, t_man, k0, axis, cfg)
    return AxisBands(axis, values, delta, side, t_man, t_in_all, t_out_c, region, res_lo, res_hi, pref, gap,
                     rec_time, rec_n, rec_h, rec_v)  # (own_lo / own_hi None: every row has every column)


def _by_counts(own: AircraftState, intr: AircraftState, axis: int, cfg: DaaConfig, alert, lists, rows, j_lo: int,
               j_hi: int) -> AxisBands:
    """:func:`axis_bands` of a batch whose encounters have different candidate counts ``rows``, on the
    evaluator's path (the numpy reference, the cylinder recovery): one call per set of encounters with the
    same counts, each with exactly those candidates, then each row placed in the batch's ``j_lo`` + 1 +
    ``j_hi`` columns with its outermost candidates repeated past its own."""
    n, k = own.shape[0], j_lo + j_hi + 1
    key = rows[0] * (j_hi + 1) + rows[1]
    parts = []
    for v in np.unique(key):
        idx = np.flatnonzero(key == v)
        lo, hi = int(rows[0][idx[0]]), int(rows[1][idx[0]])
        li = None if lists is None else (lists[0][idx], lists[1][idx])
        parts.append((idx, lo, hi, axis_bands(own[idx], intr[idx], axis, cfg, np.asarray(alert)[idx], (lo, hi), li,
                                              evaluator=True)))
    b0 = parts[0][3]

    def widen(name: str, width: int):
        out = None
        for idx, lo, hi, b in parts:
            a = np.asarray(getattr(b, name))
            if out is None:
                out = np.empty((n, width) if width else (n,), a.dtype)
            if not width:
                out[idx] = a
                continue
            a = np.broadcast_to(a, (idx.size, a.shape[1]))
            c0 = j_lo - lo
            out[idx, c0:c0 + a.shape[1]] = a
            if name == "gap_region":  # (between repeated candidates: the outermost one's region)
                out[idx, :c0] = np.asarray(b.region)[:, :1]
                out[idx, c0 + a.shape[1]:] = np.asarray(b.region)[:, -1:]
            else:
                out[idx, :c0] = a[:, :1]
                out[idx, c0 + a.shape[1]:] = a[:, -1:]
        return out
    per_row = {f.name: widen(f.name, k if f.name in ("values", "delta", "t_man", "t_in", "t_out", "region") else 0)
               for f in fields(AxisBands) if f.name not in ("axis", "side", "gap_region", "own_lo", "own_hi")}
    gap = None if b0.gap_region is None else widen("gap_region", k - 1)
    side = np.concatenate([-np.ones(j_lo, int), [0], np.ones(j_hi, int)])
    return AxisBands(axis=axis, side=side, gap_region=gap, own_lo=j_lo - rows[0], own_hi=j_lo + rows[1], **per_row)


def _cylinder_rows(own: AircraftState, intr: AircraftState, axis: int, cfg: DaaConfig, alert, lists, rows,
                   j_lo: int, j_hi: int) -> AxisBands:
    """:func:`axis_bands` with the cylinder recovery: the one-pass kernels for every row (as without
    recovery: a row with a conflict-free candidate has none), then the rows without a NONE candidate of their
    own -- saturated for the cylinder search, or relabelled by the kernels' earliest exit -- made again: those
    with every candidate of the batch from their one-pass conflicts by the compiled search
    (:func:`daa_sil.daa.recovery.recover_rows`, with ``CYLINDER_COMPILED``), the others on the evaluator's
    path, which searches their recovery; both give a row the same numbers."""
    n, m = intr.shape
    paths, _ = maneuver_paths(own, axis, cfg, max(j_lo, j_hi), with_values=False)
    side = column_sides(j_lo, j_hi)
    if cfg.horizon_from_maneuver and lists is None:
        lists = conflict_lists(own, intr, cfg)
    with scratch() as ws:  # (every array taken from it is consumed or copied in this block)
        out = axis_path_conflicts(paths, intr, cfg.th, float(cfg.lookahead_s), np.maximum(rows[0], rows[1]), ws.take)
        values, delta, t_man, *rest = regions_of_conflicts(out, alert, lists, paths.axis_times(), own, intr, axis,
                                                           cfg, j_lo, j_hi, rows)
        ab = AxisBands(axis, values, delta, side, t_man, *rest)
        free = ab.region == REGION_NONE
        mask = ab.own_mask()
        idx = np.flatnonzero(~np.any(free if mask is None else free & mask, axis=1)) if m else np.zeros(0, int)
        if not idx.size:
            return ab
        full = (rows[0][idx] == j_lo) & (rows[1][idx] == j_hi) if CYLINDER_COMPILED else np.zeros(idx.size, bool)
        fast, idx = idx[full], idx[~full]
        if fast.size:
            conf = tuple(a.reshape(n, m, 2, -1)[fast] for a in out)  # (copies: the scratch is reused)
    if fast.size:
        recover_rows(paths, intr, axis, cfg, alert, lists, conf, fast, (j_lo, j_hi), ab)
    if not idx.size:
        return ab
    li = None if lists is None else (lists[0][idx], lists[1][idx])
    sub = axis_bands(own[idx], intr[idx], axis, cfg, np.asarray(alert)[idx], (j_lo, j_hi), li, evaluator=True)
    for f in fields(AxisBands):
        if f.name in ("axis", "side", "own_lo", "own_hi") or getattr(ab, f.name) is None:
            continue
        if axis == AXIS_HORIZONTAL and f.name in ("delta", "t_man"):  # (one row for every encounter, the same)
            continue
        getattr(ab, f.name)[idx] = getattr(sub, f.name)
    return ab


def resolutions(region, values, delta, side, t_man, k0: int, axis: int, cfg: DaaConfig,
                own: "np.ndarray | None" = None):
    """(res_lo, res_hi, preferred) of candidates ``(N, K)`` (see the module docstring); ``own`` (N, K): each
    row's own candidates (:meth:`AxisBands.own_mask`; None: all)."""
    cur = region[:, k0]
    cur_conflict = (cur == REGION_MID) | (cur == REGION_NEAR)
    ok = (region == REGION_NONE) | (region == REGION_RECOVERY)
    if own is not None:
        ok &= own
    if axis == AXIS_HORIZONTAL and cfg.daidalus_grid:  # a resolution is never exactly 180 deg away
        ok &= np.abs(delta) < np.pi - 1e-9
    i_lo, f_lo = _first_on_side(ok, side, -1, k0)
    i_hi, f_hi = _first_on_side(ok, side, +1, k0)
    take = lambda a, i: np.take_along_axis(a, i[:, None], -1)[:, 0]  # noqa: E731
    res_lo = np.where(cur_conflict, np.where(f_lo, take(values, i_lo), -np.inf), np.nan)
    res_hi = np.where(cur_conflict, np.where(f_hi, take(values, i_hi), np.inf), np.nan)
    d_lo, d_hi = take(t_man, i_lo), take(t_man, i_hi)
    hi_first = d_hi <= d_lo + 1e-9 * np.maximum(d_lo, 1.0)  # equal distances: right / up / faster
    pref = np.where(f_lo & f_hi, np.where(hi_first, 1, -1), np.where(f_hi, 1, np.where(f_lo, -1, 0)))
    return res_lo, res_hi, np.where(cur_conflict, pref, 0).astype(np.int8)


def compute_bands(own: AircraftState, intr: AircraftState, cfg: "DaaConfig | None" = None,
                  alert: "np.ndarray | None" = None,
                  lists: "tuple[np.ndarray, np.ndarray] | None" = None, axes: "tuple[int, ...] | None" = None) -> Bands:
    """Kinematic track, vertical-speed and ground-speed bands for ownship ``(N,)`` vs intruders ``(N, M)``.

    ``alert`` (N, M) are the current alert levels (computed with :func:`alert_levels` if omitted);
    ``lists`` the (NEAR, MID) conflict-aircraft flags for ``cfg.horizon_from_maneuver`` (computed
    without hysteresis if omitted; :class:`daa_sil.daa.DaaState` passes its early-alerting ones).
    ``axes`` the AXIS_* codes to compute (default all three; each axis is computed on its own, so
    an axis's bands do not depend on which others are asked for); an axis left out is None.
    """
    cfg = cfg or DaaConfig()
    if alert is None:
        alert = alert_levels(own, intr, cfg)
    if cfg.horizon_from_maneuver and lists is None:
        lists = conflict_lists(own, intr, cfg)
    n = own.shape[0]
    codes = (AXIS_HORIZONTAL, AXIS_VERTICAL, AXIS_SPEED)
    wanted = codes if axes is None else tuple(a for a in codes if a in axes)
    sizes = {a: candidate_counts(own, a, cfg) for a in wanted}
    chunks = []
    for lo in range(0, max(n, 1), CHUNK):
        sl = slice(lo, min(lo + CHUNK, n))
        li = None if lists is None else (lists[0][sl], lists[1][sl])
        # one chunk: the states as given (axis_bands only reads them; a slice would copy all twelve arrays)
        o, i_ = (own, intr) if n <= CHUNK else (own[sl], intr[sl])
        chunks.append({a: axis_bands(o, i_, a, cfg, alert[sl], sizes[a], li) for a in wanted})
    out = [None if a not in wanted else chunks[0][a] if len(chunks) == 1 else _concat([c[a] for c in chunks])
           for a in codes]
    return Bands(*out, alert=alert, preset=cfg.th.name)


#: encounters per internal chunk (keeps the working arrays cache-sized; results do not depend on it)
CHUNK = 16384


def _concat(parts: "list[AxisBands]") -> AxisBands:
    p0 = parts[0]
    if any(p.own_lo is not None for p in parts):  # (a part without them has every column)
        parts = [p.with_fields(own_lo=p.own_range()[0], own_hi=p.own_range()[1]) for p in parts]
    keep = lambda f: f.name in ("axis", "side") or any(getattr(p, f.name) is None for p in parts)  # noqa: E731
    return AxisBands(**{f.name: ((getattr(p0, f.name) if f.name in ("axis", "side") else None) if keep(f)
                                 else np.concatenate([getattr(p, f.name) for p in parts], axis=0))
                        for f in fields(p0)})


__all__ = ["AxisBands", "Bands", "gap_regions", "axis_bands", "compute_bands", "resolutions", "COMPILED", "FUSED",
           "CYLINDER_COMPILED", "CHUNK"]
