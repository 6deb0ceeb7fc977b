"""Remote-pilot model (after Guendel et al. 2017, simplified as ``docs/models.md`` describes), batched.

One :class:`PilotModel` steps N pilots (one per encounter) at 1 Hz with the GCS's view: the
ownship state it sees (downlink-delayed telemetry) and the DAA guidance computed from that view
(:class:`Guidance`). The link delay is *not* in here; the caller delays what the pilot sees and
what it sends.

Streaming (``docs/architecture.md``): from the step the pilot sees an alert (DAIDALUS level >=
``alert_level_min``, held ``alert_hold_s``) it sends one command per step until the alert clears:
first "hold" (track/vs/gs of the telemetry seen at alert onset), then its maneuver, replaced at
each follow-up decision. Two readings of the paper's simulator are options (``daa_sil.config.readings``):
``stream_hold=False`` sends no "hold" (only maneuvers and the return to plan), and
``stream_level_min`` < ``alert_level_min`` streams "hold" of the seen state from a lower alert level
(0: from the first telemetry) until the pilot first engages. Timeline of the first engagement: response delay
``T_p = T_init + T_coord + T_exec`` drawn at the trigger; the maneuver is *decided* at
``t_trigger + T_p - T_exec`` from the guidance seen then and *sent* from ``t_trigger + T_p``.
Follow-ups: ``min[L] + extra[L]`` s after a maneuver is sent (``L`` = pilot alert level =
DAIDALUS level + 1, 5 for a well-clear violation) a new decision is made, sent after a fresh
execution delay. If the alert clears and returns, the (already engaged) pilot streams hold again
and re-decides immediately, sending after a fresh execution delay.

Return to plan (``PilotConfig.recover``, needs ``plan``): when the alert clears, an engaged pilot
that was climbing or descending levels off at once (one command: its track and speed, vs 0), then
waits its follow-up decision time at the cleared level (``min[L] + extra[L]``, 12 + Exp(12) s at
level none) and then streams the plan's track and ground speed with a vertical speed toward the
plan altitude (``dz / recover_capture_s``, at most 500 fpm, Guendel's desired vertical rate), from
the delayed state it sees -- only while its display shows that way back clear of every intruder
(the command's safety metric is positive; needs the observed intruders) -- until it sees the plan
altitude and track reached; it then sends the
plan (level flight) once. Without it a vertical maneuver commanded as a vertical speed would never
end (the paper's Fig. 8: the UAS "regains the altitude" and returns toward its original path).

Response modes (``PilotConfig.mode``):

* ``guendel``  T_init ~ Exp(5 s), T_coord ~ Gamma(5.5, 2 s), T_exec ~ Exp(3 s) (mean 19 s);
* ``no_atc``   as guendel without T_coord (mean 8 s);
* ``nasa_rayleigh5``  first response ~ Rayleigh(sigma = 3.989 s) (mean 5 s), decided and sent at
  once (T_exec = 0); follow-up execution delays Exp(3 s);
* ``fixed``    constant delays ``fixed_init_s + fixed_coord_s + fixed_exec_s`` (5 + 11 + 3 = 19 s),
  stochastic maneuver choice;
* ``deterministic``  fixed 5 + 11 + 3 s, follow-ups at ``min + mean`` s, always the
  minimum-deviation direction (ties: left / climb), prefers turns, magnitudes +30 deg (primary),
  +15 deg (opposite), +500 ft (vertical). For regression tests.

Maneuver choice (models.md §1.3), per plane: the two candidate directions (closest band-free
track to the left/right, closest vertical speed up/down) carry the band level they reach (lower
is better, 0 = clear, 1 = recovery; 0 and 1 count as equal). A strictly better level wins;
otherwise the smaller deviation with probability 0.8 (always if the deviations differ by more than
40 deg), exact ties left with p 0.6 / descend with p 0.5. A turn is chosen iff (prefer turn, p =
``prob_turn``, and turn level <= vertical level) or (not prefer turn and turn level < vertical
level). Turn magnitude: ``min_dev + delta``, delta ~ Gamma(6.21, 9.67 deg) - 30 deg in the
minimum-deviation direction, Gamma(5.47, 8.25 deg) - 30 deg opposite; a draw that would reverse
the turn is clamped back to the minimum deviation; total turn at most 175 deg (so the short-way
turn keeps the direction); track rounded to 5 deg (never across the current track). Vertical: the
suggested vertical speed plus delta, delta ~ Gamma(9.73, 207.98 ft) - 1500 ft read as **fpm**
(our reading: Guendel commands altitudes 500 ft beyond the suggestion flown at 500 fpm; we command
vertical speed, so the altitude overshoot in ft becomes a vertical-speed overshoot in fpm, 1:1),
never reversing the direction.

Randomness: every encounter has its own generator (``seeds``); at construction it draws, in this
order, the response components (T_init, T_coord, T_exec, Rayleigh) and then blocks of
``_K`` per-decision values (see :func:`_draw_block`), so the stream does not depend on N or on
other encounters.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Sequence

import numpy as np

from daa_sil.errors import UsageError
from daa_sil.geometry.frames import wrap_2pi, wrap_pi
from daa_sil.geometry.kinematics import AircraftState, Command
from daa_sil.geometry.units import DEG, FPM

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
        arrs = np.broadcast_arrays(*(np.asarray(getattr(self, k), float) for k in names))
        for k, a in zip(names, arrs):
            setattr(self, k, np.array(a))
        self.alert_level = np.nan_to_num(self.alert_level, nan=0.0).astype(np.int64)
        self.wcv = self.wcv.astype(bool)
        for k in ("left_level", "right_level", "up_level", "down_level"):
            a = getattr(self, k)
            setattr(self, k, np.where(np.isnan(a), NO_BAND, a))


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


# --------------------------------------------------------------------------------------------------
def sample_response_components(rng: np.random.Generator, size, cfg: PilotConfig) -> dict:
    """Response-delay components (s) for ``size`` draws from one generator, in the fixed order
    T_init, T_coord, T_exec, Rayleigh: ``{"init", "coord", "exec", "rayleigh"}``."""
    return {"init": rng.exponential(cfg.init_mean_s, size), "coord": rng.gamma(cfg.coord_k, cfg.coord_theta_s, size),
            "exec": rng.exponential(cfg.exec_mean_s, size), "rayleigh": rng.rayleigh(cfg.rayleigh_sigma_s, size)}


_K = 32
_BLOCK_KEYS = ("exec", "update", "u_turn", "u_follow_h", "u_tie_h", "u_follow_v", "u_tie_v", "g_primary",
               "g_opposite", "g_vertical")


def _draw_block(rng: np.random.Generator, cfg: PilotConfig, k: int = _K) -> dict:
    """Per-decision draws for ``k`` decisions (fixed order: :data:`_BLOCK_KEYS`). ``update`` is
    a unit-mean exponential scaled by the level's mean at use; gammas are in deg / ft with the
    offset already subtracted."""
    return {"exec": rng.exponential(cfg.exec_mean_s, k), "update": rng.exponential(1.0, k),
            "u_turn": rng.random(k), "u_follow_h": rng.random(k), "u_tie_h": rng.random(k),
            "u_follow_v": rng.random(k), "u_tie_v": rng.random(k),
            "g_primary": rng.gamma(cfg.turn_primary[0], cfg.turn_primary[1], k) - cfg.turn_primary[2],
            "g_opposite": rng.gamma(cfg.turn_opposite[0], cfg.turn_opposite[1], k) - cfg.turn_opposite[2],
            "g_vertical": rng.gamma(cfg.vertical[0], cfg.vertical[1], k) - cfg.vertical[2]}


def _as_rng(s) -> np.random.Generator:
    if isinstance(s, np.random.Generator):
        return s
    if isinstance(s, np.random.SeedSequence):
        return np.random.Generator(np.random.PCG64(s))
    try:
        v = int(s)
    except (TypeError, ValueError):
        raise UsageError(f"pilot seed must be a non-negative int, SeedSequence or Generator, got {s!r}") from None
    if v < 0:
        raise UsageError(f"pilot seed must be a non-negative int, got {s!r}")
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence(v)))


def choose_maneuver(cur_trk, cur_vs, cur_gs, g: Guidance, draws: dict, cfg: PilotConfig
                    ) -> tuple[Command, np.ndarray, np.ndarray]:
    """The maneuver decided from guidance ``g`` (all (n,) arrays; ``draws`` one value per pilot of
    each :data:`_BLOCK_KEYS` entry). Returns ``(cmd, axis, direction)`` codes; axis 0 (hold the
    current state) when no candidate exists. Pure and vectorised."""
    det = cfg.deterministic
    cur_trk, cur_vs, cur_gs = (np.asarray(a, float) for a in (cur_trk, cur_vs, cur_gs))
    merge = lambda lv: np.where(lv <= 1, 0.0, lv)  # noqa: E731 - clear and recovery count equal
    lL, lR, lU, lD = merge(g.left_level), merge(g.right_level), merge(g.up_level), merge(g.down_level)
    lL = np.where(np.isnan(g.left_trk), NO_BAND, lL)
    lR = np.where(np.isnan(g.right_trk), NO_BAND, lR)
    lU = np.where(np.isnan(g.up_vs), NO_BAND, lU)
    lD = np.where(np.isnan(g.down_vs), NO_BAND, lD)
    aL = np.nan_to_num(wrap_2pi(cur_trk - g.left_trk), nan=np.inf)
    aR = np.nan_to_num(wrap_2pi(g.right_trk - cur_trk), nan=np.inf)
    dU = np.nan_to_num(np.abs(g.up_vs - cur_vs), nan=np.inf)
    dD = np.nan_to_num(np.abs(cur_vs - g.down_vs), nan=np.inf)

    # horizontal direction: +1 right, -1 left
    mindev_h = np.where(aL < aR, -1.0, np.where(aR < aL, 1.0,
                        np.where(det | (draws["u_tie_h"] < cfg.prob_left), -1.0, 1.0)))
    far = np.abs(aL - aR) > cfg.max_relative_hdg_deg * DEG
    follow = det | far | (draws["u_follow_h"] < cfg.prob_follow_min_dev)
    same_h = np.where(follow, mindev_h, -mindev_h)
    h_dir = np.where(lL < lR, -1.0, np.where(lR < lL, 1.0, same_h))
    primary = h_dir == mindev_h
    h_min = np.where(h_dir < 0, aL, aR)
    h_lvl = np.where(h_dir < 0, lL, lR)
    # vertical direction: +1 up, -1 down
    mindev_v = np.where(dU < dD, 1.0, np.where(dD < dU, -1.0,
                        np.where(det | (draws["u_tie_v"] >= cfg.prob_descend), 1.0, -1.0)))
    follow_v = det | (draws["u_follow_v"] < cfg.prob_follow_min_dev)
    same_v = np.where(follow_v, mindev_v, -mindev_v)
    v_dir = np.where(lU < lD, 1.0, np.where(lD < lU, -1.0, same_v))
    v_sugg = np.where(v_dir > 0, g.up_vs, g.down_vs)
    v_lvl = np.where(v_dir > 0, lU, lD)
    # plane
    prefer_turn = det | (draws["u_turn"] < cfg.prob_turn)
    turn = (prefer_turn & (h_lvl <= v_lvl)) | (~prefer_turn & (h_lvl < v_lvl))
    none = ~np.isfinite(h_lvl) & ~np.isfinite(v_lvl)

    # turn magnitude
    if det:
        delta = np.where(primary, cfg.det_turn_primary_deg, cfg.det_turn_opposite_deg) * DEG
    else:
        delta = np.where(primary, draws["g_primary"], draws["g_opposite"]) * DEG
    h_min_f = np.where(np.isfinite(h_min), h_min, 0.0)
    mag = h_min_f + delta
    mag = np.where(mag < 0.0, h_min_f, mag)
    mag = np.minimum(mag, cfg.max_turn_deg * DEG)
    trk = cur_trk + h_dir * mag
    if cfg.heading_round_deg > 0:
        q = cfg.heading_round_deg * DEG
        r = np.round(trk / q) * q
        # rounding must not turn the command across the current track (or below zero turn)
        away = np.where(h_dir > 0, np.ceil(trk / q), np.floor(trk / q)) * q
        r = np.where(h_dir * wrap_pi(r - cur_trk) < 0, away, r)
        trk = r
    trk = wrap_2pi(trk)
    # vertical magnitude (ft overshoot read as fpm)
    dv = (cfg.det_vertical_ft if det else draws["g_vertical"]) * FPM
    v_sugg_f = np.where(np.isfinite(v_sugg), v_sugg, cur_vs)
    vs = v_sugg_f + v_dir * dv
    vs = np.where(v_dir * (vs - cur_vs) < 0, v_sugg_f, vs)

    cmd_trk = np.where(none, cur_trk, np.where(turn, trk, cur_trk))
    cmd_vs = np.where(none, cur_vs, np.where(turn, cur_vs, vs))
    axis = np.where(none, 0, np.where(turn, 1, 2)).astype(np.int64)
    direction = np.where(none, 0, np.where(turn, np.where(h_dir < 0, 1, 2), np.where(v_dir > 0, 3, 4))).astype(np.int64)
    return Command(cmd_trk, cmd_vs, cur_gs.copy()), axis, direction


# --------------------------------------------------------------------------------------------------
class PilotModel:
    """N remote pilots stepped together at 1 Hz (see the module docstring).

    ``seeds``: N ints / SeedSequences / Generators, the pilot stream of each encounter (the caller
    picks the stream, e.g. a child of the encounter seed). ``step`` must be called with
    non-decreasing ``t``.
    """

    def __init__(self, n: int, seeds: "Sequence | None" = None, cfg: "PilotConfig | None" = None,
                 plan: "AircraftState | None" = None, daa_cfg=None):
        self.cfg = (cfg or PilotConfig()).validate()
        if not isinstance(n, (int, np.integer)) or n < 1:
            raise UsageError(f"number of pilots must be a positive integer, got {n!r}")
        self.n = int(n)
        if seeds is None:
            if not self.cfg.deterministic:
                raise UsageError(f"pilot mode {self.cfg.mode!r} needs seeds (one per encounter)")
            seeds = list(range(self.n))
        seeds = list(seeds) if not isinstance(seeds, (int, np.integer)) else [seeds]
        if len(seeds) != self.n:
            raise UsageError(f"pilot model needs {self.n} seeds, got {len(seeds)}")
        self._rngs = [_as_rng(s) for s in seeds]
        c = self.cfg
        comps = [sample_response_components(r, None, c) for r in self._rngs]
        first = {k: np.array([d[k] for d in comps], float) for k in ("init", "coord", "exec", "rayleigh")}
        blocks = [_draw_block(r, c) for r in self._rngs]
        self._buf = {k: np.stack([b[k] for b in blocks]) for k in _BLOCK_KEYS}
        if c.mode == "guendel":
            self._resp, self._exec0 = first["init"] + first["coord"] + first["exec"], first["exec"]
        elif c.mode == "no_atc":
            self._resp, self._exec0 = first["init"] + first["exec"], first["exec"]
        elif c.mode == "nasa_rayleigh5":
            self._resp, self._exec0 = first["rayleigh"], np.zeros(self.n)
        else:
            tot = c.fixed_init_s + c.fixed_coord_s + c.fixed_exec_s
            self._resp, self._exec0 = np.full(self.n, tot), np.full(self.n, c.fixed_exec_s)
        n = self.n
        self.engaged = np.zeros(n, bool)
        self.streaming = np.zeros(n, bool)
        self.holding = np.zeros(n, bool)  #: streaming "hold" (no maneuver sent since streaming started)
        self.alert_since = np.full(n, np.nan)
        self.t_trigger = np.full(n, np.nan)
        self.t_decide = np.full(n, np.inf)
        self.t_activate = np.full(n, np.inf)
        self.exec_next = np.zeros(n)
        self.k_dec = np.zeros(n, np.int64)
        self.cmd = Command(np.full(n, np.nan), np.full(n, np.nan), np.full(n, np.nan))
        self.pending = self.cmd.copy()
        self.axis = np.zeros(n, np.int64)
        self.direction = np.zeros(n, np.int64)
        self.p_axis = np.zeros(n, np.int64)
        self.p_dir = np.zeros(n, np.int64)
        self.maneuvers = np.zeros(n, np.int64)
        self.seq = np.full(n, -1, np.int64)
        self.level = np.zeros(n, np.int64)
        # flight plan (track rad, gs m/s, altitude m) the pilot returns to after the conflict
        if plan is not None and plan.shape != (n,):
            raise UsageError(f"pilot plan must have shape ({n},), got {plan.shape}")
        self.plan = None if plan is None else (plan.trk.astype(float).copy(), plan.gs.astype(float).copy(),
                                               plan.z.astype(float).copy())
        self.recovering = np.zeros(n, bool)
        self.t_recover = np.full(n, np.inf)
        self.daa_cfg = daa_cfg  #: DaaConfig of the display the pilot reads (checks the way back is clear)

    @property
    def response_delay_s(self) -> np.ndarray:
        """(N,) total first-response delay T_p (s) drawn for each pilot."""
        return self._resp.copy()

    def _draws(self, idx: np.ndarray) -> dict:
        need = self.k_dec[idx].max(initial=-1) + 1
        while need > self._buf["exec"].shape[1]:
            more = [_draw_block(self._rngs[i], self.cfg) for i in range(self.n)]
            for k in _BLOCK_KEYS:
                self._buf[k] = np.concatenate([self._buf[k], np.stack([b[k] for b in more])], axis=1)
        return {k: self._buf[k][idx, self.k_dec[idx]] for k in _BLOCK_KEYS}

    def _schedule_next(self, idx: np.ndarray, t: float) -> None:
        c = self.cfg
        lvl = self.level[idx]
        mins = np.asarray(c.update_min_s, float)[lvl]
        means = np.asarray(c.update_mean_s, float)[lvl]
        d = self._draws(idx)
        extra = means if c.deterministic else means * d["update"]
        self.t_decide[idx] = t + mins + extra
        self.exec_next[idx] = c.fixed_exec_s if c.mode in ("fixed", "deterministic") else d["exec"]

    def step(self, t: float, observed_own: AircraftState, guidance: "Guidance | None" = None,
             observed_intr: "AircraftState | None" = None) -> PilotOutput:
        """Advance the pilots to sim time ``t`` (s) given what the GCS sees; returns the commands
        sent at ``t``. ``guidance`` (N,) from the observed state; if None it is computed with
        :func:`guidance_from_daa` from ``observed_own``/``observed_intr``."""
        c = self.cfg
        n = self.n
        own = observed_own
        if own.shape != (n,):
            raise UsageError(f"observed ownship must have shape ({n},), got {own.shape}")
        if guidance is None:
            if observed_intr is None:
                raise UsageError("pilot step needs guidance or the observed intruders to compute it")
            guidance = guidance_from_daa(own, observed_intr)
        g = guidance
        lvl_daa = np.broadcast_to(g.alert_level, (n,))
        valid = np.isfinite(own.trk)
        alert = valid & (lvl_daa >= c.alert_level_min)
        self.level = np.where(np.broadcast_to(g.wcv, (n,)), 5, np.clip(lvl_daa + 1, 0, 4)).astype(np.int64)
        self.alert_since = np.where(alert, np.where(np.isnan(self.alert_since), t, self.alert_since), np.nan)
        # stop streaming when the alert clears; an engaged pilot returns to the plan after its
        # follow-up decision time at the (cleared) level
        stop = self.streaming & ~alert
        self.streaming &= ~stop
        self.t_decide[stop] = np.inf
        self.t_activate[stop] = np.inf
        level_off = np.zeros(n, bool)
        if c.recover and self.plan is not None and stop.any():
            i = np.flatnonzero(stop)
            # clear of conflict: stop any climb / descent at once (keep track and speed), one command
            level_off[i] = np.abs(np.nan_to_num(self.cmd.vs[i])) > 0
            self.cmd.vs[i[level_off[i]]] = 0.0
            self.axis[i] = 0
            self.direction[i] = 0
            lvl = self.level[i]
            extra = np.asarray(c.update_mean_s, float)[lvl]
            if not c.deterministic:
                extra = extra * self._draws(i)["update"]
            self.t_recover[i] = t + np.asarray(c.update_min_s, float)[lvl] + extra
        # start streaming (hold) when the alert has persisted alert_hold_s
        start = alert & ~self.streaming & (t - self.alert_since >= c.alert_hold_s - 1e-9)
        if start.any():
            s = np.flatnonzero(start)
            self.cmd.trk[s], self.cmd.vs[s], self.cmd.gs[s] = own.trk[s], own.vs[s], own.gs[s]
            self.axis[s] = 0
            self.direction[s] = 0
            first = s[~self.engaged[s]]
            again = s[self.engaged[s]]
            self.t_trigger[first] = t
            self.t_decide[first] = t + self._resp[first] - self._exec0[first]
            self.exec_next[first] = self._exec0[first]
            self.engaged[first] = True
            self.t_decide[again] = t
            if again.size:
                d = self._draws(again)
                self.exec_next[again] = c.fixed_exec_s if c.mode in ("fixed", "deterministic") else d["exec"]
            self.streaming |= start
            self.holding[s] = True
            self.recovering[s] = False
            self.t_recover[s] = np.inf
        # decisions due
        dec = self.streaming & (t >= self.t_decide - 1e-9)
        if dec.any():
            i = np.flatnonzero(dec)
            sub = Guidance(*(np.broadcast_to(getattr(g, k), (n,))[i] for k in (
                "alert_level", "left_trk", "left_level", "right_trk", "right_level", "up_vs", "up_level",
                "down_vs", "down_level", "wcv")))
            cmd, ax, di = choose_maneuver(own.trk[i], own.vs[i], own.gs[i], sub, self._draws(i), c)
            self.k_dec[i] += 1
            self.pending.trk[i], self.pending.vs[i], self.pending.gs[i] = cmd.trk, cmd.vs, cmd.gs
            self.p_axis[i], self.p_dir[i] = ax, di
            self.t_activate[i] = t + self.exec_next[i]
            self.t_decide[i] = np.inf
        # maneuvers whose execution delay has passed
        act = self.streaming & (t >= self.t_activate - 1e-9)
        if act.any():
            i = np.flatnonzero(act)
            self.cmd.trk[i], self.cmd.vs[i], self.cmd.gs[i] = self.pending.trk[i], self.pending.vs[i], self.pending.gs[i]
            self.axis[i], self.direction[i] = self.p_axis[i], self.p_dir[i]
            self.holding[i] = False
            self.maneuvers[i] += 1
            self.t_activate[i] = np.inf
            self._schedule_next(i, t)
        rec = self._recovery(t, own, valid, observed_intr)
        streamed = self.streaming & (~self.holding | c.stream_hold)
        # before the first engagement: hold streamed from a lower alert level (stream_level_min)
        pre = np.zeros(n, bool)
        if c.stream_level_min is not None and c.stream_level_min < c.alert_level_min and c.stream_hold:
            pre = valid & ~self.engaged & ~self.streaming & (lvl_daa >= c.stream_level_min)
        send = streamed | rec | level_off | pre
        self.seq = np.where(send, self.seq + 1, self.seq)
        nan = np.full(n, np.nan)
        cur = Command(np.where(pre, own.trk, self.cmd.trk), np.where(pre, own.vs, self.cmd.vs),
                      np.where(pre, own.gs, self.cmd.gs))
        out = Command(np.where(send, cur.trk, nan), np.where(send, cur.vs, nan), np.where(send, cur.gs, nan))
        return PilotOutput(send=send, cmd=out, seq=np.where(send, self.seq, -1),
                           axis=np.where(send, self.axis, 0), direction=np.where(send, self.direction, 0),
                           maneuver=self.maneuvers.copy(), t_sent=float(t))

    def _recovery(self, t: float, own: AircraftState, valid: np.ndarray,
                  intr: "AircraftState | None" = None) -> np.ndarray:
        """Return-to-plan commands (the pilot flies back to the plan's track, speed and altitude after
        the conflict); updates ``self.cmd`` and returns who sends one at ``t``.

        Each step from ``t_recover`` the pilot commands the plan track and ground speed and a vertical
        speed ``dz / recover_capture_s`` limited to ``recover_vs_fpm`` toward the plan altitude, from
        the (delayed) state it sees; once the seen altitude and track are within tolerance it sends
        the plan itself (level) once and stops. With the observed intruders (``intr``) the pilot only
        turns back when its display shows the way back clear: the return command's safety metric
        (:func:`daa_sil.daa.safety_metric`, no LoWC within the corrective alerting time) is positive;
        otherwise it keeps its course and looks again next step."""
        c = self.cfg
        if self.plan is None or not c.recover:
            return np.zeros(self.n, bool)
        begin = ~self.streaming & ~self.recovering & (t >= self.t_recover - 1e-9)
        self.recovering |= begin
        self.t_recover[begin] = np.inf
        act = self.recovering & valid
        if not act.any():
            return act
        i = np.flatnonzero(act)
        p_trk, p_gs, p_z = (a[i] for a in self.plan)
        dz = p_z - own.z[i]
        rate = c.recover_vs_fpm * FPM
        done = (np.abs(dz) <= c.recover_alt_tol_m) & (np.abs(wrap_pi(own.trk[i] - p_trk)) <= c.recover_trk_tol_deg * DEG)
        vs = np.where(done, 0.0, np.clip(dz / c.recover_capture_s, -rate, rate))
        if intr is not None and intr.shape[1]:
            from daa_sil.daa import DaaConfig, safety_metric

            clear = safety_metric(own[i], intr[i], Command(p_trk, vs, p_gs), self.daa_cfg or DaaConfig()) > 0
            if not clear.all():
                act[i[~clear]] = False
                i, p_trk, p_gs, vs, done = i[clear], p_trk[clear], p_gs[clear], vs[clear], done[clear]
        self.cmd.trk[i], self.cmd.vs[i], self.cmd.gs[i] = p_trk, vs, p_gs
        self.axis[i] = 0
        self.direction[i] = 0
        self.recovering[i[done]] = False
        return act


_REGION_LEVEL = np.array([0.0, 2.0, 3.0, 4.0, 1.0])  # daa REGION_NONE, FAR, MID, NEAR, RECOVERY -> level


def _side_candidate(ax, want: int) -> tuple[np.ndarray, np.ndarray]:
    """Closest candidate (min time to reach) on side ``want`` among those with the side's lowest
    level (0/1 merged); returns (value, level) with nan/inf where the side is empty."""
    lvl = _REGION_LEVEL[np.asarray(ax.region, int)]
    merged = np.where(lvl <= 1, 0.0, lvl)
    on = (np.asarray(ax.side) == want)[None, :]
    best = np.where(on, merged, np.inf).min(axis=1)
    cost = np.where(on & (merged == best[:, None]), ax.t_man, np.inf)
    k = np.argmin(cost, axis=1)
    found = np.isfinite(np.take_along_axis(cost, k[:, None], 1)[:, 0])
    val = np.take_along_axis(ax.values, k[:, None], 1)[:, 0]
    level = np.take_along_axis(lvl, k[:, None], 1)[:, 0]
    return np.where(found, val, np.nan), np.where(found, level, NO_BAND)


def guidance_from_bands(bands) -> Guidance:
    """:class:`Guidance` from :class:`daa_sil.daa.bands.Bands` (track and vertical-speed axes)."""
    lt, ll = _side_candidate(bands.trk, -1)
    rt, rl = _side_candidate(bands.trk, +1)
    dv, dl = _side_candidate(bands.vs, -1)
    uv, ul = _side_candidate(bands.vs, +1)
    alert = np.asarray(bands.alert)
    lvl = alert.max(axis=1) if alert.ndim == 2 and alert.shape[1] else np.zeros(len(lt))
    return Guidance(alert_level=lvl, left_trk=lt, left_level=ll, right_trk=rt, right_level=rl, up_vs=uv,
                    up_level=ul, down_vs=dv, down_level=dl)


class PilotDisplay:
    """What N pilots' displays show, refreshed only for the pilots that see newer telemetry (the GCS
    of the SIL and the fast-time loop both use this, so the pilot reads the same guidance in both).

    Per pilot: the vehicle's DAIDALUS alert level sent with that telemetry, well clear violated on
    the observed states and, at or above ``alert_level_min``, the DAA bands' candidates of the
    observed states (``cfg`` a :class:`daa_sil.daa.config.DaaConfig`); below it the last bands stay.
    """

    _KEYS = ("left_trk", "left_level", "right_trk", "right_level", "up_vs", "up_level", "down_vs", "down_level")

    def __init__(self, n: int, cfg, alert_level_min: int):
        self.cfg = cfg
        self.alert_level_min = int(alert_level_min)
        self.alert = np.zeros(n, np.int64)
        self.wcv = np.zeros(n, bool)
        self.bands = {k: np.full(n, np.inf if k.endswith("_level") else np.nan) for k in self._KEYS}

    def refresh(self, rows: np.ndarray, own: AircraftState, intr: AircraftState, alert: np.ndarray) -> None:
        """Pilots ``rows`` (indices) now see ownship ``own`` (R,), intruders ``intr`` (R, M) and the
        vehicle's alert level ``alert`` (R,) sent with them."""
        from daa_sil.daa.alerting import relative_state
        from daa_sil.daa.bands import compute_bands
        from daa_sil.geometry.wellclear import wcv

        rows = np.asarray(rows, np.int64)
        if not rows.size:
            return
        alert = np.asarray(alert, np.int64)
        self.alert[rows] = alert
        self.wcv[rows] = wcv(*relative_state(own, intr), self.cfg.th).any(axis=1)
        sel = alert >= self.alert_level_min
        if sel.any():
            gb = guidance_from_bands(compute_bands(own[sel], intr[sel], self.cfg))
            for key in self._KEYS:
                self.bands[key][rows[sel]] = getattr(gb, key)

    def guidance(self) -> Guidance:
        """The current :class:`Guidance` of every pilot (N,)."""
        return Guidance(alert_level=self.alert, wcv=self.wcv, **self.bands)


def guidance_from_daa(own: AircraftState, intr: AircraftState, cfg=None) -> Guidance:
    """Compute :class:`Guidance` with :mod:`daa_sil.daa` for ownship (N,) and intruders (N, M)
    (``cfg``: a :class:`daa_sil.daa.config.DaaConfig`, default DO-365B); ``wcv`` from the preset."""
    from daa_sil.daa.bands import compute_bands
    from daa_sil.daa.alerting import relative_state
    from daa_sil.daa.config import DaaConfig
    from daa_sil.geometry.wellclear import wcv

    cfg = cfg or DaaConfig()
    g = guidance_from_bands(compute_bands(own, intr, cfg))
    s, v = relative_state(own, intr)
    g.wcv = wcv(s, v, cfg.th).any(axis=1)
    return g


__all__ = ["PilotConfig", "PilotModel", "PilotOutput", "Guidance", "PilotDisplay", "MODES", "AXIS_NAMES", "DIR_NAMES",
           "choose_maneuver", "sample_response_components", "guidance_from_daa", "guidance_from_bands"]
