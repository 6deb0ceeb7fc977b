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
(0: from the first telemetry) until the pilot first engages.

**Till safe avoidance** (``stream_until="safe-avoidance"``, the paper's "The model captures pilot
response from the beginning of an encounter till safe avoidance"): the pilot sends one command per
step -- "hold" before it engages, its maneuver while alerted, then, once the alert has cleared, the
command it is flying (level-off, the maneuver's track, or the return to plan) -- until **safe
avoidance**: the first step at which its display (the delayed telemetry it sees) shows no DAA alert
of any level *and* every intruder past its closest point of approach (the horizontal range rate,
relative position . relative velocity, is positive: the two are diverging). From then it sends
nothing until a new corrective alert restarts the stream (safe avoidance is then judged afresh);
a return to plan already under way keeps sending its commands. Safe avoidance is judged on what the
pilot sees, straight-line: an intruder seen diverging before it turns toward the ownship ends the
stream early, and its later alert restarts it. Timeline of the first engagement: response delay
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

Maneuver choice (docs/models.md, "Remote pilot"), per plane: the two candidate directions (closest band-free
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
``_K`` per-decision values (see :func:`draw_decisions`), so the stream does not depend on N or on
other encounters.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from daa_sil.errors import UsageError
from daa_sil.geometry.frames import wrap_pi
from daa_sil.geometry.kinematics import AircraftState, Command
from daa_sil.geometry.units import DEG, FPM
from daa_sil.daa.alerting import safe_avoidance
from daa_sil.models.pilot_display import guidance_from_daa
from daa_sil.models.pilot_choice import DRAW_KEYS, as_generator, draw_decisions, choose_maneuver, sample_response_components
from daa_sil.models.pilot_config import Guidance, PilotConfig, PilotOutput
from daa_sil.daa import DaaConfig, safety_metric


# --------------------------------------------------------------------------------------------------


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
        self._rngs = [as_generator(s) for s in seeds]
        c = self.cfg
        comps = [sample_response_components(r, None, c) for r in self._rngs]
        first = {k: np.array([d[k] for d in comps], float) for k in ("init", "coord", "exec", "rayleigh")}
        blocks = [draw_decisions(r, c) for r in self._rngs]
        self._buf = {k: np.stack([b[k] for b in blocks]) for k in DRAW_KEYS}
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
        self.safe = np.zeros(n, bool)  #: safe avoidance seen since the stream last (re)started
        self.t_safe = np.full(n, np.nan)  #: when (s; nan = not yet)
        self.daa_cfg = daa_cfg  #: DaaConfig of the display the pilot reads (checks the way back is clear)

    @property
    def response_delay_s(self) -> np.ndarray:
        """(N,) total first-response delay T_p (s) drawn for each pilot."""
        return self._resp.copy()

    def _draws(self, idx: np.ndarray) -> dict:
        need = self.k_dec[idx].max(initial=-1) + 1
        while need > self._buf["exec"].shape[1]:
            more = [draw_decisions(self._rngs[i], self.cfg) for i in range(self.n)]
            for k in DRAW_KEYS:
                self._buf[k] = np.concatenate([self._buf[k], np.stack([b[k] for b in more])], axis=1)
        return {k: self._buf[k][idx, self.k_dec[idx]] for k in DRAW_KEYS}

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
            self.safe[s] = False
            self.t_safe[s] = np.nan
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
        post = np.zeros(n, bool)
        if c.stream_until == "safe-avoidance":
            now = ~self.safe & ~self.streaming & safe_avoidance(own, observed_intr, lvl_daa)
            self.safe |= now
            self.t_safe[now] = t
            pre &= ~self.safe
            # an engaged pilot whose alert cleared keeps sending the command it flies until safe avoidance
            post = valid & self.engaged & ~self.streaming & ~self.safe & ~rec & ~level_off
        send = streamed | rec | level_off | pre | post
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
            clear = safety_metric(own[i], intr[i], Command(p_trk, vs, p_gs), self.daa_cfg or DaaConfig()) > 0
            if not clear.all():
                act[i[~clear]] = False
                i, p_trk, p_gs, vs, done = i[clear], p_trk[clear], p_gs[clear], vs[clear], done[clear]
        self.cmd.trk[i], self.cmd.vs[i], self.cmd.gs[i] = p_trk, vs, p_gs
        self.axis[i] = 0
        self.direction[i] = 0
        self.recovering[i[done]] = False
        return act


__all__ = ["PilotModel", "safe_avoidance"]
