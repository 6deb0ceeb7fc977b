"""Onboard DAA, DAIDALUS-style (batched over N encounters and M intruders); rules in ``docs/daa.md``.

Contract (ownship :class:`~daa_sil.geometry.kinematics.AircraftState` shape ``(N,)``, intruders ``(N, M)``;
SI units, compass radians):

* :class:`DaaConfig` -- ``DaaConfig.for_preset(name)``: ``do365`` (default) and ``paper`` (project grids
  5 deg / 500 fpm / 10 kt in 40-200 kt, horizons from now, earliest-exit recovery, stateless) and
  ``daidalus`` (NASA DAIDALUS v2.0.4 ``DO_365B_no_SUM.conf``: 1 deg / 100 fpm / 5 kt in 10-700 kt,
  horizons from the maneuver, shrinking-cylinder recovery, hysteresis). Common: lookahead 180 s;
  alerting 55/55/25 s; preventive ZTHR 700 ft; 3 deg/s, 2 m/s^2, 0.25 g, +-6000 fpm.
* :func:`alert_levels` ``(own, intr, cfg) -> int8 (N, M)`` 0 none, 1 preventive, 2 corrective, 3 warning.
* :func:`compute_bands` ``(own, intr, cfg) -> Bands`` kinematic track / vs / gs bands with regions
  (none, mid, near, recovery), resolutions per side and a preferred side, maneuvers evaluated on the
  true trajectory; ``AxisBands.intervals(i)`` / ``band_intervals(i)``.
* :class:`DaaState` -- hysteresis, M-of-N and persistence of alerts, bands and resolutions (stateful presets).
* :func:`proj_lowc` ``(own, intr, cfg, horizon_s) -> bool (N, M)`` paper Eq. 10.
* :func:`safety_metric` ``(own, intr, cmd, cfg, horizon_s) -> (N,)`` SM(u) in seconds; > 0 iff u keeps
  the ownship well clear of every intruder for ``horizon_s``.
* :func:`search_maneuver` ``(own, intr, axis, direction, cfg, ref=None) -> (Command, rule)`` Algorithm 2.
* :func:`daa_resolution` ``(own, intr, cfg, prev=None) -> Command`` and :func:`classify_command`.
* :mod:`daa_sil.daa.conformance` -- agreement with DAIDALUS reference outputs.
"""

from .alerting import alert_levels, conflict_lists, proj_lowc, relative_state
from .bands import AxisBands, Bands, compute_bands
from .config import (ALERT_NAMES, AXIS_HORIZONTAL, AXIS_NAMES, AXIS_NONE, AXIS_SPEED, AXIS_VERTICAL, DEFAULT_CONFIG,
                     DIR_DOWN, DIR_FASTER, DIR_LEFT, DIR_NAMES, DIR_NONE, DIR_RIGHT, DIR_SLOWER, DIR_UP,
                     REGION_FAR, REGION_MID, REGION_NAMES, REGION_NEAR, REGION_NONE, REGION_RECOVERY, RULE_ANY,
                     RULE_AXIS, RULE_AXIS_DIR, RULE_BEST_EFFORT, RULE_NAMES, RULE_NONE, DaaConfig)
from .hysteresis import DaaState
from .resolution import classify_command, daa_resolution, resolve, search_maneuver
from daa_sil.daa.safety import command_conflicts, safety_metric, sm_from_tin

__all__ = [
    "DaaConfig", "DEFAULT_CONFIG", "DaaState", "alert_levels", "conflict_lists", "proj_lowc", "relative_state", "compute_bands", "Bands",
    "AxisBands", "safety_metric", "command_conflicts", "sm_from_tin", "search_maneuver", "daa_resolution",
    "resolve", "classify_command",
    "ALERT_NAMES", "REGION_NAMES", "AXIS_NAMES", "DIR_NAMES", "RULE_NAMES",
    "REGION_NONE", "REGION_FAR", "REGION_MID", "REGION_NEAR", "REGION_RECOVERY",
    "AXIS_NONE", "AXIS_HORIZONTAL", "AXIS_VERTICAL", "AXIS_SPEED",
    "DIR_NONE", "DIR_LEFT", "DIR_RIGHT", "DIR_UP", "DIR_DOWN", "DIR_FASTER", "DIR_SLOWER",
    "RULE_NONE", "RULE_AXIS_DIR", "RULE_AXIS", "RULE_ANY", "RULE_BEST_EFFORT",
]
