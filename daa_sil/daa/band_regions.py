"""The compiled tail of :func:`daa_sil.daa.bands.axis_bands` for the ``earliest_exit`` recovery:
from the candidates' first violation / last exit per intruder to the axis's candidate values,
regions, gap regions, recovery columns, resolutions and preferred side, in one pass per encounter
(:func:`daa_sil.daa.kernels.regions.axis_regions_into`). ``axis_bands`` with ``bands.COMPILED = False``
is the numpy reference the tests compare it with."""

from __future__ import annotations

import numpy as np

from daa_sil.daa import kernels
from daa_sil.daa.alerting import conflict_lists
from daa_sil.daa.axis_paths import speed_limits
from daa_sil.daa.config import AXIS_HORIZONTAL, AXIS_VERTICAL, DaaConfig
from daa_sil.geometry.kinematics import TWO_PI, AircraftState

_NO_FLAGS = np.zeros((1, 1), bool)


def axis_regions(t_in: np.ndarray, t_out: np.ndarray, alert, lists, t: np.ndarray, own: AircraftState,
                 intr: AircraftState, axis: int, cfg: DaaConfig, j_lo: int, j_hi: int) -> tuple:
    """``(values, delta, t_man, t_in, t_out, region, res_lo, res_hi, preferred, gap_region, recovery_time,
    recovery_nfactor, recovery_h, recovery_v)`` of one axis (the :class:`daa_sil.daa.bands.AxisBands` fields
    after ``side``, s / rad / m/s; no recovery cylinder) from ``t_in``/``t_out`` (N, M, 2, J+1, s), the alert
    levels ``alert`` (N, M), the conflict lists ``lists`` (with ``cfg.horizon_from_maneuver``; computed for
    ownship ``own`` and intruders ``intr`` when None) and the knot times ``t`` (J+1,) s; ``gap_region`` is
    None off the DAIDALUS grid."""
    n = t_in.shape[0]
    k = j_lo + j_hi + 1
    hfm = bool(cfg.horizon_from_maneuver)
    if hfm:
        if lists is None:
            lists = conflict_lists(own, intr, cfg)
        near, mid = (np.asarray(a, bool) for a in lists)
        alert2 = _NO_FLAGS
    else:
        near = mid = _NO_FLAGS
        alert2 = np.asarray(alert) >= 2
    if axis == AXIS_HORIZONTAL:
        cur, rate, lim = own.trk, cfg.turn_rate, np.zeros(2)
    else:
        vertical = axis == AXIS_VERTICAL
        rate, lim = speed_limits(vertical, cfg, np.array([-1.0, 1.0]))
        cur = own.vs if vertical else own.gs
    clip = (-cfg.max_vs, cfg.max_vs) if axis == AXIS_VERTICAL else (cfg.min_gs, cfg.max_gs)
    values, delta, t_man, t_in_all, t_out_c = (np.empty((n, k)) for _ in range(5))
    region = np.empty((n, k), np.int8)
    gap = np.empty((n, max(k - 1, 0)), np.int8)
    res_lo, res_hi, pref = np.empty(n), np.empty(n), np.empty(n, np.int8)
    kernels.get().axis_regions_into(
        t_in, t_out, hfm, near, mid, alert2, np.asarray(t, float), float(cfg.lookahead_s), float(cfg.alert_time_warning_s),
        float(cfg.alert_time_corrective_s), j_lo, j_hi, bool(cfg.daidalus_grid), axis, np.asarray(cur, float),
        float(rate), float(lim[0]), float(lim[1]), bool(cfg.daidalus_grid and axis != AXIS_HORIZONTAL), float(clip[0]),
        float(clip[1]), float(cfg.sm_horizon_s), float(cfg.recovery_stability_s), np.pi - 1e-9, TWO_PI,
        values, delta, t_man, t_in_all, t_out_c, region, gap, res_lo, res_hi, pref)
    nan = np.full(n, np.nan)
    return (values, delta, t_man, t_in_all, t_out_c, region, res_lo, res_hi, pref, gap if cfg.daidalus_grid else None,
            nan, np.full(n, -1, np.int16), nan.copy(), nan.copy())
