"""DAA configuration (DO-365B / DAIDALUS defaults) and the integer codes used in results.

All values SI inside (m, s, m/s, rad). Defaults follow DAIDALUS ``DO_365B_no_SUM.conf``
(``daa_spec.md`` §3.3, §4.5) except where a UAS-sized value is more sensible (ground-speed range).

Candidate grids (``daa_spec.md`` §4.1, anchored at the current value as in DAIDALUS):

* track: every ``trk_step`` = 5 deg, 180 deg to each side (left -5..-180, right +5..+175);
* vertical speed: every ``vs_step`` = 500 fpm within +-``max_vs`` (6000 fpm);
* ground speed: every ``gs_step`` = 10 kt within [``min_gs``, ``max_gs``] = [40, 200] kt.

Each candidate is reached kinematically (turn at ``turn_rate``, accelerate at ``vertical_accel`` /
``horizontal_accel``), so candidate k of an axis is reached after ``k * knot`` seconds with
``knot = step / rate`` (5/3 s for track, 1.04 s for vs, 2.57 s for gs). The maneuver phase is
evaluated on chords between these knots (chord error < 2 m for a 5 deg turn at 100 m/s).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from ..kinematics import Performance
from ..thresholds import Thresholds, get_thresholds
from ..units import DEG, FPM, FT, G0, KT

# --- codes -----------------------------------------------------------------------------------
ALERT_NAMES = ("none", "preventive", "corrective", "warning")

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
    import numpy as np

    axis = np.asarray(axis)
    side = np.asarray(side)
    table = np.array([[0, 0, 0], [DIR_LEFT, 0, DIR_RIGHT], [DIR_DOWN, 0, DIR_UP], [DIR_SLOWER, 0, DIR_FASTER]])
    return table[axis, np.sign(side).astype(int) + 1]


@dataclass(frozen=True)
class DaaConfig:
    """Onboard DAA parameters (SI). Frozen; use :meth:`with_` for variants."""

    thresholds: "str | Thresholds" = "do365"  #: corrective/warning well-clear volume (preset name)
    preventive_zthr: float = 700.0 * FT  #: m, DO-365 preventive volume ZTHR
    lookahead_s: float = 180.0  #: s, DO-365B lookahead_time
    alert_time_preventive_s: float = 55.0
    alert_time_corrective_s: float = 55.0
    alert_time_warning_s: float = 25.0
    early_alert_time_preventive_s: float = 75.0  #: used only with alert hysteresis
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
    recovery_stability_s: float = 3.0  #: s, recovery candidates: exit within this of the best
    sm_horizon_s: float = 55.0  #: s, SM(u) horizon: a command is safe if no LoWC within it
    sm_margin_s: float = 30.0  #: s, SM is capped at this value (search window horizon + margin)
    resolution_axes: tuple = ("horizontal", "vertical", "speed")  #: DAA resolution axis priority

    @property
    def th(self) -> Thresholds:
        """Corrective/warning well-clear thresholds."""
        return get_thresholds(self.thresholds)

    @property
    def th_preventive(self) -> Thresholds:
        """Preventive volume: the corrective one with ZTHR = max(ZTHR, preventive_zthr)."""
        th = self.th
        return th.with_(name=th.name + "-preventive", zthr=max(th.zthr, self.preventive_zthr))

    def performance(self) -> Performance:
        """The ownship :class:`~daa_sil.kinematics.Performance` these bands assume."""
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


DEFAULT_CONFIG = DaaConfig()
