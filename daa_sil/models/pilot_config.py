"""The remote-pilot model's parameters and data types: :class:`PilotConfig` (response-time model,
decision rules), :class:`Guidance` (what the pilot's display shows, per plane) and
:class:`PilotOutput` (commands and their intent)."""

from __future__ import annotations

from dataclasses import dataclass, field, fields

import numpy as np

from daa_sil.config.choices import PILOT_STOPS
from daa_sil.errors import UsageError
from daa_sil.geometry.kinematics import Command

MODES = ("guendel", "no_atc", "nasa_rayleigh5", "fixed", "deterministic")


AXIS_NAMES = ("none", "horizontal", "vertical")


DIR_NAMES = ("none", "left", "right", "up", "down")


NO_BAND = np.inf  #: level of a missing candidate


@dataclass(frozen=True)
class PilotConfig:
    """Pilot-model parameters (Guendel Release 6.1 defaults). Times s, angles deg, altitudes ft."""

    mode: str = "guendel"
    alert_level_min: int = 2  #: DAIDALUS level that starts streaming (2 = corrective, the agent's active phase)
    alert_hold_s: float = 0.0  #: the alert must persist this long before streaming starts
    #: before the pilot first engages, stream "hold" (the seen track/vs/gs) while the alert level is at
    #: least this (None = only from ``alert_level_min``; 0 = from the first telemetry: the reading
    #: "the model captures pilot response from the beginning of an encounter")
    stream_level_min: "int | None" = None
    stream_hold: bool = True  #: the GCS sends "hold" as a pilot command (False: only maneuvers)
    #: when streaming ends (:data:`daa_sil.config.choices.PILOT_STOPS`): ``alert`` -- when the alert
    #: clears (a "hold" streamed from ``stream_level_min`` runs on while that level holds);
    #: ``safe-avoidance`` -- one command per step until the pilot's display shows safe avoidance (no
    #: alert, every intruder past its closest point of approach), see :mod:`daa_sil.models.pilot`
    stream_until: str = "alert"
    init_mean_s: float = 5.0
    coord_k: float = 5.5
    coord_theta_s: float = 2.0
    exec_mean_s: float = 3.0
    rayleigh_sigma_s: float = 3.989
    fixed_init_s: float = 5.0
    fixed_coord_s: float = 11.0
    fixed_exec_s: float = 3.0
    update_min_s: tuple = (12.0, 12.0, 9.0, 6.0, 6.0, 0.0)  #: by pilot level none..WCV
    update_mean_s: tuple = (12.0, 12.0, 6.0, 3.0, 3.0, 3.0)  #: mean of the Exp extra
    prob_turn: float = 0.65
    prob_follow_min_dev: float = 0.8
    max_relative_hdg_deg: float = 40.0
    prob_left: float = 0.6
    prob_descend: float = 0.5
    turn_primary: tuple = (6.21, 9.67, 30.0)  #: Gamma shape, scale (deg), offset (deg)
    turn_opposite: tuple = (5.47, 8.25, 30.0)
    vertical: tuple = (9.73, 207.98, 1500.0)  #: Gamma shape, scale (ft), offset (ft)
    det_turn_primary_deg: float = 30.0
    det_turn_opposite_deg: float = 15.0
    det_vertical_ft: float = 500.0
    heading_round_deg: float = 5.0
    max_turn_deg: float = 175.0
    recover: bool = True  #: return to the flight plan after the conflict (needs a plan, see PilotModel)
    recover_vs_fpm: float = 500.0  #: climb/descent rate back to the plan altitude (Guendel desired rate)
    recover_capture_s: float = 15.0  #: s, altitude capture time constant (vs = dz / this, limited)
    recover_alt_tol_m: float = 15.0  #: plan altitude reached within this (m): level off
    recover_trk_tol_deg: float = 1.0  #: plan track reached within this (deg)

    def validate(self) -> "PilotConfig":
        if self.mode not in MODES:
            raise UsageError(f"pilot mode must be one of {', '.join(MODES)}, got {self.mode!r}")
        if self.stream_until not in PILOT_STOPS:
            raise UsageError(f"pilot stream_until must be one of {', '.join(PILOT_STOPS)}, got {self.stream_until!r}")
        for name in ("prob_turn", "prob_follow_min_dev", "prob_left", "prob_descend"):
            v = getattr(self, name)
            if not 0.0 <= v <= 1.0:
                raise UsageError(f"pilot {name} must be within [0, 1], got {v!r}")
        if len(self.update_min_s) != 6 or len(self.update_mean_s) != 6:
            raise UsageError("pilot update_min_s / update_mean_s need 6 values (levels none..WCV)")
        if self.stream_level_min is not None and not 0 <= self.stream_level_min <= self.alert_level_min:
            raise UsageError(f"pilot stream_level_min must be within [0, alert_level_min={self.alert_level_min}], "
                             f"got {self.stream_level_min!r}")
        if self.alert_hold_s < 0 or self.heading_round_deg < 0:
            raise UsageError("pilot alert_hold_s and heading_round_deg must be >= 0")
        for name in ("recover_vs_fpm", "recover_capture_s", "recover_alt_tol_m", "recover_trk_tol_deg"):
            if not getattr(self, name) > 0:
                raise UsageError(f"pilot {name} must be > 0, got {getattr(self, name)!r}")
        return self

    @property
    def deterministic(self) -> bool:
        return self.mode == "deterministic"


@dataclass
class Guidance:
    """What the pilot's display shows, per encounter (N,) arrays.

    ``alert_level``: DAIDALUS level (0 none, 1 preventive, 2 corrective, 3 warning), max over
    intruders; ``wcv``: well clear violated. Candidates: ``left_trk``/``right_trk`` (compass rad)
    the closest track reached by turning left/right that has the lowest band level reachable that
    way, ``up_vs``/``down_vs`` (m/s) likewise; ``*_level`` the band level there (0 clear,
    1 recovery, 2 far/preventive, 3 mid/corrective, 4 near/warning; inf or nan = no candidate).
    """

    alert_level: np.ndarray
    left_trk: np.ndarray
    left_level: np.ndarray
    right_trk: np.ndarray
    right_level: np.ndarray
    up_vs: np.ndarray
    up_level: np.ndarray
    down_vs: np.ndarray
    down_level: np.ndarray
    wcv: np.ndarray = field(default_factory=lambda: np.array(False))

    def __post_init__(self):
        names = ("alert_level", "left_trk", "left_level", "right_trk", "right_level", "up_vs", "up_level",
                 "down_vs", "down_level", "wcv")
        vals = [np.asarray(getattr(self, k), float) for k in names]
        shape = vals[0].shape
        if any(a.shape != shape for a in vals):  # (one shape, the usual case: no broadcast needed)
            vals = np.broadcast_arrays(*vals)
        for k, a in zip(names, vals):
            setattr(self, k, np.array(a))  # own copies
        self.alert_level = np.nan_to_num(self.alert_level, nan=0.0).astype(np.int64)
        self.wcv = self.wcv.astype(bool)
        for k in ("left_level", "right_level", "up_level", "down_level"):
            a = getattr(self, k)
            setattr(self, k, np.where(np.isnan(a), NO_BAND, a))

    def copy(self) -> "Guidance":
        """An independent copy (its fields are already normalised: no second pass)."""
        out = object.__new__(type(self))
        out.__dict__.update({f.name: getattr(self, f.name).copy() for f in fields(self)})
        return out


@dataclass
class PilotOutput:
    """One step of N pilots: ``send`` (N,) bool; ``cmd`` (nan where not sending); ``seq`` (N,)
    int64 sequence number of the sent command (-1 if none); ``axis``/``direction`` codes into
    :data:`AXIS_NAMES`/:data:`DIR_NAMES` (0 for hold); ``maneuver`` (N,) number of maneuvers sent
    so far (0 = still holding); ``t_sent`` s."""

    send: np.ndarray
    cmd: Command
    seq: np.ndarray
    axis: np.ndarray
    direction: np.ndarray
    maneuver: np.ndarray
    t_sent: float

    def axis_names(self) -> np.ndarray:
        return np.asarray(AXIS_NAMES, dtype=object)[self.axis]

    def direction_names(self) -> np.ndarray:
        return np.asarray(DIR_NAMES, dtype=object)[self.direction]
