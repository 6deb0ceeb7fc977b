"""DAA configuration, the named DAA presets, and the integer codes used in results.

All values SI inside (m, s, m/s, rad). A preset name sets the well-clear thresholds *and* the band
settings (:meth:`DaaConfig.for_preset`):

* ``do365`` (default) and ``paper``: today's project configuration. DO-365B kinematics (3 deg/s,
  2 m/s^2, 0.25 g, +-6000 fpm, lookahead 180 s, alerting 55 / 55 / 25 s) with UAS-sized candidate
  grids: track every 5 deg, vertical speed every 500 fpm, ground speed every 10 kt in [40, 200] kt;
  peripheral band horizons counted from now, "earliest exit" recovery, stateless alerting.
* ``daidalus``: NASA DAIDALUS v2.0.4 ``DO_365B_no_SUM.conf`` -- DMOD = HMD* = 0.66 nmi, grids
  1 deg / 5 kt / 100 fpm over +-180 deg, [10, 700] kt and +-6000 fpm, band horizons from the
  maneuver (``bands_add_time_to_maneuver = false``), shrinking-cylinder recovery down to the NMAC
  volume (``ca_bands``, ``ca_factor`` 0.1), and hysteresis 5 s / persistence 4 s / M-of-N 2 of 4.

Candidate grids are anchored at the current value as in DAIDALUS: candidate ``k`` of an axis is
reached kinematically after ``k * knot`` seconds with ``knot = step / rate`` (5/3 s for a 5 deg
track step at 3 deg/s). The maneuver between knots is evaluated on the true trajectory (turn arc,
acceleration parabola) by :mod:`daa_sil.daa.trajectory`; ``docs/daa.md`` states every rule.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property

from daa_sil.geometry.kinematics import Performance
from ..errors import UsageError
from daa_sil.geometry.thresholds import PRESETS, Thresholds, get_thresholds
from daa_sil.config.settings import STANDARD_PRESET
from daa_sil.geometry.units import DEG, FPM, FT, G0, KT, NMI
import numpy as np

# --- codes -----------------------------------------------------------------------------------
ALERT_NAMES = ("none", "preventive", "corrective", "warning")

#: region codes (step log, MAVLink DAA_SIL_BAND_REGION). FAR is DAIDALUS's preventive-level band; our
#: bands paint MID, NEAR and RECOVERY only, so FAR is a reserved code of the wire format and the
#: vocabulary (painting it would change what the pilot model sees: a model change, docs/architecture.md)
REGION_NONE, REGION_FAR, REGION_MID, REGION_NEAR, REGION_RECOVERY = range(5)
REGION_NAMES = ("none", "far", "mid", "near", "recovery")

AXIS_NONE, AXIS_HORIZONTAL, AXIS_VERTICAL, AXIS_SPEED = range(4)
AXIS_NAMES = ("none", "horizontal", "vertical", "speed")

DIR_NONE, DIR_LEFT, DIR_RIGHT, DIR_UP, DIR_DOWN, DIR_FASTER, DIR_SLOWER = range(7)
DIR_NAMES = ("none", "left", "right", "up", "down", "faster", "slower")

#: (axis, side) of each direction code; side -1 = left/down/slower, +1 = right/up/faster
DIR_AXIS = (AXIS_NONE, AXIS_HORIZONTAL, AXIS_HORIZONTAL, AXIS_VERTICAL, AXIS_VERTICAL, AXIS_SPEED, AXIS_SPEED)
DIR_SIDE = (0, -1, +1, +1, -1, +1, -1)

RULE_NONE, RULE_AXIS_DIR, RULE_AXIS, RULE_ANY, RULE_BEST_EFFORT = range(5)
RULE_NAMES = ("-", "axis_dir", "axis", "any", "best_effort")


def axis_code(axis) -> int:
    """Axis name or code to its integer code."""
    if isinstance(axis, str):
        return AXIS_NAMES.index(axis)
    return int(axis)


def dir_code(direction) -> int:
    """Direction name or code to its integer code."""
    if isinstance(direction, str):
        return DIR_NAMES.index(direction)
    return int(direction)


def side_to_dir(axis, side):
    """Direction code of (axis code, side +-1) arrays (0 where side is 0 or axis none)."""

    axis = np.asarray(axis)
    side = np.asarray(side)
    table = np.array([[0, 0, 0], [DIR_LEFT, 0, DIR_RIGHT], [DIR_DOWN, 0, DIR_UP], [DIR_SLOWER, 0, DIR_FASTER]])
    return table[axis, np.sign(side).astype(int) + 1]


RECOVERY_MODES = ("earliest_exit", "cylinder")


@dataclass(frozen=True)
class DaaConfig:
    """Onboard DAA parameters (SI). Frozen; use :meth:`with_` for variants, :meth:`for_preset` for presets.

    The four switches below select between today's project semantics (defaults) and DAIDALUS v2.0.4's
    (the ``daidalus`` preset); ``docs/daa.md`` explains each one.
    """

    thresholds: "str | Thresholds" = STANDARD_PRESET.default  #: corrective/warning well-clear volume (preset name)
    preventive_zthr: float = 700.0 * FT  #: m, DO-365 preventive volume ZTHR
    lookahead_s: float = 180.0  #: s, DO-365B lookahead_time
    alert_time_preventive_s: float = 55.0
    alert_time_corrective_s: float = 55.0
    alert_time_warning_s: float = 25.0
    early_alert_time_preventive_s: float = 75.0  #: used only with hysteresis (``hysteresis_s > 0``)
    early_alert_time_corrective_s: float = 75.0
    early_alert_time_warning_s: float = 55.0
    turn_rate: float = 3.0 * DEG  #: rad/s
    horizontal_accel: float = 2.0  #: m/s^2
    vertical_accel: float = 0.25 * G0  #: m/s^2
    max_vs: float = 6000.0 * FPM  #: m/s (symmetric)
    min_gs: float = 40.0 * KT  #: m/s
    max_gs: float = 200.0 * KT  #: m/s
    trk_step: float = 5.0 * DEG  #: rad, track candidate spacing (1-5 deg sensible)
    vs_step: float = 500.0 * FPM  #: m/s, vertical-speed candidate spacing
    gs_step: float = 10.0 * KT  #: m/s, ground-speed candidate spacing
    trk_range: float = 180.0 * DEG  #: rad, candidates to each side (DAIDALUS left/right_hdir)
    recovery_stability_s: float = 3.0  #: s, recovery: exit within this of the best / DAIDALUS stability time
    #: band horizon of an intruder not in conflict: False = alerting time from now (DAIDALUS v1/v2.0.1);
    #: True = alerting time plus the time to reach the maneuver, and the full lookahead for NEAR as
    #: well as MID once an intruder conflicts within that level's alerting time (DAIDALUS v2.0.4)
    horizon_from_maneuver: bool = False
    #: "earliest_exit" (the maneuvers that regain well clear soonest) or "cylinder" (DAIDALUS:
    #: shrink a recovery cylinder from (min_horizontal_recovery, min_vertical_recovery) toward NMAC)
    recovery: str = "earliest_exit"
    #: DAIDALUS candidate grid and interval semantics: both +-180 deg track candidates, the last
    #: speed candidate one step past the limit (its interval is clipped to the limit), a conflict-free
    #: run of a single candidate is not a band, and a resolution never lies exactly 180 deg away
    daidalus_grid: bool = False
    min_horizontal_recovery: "float | None" = None  #: m, recovery cylinder start (None = DTHR)
    min_vertical_recovery: "float | None" = None  #: m, recovery cylinder start (None = ZTHR)
    ca_bands: bool = True  #: cylinder recovery: keep shrinking down to the NMAC volume
    ca_factor: float = 0.1  #: cylinder recovery: shrink by (1 - ca_factor) per iteration
    hysteresis_s: float = 0.0  #: s, > 0 enables alert/band/resolution hysteresis (DaaState)
    persistence_s: float = 0.0  #: s, minimum time a raised alert / conflict band / direction is kept
    alert_m: int = 0  #: M of the M-of-N filter (0 = off)
    alert_n: int = 0  #: N of the M-of-N filter
    bands_persistence: bool = False  #: keep the current value's conflict band for persistence_s
    pref_delta_trk: float = 15.0 * DEG  #: rad, preferred-direction / resolution persistence delta
    pref_delta_gs: float = 100.0 * KT  #: m/s
    pref_delta_vs: float = 250.0 * FPM  #: m/s
    sm_horizon_s: float = 55.0  #: s, SM(u) horizon: a command is safe if no LoWC within it
    sm_margin_s: float = 30.0  #: s, SM is capped at this value (search window horizon + margin)
    resolution_axes: tuple = ("horizontal", "vertical", "speed")  #: DAA resolution axis priority

    def __post_init__(self):
        if self.recovery not in RECOVERY_MODES:
            raise UsageError(f"DaaConfig.recovery must be one of {', '.join(RECOVERY_MODES)}, got {self.recovery!r}")
        if self.hysteresis_s > 0 and not (0 < self.alert_m <= self.alert_n):
            raise UsageError(f"hysteresis needs 0 < alert_m <= alert_n, got M={self.alert_m}, N={self.alert_n}")

    @classmethod
    def for_preset(cls, name: "str | None" = None, **changes) -> "DaaConfig":
        """The DAA configuration of a named preset (``do365``, ``paper``, ``daidalus``; None: the field's default,
        the standard's ``do365``, as ``DaaConfig()``), plus ``changes``."""
        key = STANDARD_PRESET.default if name is None else str(name).lower()
        if key not in PRESETS:
            raise UsageError(f"unknown preset {name!r}; allowed: {', '.join(PRESETS)}")
        base = dict(DAIDALUS_DO365B) if key == "daidalus" else {}
        base.update(changes)
        return cls(thresholds=key, **base)

    @property
    def stateful(self) -> bool:
        """True when alerts, bands and resolutions carry hysteresis (:class:`daa_sil.daa.DaaState`)."""
        return self.hysteresis_s > 0

    @property
    def recovery_cylinder(self) -> tuple[float, float]:
        """(horizontal, vertical) start size of the recovery cylinder, m."""
        th = self.th
        h = th.dthr if self.min_horizontal_recovery is None else self.min_horizontal_recovery
        v = th.zthr if self.min_vertical_recovery is None else self.min_vertical_recovery
        return float(h), float(v)

    @property
    def th(self) -> Thresholds:
        """Corrective/warning well-clear thresholds."""
        return get_thresholds(self.thresholds)

    @cached_property
    def th_preventive(self) -> Thresholds:
        """Preventive volume: the corrective one with ZTHR = max(ZTHR, preventive_zthr); made once per
        configuration (the alert levels read it every step)."""
        th = self.th
        return th.with_(name=th.name + "-preventive", zthr=max(th.zthr, self.preventive_zthr))

    def performance(self) -> Performance:
        """The ownship :class:`~daa_sil.geometry.kinematics.Performance` these bands assume."""
        return Performance(max_turn_rate=self.turn_rate, horizontal_accel=self.horizontal_accel,
                           vertical_accel=self.vertical_accel, max_vs=self.max_vs,
                           min_gs=self.min_gs, max_gs=self.max_gs)

    @property
    def knot_trk(self) -> float:
        """Time (s) to turn by one track step."""
        return self.trk_step / self.turn_rate

    @property
    def knot_vs(self) -> float:
        """Time (s) to change vertical speed by one step."""
        return self.vs_step / self.vertical_accel

    @property
    def knot_gs(self) -> float:
        """Time (s) to change ground speed by one step."""
        return self.gs_step / self.horizontal_accel

    def with_(self, **changes) -> "DaaConfig":
        """A copy with some fields changed."""
        return replace(self, **changes)


#: DaaConfig fields of the ``daidalus`` preset: DAIDALUS v2.0.4 ``DO_365B_no_SUM.conf`` (the values
#: DAIDALUS read from that file, listed in the conformance set's configuration summary)
DAIDALUS_DO365B = dict(
    lookahead_s=180.0, alert_time_preventive_s=55.0, alert_time_corrective_s=55.0, alert_time_warning_s=25.0,
    early_alert_time_preventive_s=75.0, early_alert_time_corrective_s=75.0, early_alert_time_warning_s=55.0,
    preventive_zthr=700.0 * FT, turn_rate=3.0 * DEG, horizontal_accel=2.0, vertical_accel=0.25 * G0,
    max_vs=6000.0 * FPM, min_gs=10.0 * KT, max_gs=700.0 * KT, trk_step=1.0 * DEG, vs_step=100.0 * FPM,
    gs_step=5.0 * KT, trk_range=180.0 * DEG, recovery_stability_s=3.0, horizon_from_maneuver=True,
    recovery="cylinder", daidalus_grid=True, min_horizontal_recovery=0.66 * NMI, min_vertical_recovery=450.0 * FT,
    ca_bands=True, ca_factor=0.1, hysteresis_s=5.0, persistence_s=4.0, alert_m=2, alert_n=4,
    bands_persistence=True, pref_delta_trk=15.0 * DEG, pref_delta_gs=100.0 * KT, pref_delta_vs=250.0 * FPM,
)

DEFAULT_CONFIG = DaaConfig()
