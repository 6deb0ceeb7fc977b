"""The compiled tail of :func:`daa_sil.daa.bands.axis_bands` for the ``earliest_exit`` recovery:
from the candidates' first violation / last exit per intruder to the axis's candidate values,
regions, gap regions, recovery columns, resolutions and preferred side, in one pass per encounter
(:func:`daa_sil.daa.kernels.regions.axis_regions_into`). ``axis_bands`` with ``bands.COMPILED = False``
is the numpy reference the tests compare it with."""

from __future__ import annotations

import functools

import numpy as np

from daa_sil.daa import kernels
from daa_sil.daa.alerting import conflict_lists
from daa_sil.daa.axis_paths import speed_limits
from daa_sil.daa.certify import UNDECIDED
from daa_sil.daa.scratch import scratch
from daa_sil.daa.config import AXIS_HORIZONTAL, AXIS_VERTICAL, DaaConfig
from daa_sil.daa.trajectory import BLOCK, ManeuverPaths
from daa_sil.daa.undecided import resolve_segments
from daa_sil.geometry.kinematics import TWO_PI, AircraftState

_NO_FLAGS = np.zeros((1, 1), bool)
_NO_TIMES = np.zeros(0)


def regions_of_conflicts(conflicts: tuple, alert, lists, t: np.ndarray, own: AircraftState, intr: AircraftState,
                         axis: int, cfg: DaaConfig, j_lo: int, j_hi: int,
                         rows: "tuple[np.ndarray, np.ndarray] | None") -> tuple:
    """:func:`axis_regions` from ``conflicts``: the candidates' ``(t_in, t_out)`` (N, M, 2, J+1), or the paths'
    ``(tail_in, tail_out, seg_in, seg_out)`` flat (``kernels.regions.axis_regions_into``)."""
    n, m = own.shape[0], intr.shape[1]
    jl_row, jh_row = rows if rows is not None else (np.full(n, j_lo, np.int64), np.full(n, j_hi, np.int64))
    k = j_lo + j_hi + 1
    times, ax, hfm = _axis_constants(cfg, axis)
    if hfm:
        if lists is None:
            lists = conflict_lists(own, intr, cfg)
        near, mid = (np.asarray(a, bool) for a in lists)
        alert2 = _NO_FLAGS
    else:
        near = mid = _NO_FLAGS
        alert2 = np.asarray(alert) >= 2
    cur = own.trk if axis == AXIS_HORIZONTAL else own.vs if axis == AXIS_VERTICAL else own.gs
    # a track candidate's change and maneuver time do not depend on the encounter: one row, broadcast
    one = axis == AXIS_HORIZONTAL
    # the (N, K) float fields in one allocation (numpy asks the system for huge pages for one of 4 MB and
    # more, so at N = 10,000 a few faults instead of one per 4 KiB page), each field a view of its own part
    block = np.empty((3 if one else 5, n, k))
    values, t_in_all, t_out_c = block[0], block[1], block[2]
    delta, t_man = (np.empty((1, k)), np.empty((1, k))) if one else (block[3], block[4])
    region = np.empty((n, k), np.int8)
    gap = np.empty((n, max(k - 1, 0)), np.int8)
    res = np.empty((2, n))
    pref = np.empty(n, np.int8)
    flat = tuple(np.ascontiguousarray(a).reshape(-1) for a in conflicts)
    from_paths = len(flat) == 4
    if not from_paths:
        flat += (_NO_TIMES, _NO_TIMES)
    kernels.get().axis_regions_into(flat, from_paths, m, times[0], hfm, (near, mid, alert2),
                                    np.asarray(t, float), times, (j_lo, j_hi), (jl_row, jh_row), ax,
                                    np.asarray(cur, float), (values, delta, t_man, t_in_all, t_out_c), (region, gap),
                                    (res[0], res[1]), pref)
    if one:
        delta, t_man = np.broadcast_to(delta, (n, k)), np.broadcast_to(t_man, (n, k))
    rec = np.empty((3, n))
    rec[:] = np.nan
    uniform = rows is None or (bool((jl_row == j_lo).all()) and bool((jh_row == j_hi).all()))
    return (values, delta, t_man, t_in_all, t_out_c, region, res[0], res[1], pref,
            gap if cfg.daidalus_grid else None, rec[0], np.full(n, -1, np.int16), rec[1], rec[2],
            None if uniform else j_lo - jl_row, None if uniform else j_lo + jh_row)


@functools.lru_cache(maxsize=64)
def _axis_constants(cfg: DaaConfig, axis: int) -> tuple:
    """``(times, ax, hfm)`` of ``kernels.regions.axis_regions_into`` for ``cfg`` and ``axis`` (Python floats, made
    once per configuration and axis)."""
    if axis == AXIS_HORIZONTAL:
        rate, lim = cfg.turn_rate, np.zeros(2)
    else:
        rate, lim = speed_limits(axis == AXIS_VERTICAL, cfg, np.array([-1.0, 1.0]))
    clip = (-cfg.max_vs, cfg.max_vs) if axis == AXIS_VERTICAL else (cfg.min_gs, cfg.max_gs)
    times = (float(cfg.lookahead_s), float(cfg.alert_time_warning_s), float(cfg.alert_time_corrective_s),
             float(cfg.sm_horizon_s), float(cfg.recovery_stability_s), np.pi - 1e-9, TWO_PI)
    ax = (bool(cfg.daidalus_grid), axis, float(rate), float(lim[0]), float(lim[1]),
          bool(cfg.daidalus_grid and axis != AXIS_HORIZONTAL), float(clip[0]), float(clip[1]))
    return times, ax, bool(cfg.horizon_from_maneuver)


def axis_regions(t_in: np.ndarray, t_out: np.ndarray, alert, lists, t: np.ndarray, own: AircraftState,
                 intr: AircraftState, axis: int, cfg: DaaConfig, j_lo: int, j_hi: int,
                 rows: "tuple[np.ndarray, np.ndarray] | None" = None) -> tuple:
    """``(values, delta, t_man, t_in, t_out, region, res_lo, res_hi, preferred, gap_region, recovery_time,
    recovery_nfactor, recovery_h, recovery_v, own_lo, own_hi)`` of one axis (the :class:`daa_sil.daa.bands.AxisBands` fields
    after ``side``, s / rad / m/s; no recovery cylinder) from ``t_in``/``t_out`` (N, M, 2, J+1, s), the alert
    levels ``alert`` (N, M), the conflict lists ``lists`` (with ``cfg.horizon_from_maneuver``; computed for
    ownship ``own`` and intruders ``intr`` when None) and the knot times ``t`` (J+1,) s; ``gap_region`` is
    None off the DAIDALUS grid. A track axis's ``delta`` and ``t_man`` are the same for every encounter: one
    row broadcast to (N, K), read-only. ``rows``: each encounter's own candidates per side ``(N,)`` (at most
    ``j_lo``/``j_hi``; default all), its paths' conflicts up to knot ``max`` of the two; the columns past them
    repeat its outermost candidate (``kernels.regions.axis_regions_into``)."""
    return regions_of_conflicts((t_in, t_out), alert, lists, t, own, intr, axis, cfg, j_lo, j_hi, rows)


def axis_conflict_regions(paths: ManeuverPaths, own: AircraftState, intr: AircraftState, axis: int, cfg: DaaConfig,
                          alert, lists, j_lo: int, j_hi: int, rows: "tuple[np.ndarray, np.ndarray]") -> tuple:
    """:func:`axis_regions` of the band axis ``paths`` (``axis_paths.maneuver_paths``) against ``intr`` for
    ``cfg.th`` over the lookahead, the conflicts computed in one pass per path
    (``kernels.axis_pass.axis_conflicts_into``; undecided segments by
    :func:`daa_sil.daa.undecided.resolve_segments` on their knots' states alone) and read per row by the
    regions kernel: the same numbers as ``PathEvaluator(paths, intr, cfg.lookahead_s).evaluate(cfg.th)``
    then ``candidates()`` then :func:`axis_regions`, without their (N, M, 2, J+1) arrays of relative
    states and candidates' conflicts. ``rows``: each encounter's own candidates per side (:func:`axis_regions`);
    its paths are evaluated up to knot ``max`` of the two, as in a call of its own."""
    with scratch() as ws:  # (every array taken from it is consumed in this call)
        out = axis_path_conflicts(paths, intr, cfg.th, float(cfg.lookahead_s), np.maximum(rows[0], rows[1]), ws.take)
        return regions_of_conflicts(out, alert, lists, paths.axis_times(), own, intr, axis, cfg, j_lo, j_hi, rows)


def axis_path_conflicts(paths: ManeuverPaths, intr: AircraftState, th, t_end: float, nseg: np.ndarray,
                        take=None) -> tuple:
    """``(tail_in, tail_out, seg_in, seg_out)`` flat over ``(N, M, 2, J+1)`` / ``(N, M, 2, J)`` of the band axis
    ``paths`` against ``intr`` for volume ``th`` over ``[0, t_end]``, encounter ``n``'s paths up to knot
    ``nseg[n]``, in one pass per path (``kernels.axis_pass.axis_conflicts_into``; the undecided segments by
    :func:`daa_sil.daa.undecided.resolve_segments` on their knots' states alone): the numbers of
    ``PathEvaluator(paths, intr, t_end).evaluate(th)``. ``take(name, size[, dtype])``: where the arrays come
    from (default: new ones)."""
    if take is None:
        take = lambda name, size, dtype=float: np.empty(size, dtype)  # noqa: E731
    n, m = intr.shape
    kin = paths.kin
    t = paths.axis_times()
    knots = t.shape[0]
    ipos, ivel = intr.position(), intr.velocity()
    D = float(th.dthr)
    n_paths = n * m * 2
    code = take("code", n_paths * (knots - 1), np.int8)
    seg_in, seg_out = take("seg_in", n_paths * (knots - 1)), take("seg_out", n_paths * (knots - 1))
    tail_in, tail_out = take("tail_in", n_paths * knots), take("tail_out", n_paths * knots)
    vlo, vhi = take("vlo", n_paths), take("vhi", n_paths)
    k = kernels.get()
    k.axis_conflicts_into((kin[1], kin[2], kin[3], t, np.asarray(nseg, np.int64)), (ipos, ivel),
                          (paths.acc_h, paths.acc_v), bool(paths.vz_const), BLOCK, float(t_end),
                          (D, D * D, D ** 2, float(th.zthr), float(th.tthr), float(th.tcoa)),
                          (code, seg_in, seg_out), (tail_in, tail_out), (vlo, vhi))
    todo = np.flatnonzero(code == UNDECIDED)
    if todo.size:
        r = todo.size
        knot = np.empty((7, 2 * r))  # s (3), v (3), t at the segments' two knots
        k.axis_segment_knots_into(kin[1], kin[2], kin[3], t, ipos, ivel, todo, *knot)
        path = todo // (knots - 1)
        e, p = path // (m * 2), path % 2
        sub = lambda a: None if a is None else a[e, p]  # noqa: E731
        ipv = np.concatenate([ipos, ivel], axis=-1).reshape(-1, 6)
        resolve_segments(kin, ipv, m, 2, path, (knot[0], knot[1], knot[2]), (knot[3], knot[4], knot[5]), knot[6],
                         todo, np.arange(0, 2 * r, 2), paths.acc_h[e, p], paths.acc_v[e, p], sub(paths.jerk_h),
                         sub(paths.kink_t), (vlo[path], vhi[path], None) if paths.vz_const else None, True, th, seg_in,
                         seg_out)
    return tail_in, tail_out, seg_in, seg_out

