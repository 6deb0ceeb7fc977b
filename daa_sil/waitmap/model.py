"""MDP parameters and the intruder motion model (paper Table 1) with turn-rate conditioning.

Intruder motion per step (paper Sec. II): with probability ``p_horizontal`` the intruder makes a
horizontal maneuver, a (speed change, turn rate) pair with probability ``P(dv) P(dtheta)``;
otherwise a vertical maneuver ``dvh`` with probability ``P(dvh)``. Rates are per second and are
applied over ``dt``.

**Conditioning a map on an initial turn rate** omega0 (our reading; the paper only says maps are
built "by changing the intruder initial conditions"): the MDP state has no turn rate, so a map for
omega0 uses the turn-rate distribution

    P_omega0(dtheta) = turn_persistence * [dtheta == omega0] + (1 - turn_persistence) * P_table1(dtheta)

at every step: the intruder keeps its current turn with probability ``turn_persistence`` (default
0.8, i.e. it is still turning at omega0 with probability 0.84 in any one step), else redraws from
Table 1. Table 1 is symmetric, so the omega0 and -omega0 maps are mirror images across the ownship
track and the omega0 = 0 map is symmetric. ``turn_persistence = 0`` gives the unconditioned Table 1 map.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass, field, replace

import numpy as np

from daa_sil.config.settings import STEP
from ..errors import UsageError
from daa_sil.geometry.thresholds import PRESETS, Thresholds, get_thresholds

DEG = np.pi / 180.0

#: paper Table 1: (value, probability); dvh and dv in m/s^2, turn rate in deg/s
TABLE1_DVH = ((-5.0, 0.15), (-3.0, 0.20), (0.0, 0.30), (3.0, 0.20), (5.0, 0.15))
TABLE1_DV = ((-10.0, 0.10), (-5.0, 0.15), (-2.5, 0.15), (0.0, 0.20), (2.5, 0.15), (5.0, 0.15), (10.0, 0.10))
TABLE1_TURN = ((-5.0, 0.20), (-2.5, 0.20), (0.0, 0.20), (2.5, 0.20), (5.0, 0.20))

#: the wait-time definitions a map can store (see :mod:`.solve`)
WAIT_DEFINITIONS = ("paper", "until_evade")

#: the initial turn rates (deg/s, + = left) the paper's figures vary
PAPER_TURN_RATES = (-5.0, -2.5, 0.0, 2.5, 5.0)


@dataclass(frozen=True)
class MdpParams:
    """Everything (besides the grid) that determines a wait map. SI units, rates per second."""

    preset: str = "paper"  #: threshold preset for LoWC (``paper`` or ``do365``)
    v_own: float = 55.0  #: ownship ground speed along +X, m/s
    dt: float = STEP.default  #: MDP step, s
    c1: float = 1220.0  #: reward weight on 1/HMD, m
    c2: float = 122.0  #: reward weight on 1/|d_h|, m
    c3: float = 1.0  #: wait bonus per second
    sep_floor: float = 1.0  #: HMD and |d_h| are floored at this (m) before dividing
    hmd_lookahead: "float | None" = None  #: look-ahead of the reward's HMD, s; None = the preset's tau_mod*
    gamma: float = 0.95  #: discount factor
    epsilon: float = 1e-3  #: value-iteration tolerance: stop when ||V' - V||_inf < eps (1 - g) / (2 g)
    max_iter: int = 20000  #: hard cap on sweeps (reported as not converged if reached)
    lowc_value: "float | None" = None  #: terminal value of LoWC; None = -c3 dt / (1 - gamma)
    exit_value: float = 0.0  #: terminal value of EXIT (intruder left the box)
    horizon: float = 60.0  #: wait-time truncation H, s
    #: which wait time the map stores (:data:`WAIT_DEFINITIONS`): ``paper`` = E[T_LoWC | LoWC within H]
    #: under the waiting chain (paper Sec. II), ``until_evade`` = E[min(T_LoWC or evade-optimal, H)]
    wait_definition: str = "paper"
    #: LoWC-probability floor: a state with P(LoWC within H) < p_min is no threat and gets W = H
    p_min: float = 1e-3
    p_horizontal: float = 0.5  #: probability that a step is a horizontal (vs vertical) maneuver
    turn_persistence: float = 0.8  #: probability of keeping the conditioned turn rate each step
    dvh: tuple = TABLE1_DVH
    dv: tuple = TABLE1_DV
    turn: tuple = TABLE1_TURN

    def __post_init__(self):
        if self.wait_definition not in WAIT_DEFINITIONS:
            raise UsageError(f"unknown wait definition {self.wait_definition!r}; allowed: {', '.join(WAIT_DEFINITIONS)}")
        if self.preset not in PRESETS:
            raise UsageError(f"unknown threshold preset {self.preset!r}; allowed: {', '.join(PRESETS)}")
        checks = [("gamma", 0.0 < self.gamma < 1.0, "in (0, 1)"), ("dt", self.dt > 0, "> 0"),
                  ("v_own", self.v_own >= 0, ">= 0"), ("epsilon", self.epsilon > 0, "> 0"),
                  ("horizon", self.horizon >= self.dt, ">= dt"), ("sep_floor", self.sep_floor > 0, "> 0"),
                  ("p_horizontal", 0.0 <= self.p_horizontal <= 1.0, "in [0, 1]"),
                  ("turn_persistence", 0.0 <= self.turn_persistence <= 1.0, "in [0, 1]"),
                  ("p_min", 0.0 < self.p_min < 1.0, "in (0, 1)"),
                  ("c1", self.c1 >= 0, ">= 0"), ("c2", self.c2 >= 0, ">= 0"), ("max_iter", self.max_iter >= 1, ">= 1")]
        for name, ok, allowed in checks:
            if not ok:
                raise UsageError(f"wait-map parameter {name} must be {allowed}, got {getattr(self, name)!r}")
        for name in ("dvh", "dv", "turn"):
            probs = np.array([p for _, p in getattr(self, name)], float)
            if np.any(probs < 0) or not np.isclose(probs.sum(), 1.0, atol=1e-9):
                raise UsageError(f"wait-map motion table {name} probabilities must be >= 0 and sum to 1")

    @property
    def thresholds(self) -> Thresholds:
        return get_thresholds(self.preset)

    @property
    def lowc_terminal(self) -> float:
        """Terminal value of the LoWC state (default: forfeits the whole discounted wait bonus)."""
        if self.lowc_value is not None:
            return float(self.lowc_value)
        return -self.c3 * self.dt / (1.0 - self.gamma)

    @property
    def hmd_horizon(self) -> float:
        """Look-ahead (s) of the HMD in the reward (DAIDALUS ``hmd(s, v, T)``)."""
        return self.thresholds.tthr if self.hmd_lookahead is None else float(self.hmd_lookahead)

    @property
    def n_horizon(self) -> int:
        """H in steps."""
        return int(np.ceil(self.horizon / self.dt - 1e-9))

    def with_(self, **changes) -> "MdpParams":
        return replace(self, **changes)

    def to_dict(self) -> dict:
        d = asdict(self)
        for k in ("dvh", "dv", "turn"):
            d[k] = [list(map(float, vp)) for vp in d[k]]
        d["thresholds"] = self.thresholds.to_dict()
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "MdpParams":
        d = {k: v for k, v in d.items() if k in cls.__dataclass_fields__}
        for k in ("dvh", "dv", "turn"):
            if k in d:
                d[k] = tuple(tuple(map(float, vp)) for vp in d[k])
        return cls(**d)


def turn_distribution(params: MdpParams, turn_rate_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """Turn-rate support (rad/s, + = left) and probabilities for a map conditioned on ``turn_rate_deg``."""
    vals = [v for v, _ in params.turn]
    probs = [(1.0 - params.turn_persistence) * p for _, p in params.turn]
    if turn_rate_deg in vals:
        probs[vals.index(turn_rate_deg)] += params.turn_persistence
    else:
        vals.append(float(turn_rate_deg))
        probs.append(params.turn_persistence)
    return np.array(vals) * DEG, np.array(probs)


@dataclass(frozen=True)
class Outcome:
    """The intruder maneuver outcomes of one step: changes (SI, per step) and probabilities."""

    dvi: np.ndarray  #: speed change over dt, m/s
    dtheta: np.ndarray  #: heading change over dt, rad
    dvh: np.ndarray  #: vertical-rate change over dt, m/s
    prob: np.ndarray = field(repr=False)


def outcomes(params: MdpParams, turn_rate_deg: float) -> Outcome:
    """All (horizontal pair or vertical) maneuver outcomes of one step; probabilities sum to 1."""
    dt = params.dt
    tv, tp = turn_distribution(params, turn_rate_deg)
    dv = np.array([v for v, _ in params.dv]) * dt
    pv = np.array([p for _, p in params.dv])
    hv, ht = np.meshgrid(dv, tv * dt, indexing="ij")
    hp = params.p_horizontal * np.outer(pv, tp)
    vv = np.array([v for v, _ in params.dvh]) * dt
    vp = (1.0 - params.p_horizontal) * np.array([p for _, p in params.dvh])
    return Outcome(dvi=np.concatenate([hv.ravel(), np.zeros(vv.size)]),
                   dtheta=np.concatenate([ht.ravel(), np.zeros(vv.size)]),
                   dvh=np.concatenate([np.zeros(hv.size), vv]),
                   prob=np.concatenate([hp.ravel(), vp]))


#: the wait-map file format (:mod:`daa_sil.waitmap.store` writes and checks it); part of every
#: settings hash, so a format change invalidates cached maps. Defined here, below the store, because
#: the hash needs it.
FORMAT_VERSION = "daa-sil-waitmap/2"


def params_hash(grid_dict: dict, params: MdpParams, turn_rates) -> str:
    """Content hash (hex) of everything that determines a family of maps."""
    return settings_hash(grid_dict["axes"], params.to_dict(), turn_rates)


def settings_hash(grid_axes, params_dict: dict, turn_rates) -> str:
    """:func:`params_hash` from the plain forms a map file's metadata stores (``grid.axes``,
    ``params``), so that a family index can be checked against its maps' metadata."""
    blob = json.dumps({"grid": grid_axes, "params": params_dict,
                       "turn_rates": [float(t) for t in turn_rates], "format": FORMAT_VERSION},
                      sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()
