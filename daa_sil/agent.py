"""The allocation agent (paper Algorithm 1 + Algorithm 2) as a pure, batched step function.

Semantics follow ``docs/architecture.md`` "Allocation semantics":

* **Active** while any intruder has alert level >= 2 (corrective), or while a wait / blend is in
  progress (the previous step's decision was ``wait`` or ``blend`` and the ownship has not yet
  reached that command), or while the DAA holds authority and the pilot's course is still unsafe
  (SM <= 0), so that control returns to the pilot only onto a safe course. Outside the active phase the ownship flies the last pilot command and the
  decision is ``none`` (not counted).
  With ``policy.active_from = "encounter"`` the agent also decides every step from the encounter's
  start until safe avoidance (no alert, every intruder past its closest point of approach, on the
  truth it sees), the paper's "During the communication latency, the agent matches the current state
  with a state in the wait map and makes a decision".
* One decision per active step:
  - ``link_lost``: no packet from the GCS for ``link_timeout_s`` -> the onboard DAA resolution.
  - fresh pilot command received -> ``pilot`` if SM(u_p) > 0; else ``blend`` (Algorithm 2,
    :func:`daa_sil.daa.search_maneuver` with the pilot's (axis, direction), closest to u_p) when
    ``policy.blending``, or ``daa_override`` (DAA resolution) when not (baseline). With
    ``policy.unsafe_hold = "no-command"`` an unsafe fresh "hold" (a command without a maneuver
    intent: the pilot has not maneuvered yet) is decided as if no command had arrived (wait / no
    wait below); it is still stored as the pilot's latest command.
  - no fresh command -> ``wait`` (hold the last pilot command) iff ``w >= W_T`` and no ProjL
    within ``projl_horizon_s``, else ``no_wait`` (DAA resolution). A command older than
    ``stale_command_s`` (by its send time) is never executed nor stored: the step is decided as
    if no command arrived but recorded as ``stale``.
* Wait function ``w`` (``policy.wait_mode``): ``none`` -> 0 (always DAA); ``constant`` ->
  ``constant_wait_s``; ``always`` -> +inf (the map ignored: wait unless ProjL, the ``ID-2-projl``
  ablation); ``map`` -> the wait map at the current state of the most threatening intruder, read
  from the map of that intruder's estimated turn rate (:func:`make_wait_lookup`). Two readings of
  Eq. 11 (``policy.wait_rule``): ``threshold`` (default, literal) compares ``w(S(k))`` read afresh
  every step with W_T, so a constant wait (IC-1, 5 s >= W_T) waits until ProjL fires (any constant
  >= W_T gives the same runs); ``countdown`` reads the paper's
  "waits for the optimal wait time extracted from the map until the control is being authorized
  to the onboard DAA or a delayed pilot command is received": ``w`` is a budget counted from the
  start of the current waiting streak (``w - elapsed``), reset when a fresh pilot command arrives
  or the active phase ends.
* ProjL veto (``policy.projl``, default on): no wait while any intruder has ProjL within
  ``projl_horizon_s``. Off in the ``ID-2-map`` ablation (the map alone decides).
* Provenance of every wait / no-wait decision (``decided_by``): ``map`` (the wait function alone
  said no: w < W_T), ``projl`` (ProjL alone), ``both``, or ``neither`` (a wait). The map
  "decided" a step exactly when ``decided_by == "map"``: with the map replaced by "always wait"
  the decision would have been ``wait``.
* ``projl_horizon_s`` default 25 s = the DO-365 warning alerting time: a LoWC predicted that soon
  leaves no time to wait for a command delayed by up to 10 s plus a 5-10 s maneuver.
* Authority: ``pilot`` (pilot command or inactive), ``hold`` (wait), ``daa`` (DAA resolution,
  blend, override, link lost).
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import Callable

import numpy as np

from .daa.alerting import safe_avoidance
from .daa import (AXIS_NONE, DaaConfig, DaaState, alert_levels, classify_command, compute_bands, conflict_lists,
                  proj_lowc, resolve, safety_metric, search_maneuver, sm_from_tin)
from .daa.config import AXIS_NAMES, DIR_NAMES, RULE_NAMES
from .daa.resolution import command_deltas
from .errors import UsageError
from daa_sil.config.choices import AGENT_ACTIVE, OUTSIDE_BOX, UNSAFE_HOLDS, WAIT_RULES
from daa_sil.geometry.frames import to_paper_state
from daa_sil.geometry.kinematics import AircraftState, Command

DECISION_NAMES = ("none", "wait", "no_wait", "pilot", "blend", "daa_override", "daa", "stale", "link_lost")
DECIDED_BY_NAMES = ("none", "map", "projl", "both", "neither")
BY_NONE, BY_MAP, BY_PROJL, BY_BOTH, BY_NEITHER = range(5)
WAIT_MODES = ("none", "constant", "map", "always")
(D_NONE, D_WAIT, D_NO_WAIT, D_PILOT, D_BLEND, D_DAA_OVERRIDE, D_DAA, D_STALE, D_LINK_LOST) = range(9)
AUTHORITY_NAMES = ("pilot", "daa", "hold")
A_PILOT, A_DAA, A_HOLD = range(3)

#: keys of the decision record (every value is an array with leading axis N)
DECISION_FIELDS = (
    "active", "decision", "rule", "authority", "wait_s", "projl", "decided_by", "wait_p_lowc", "wait_in_box",
    "wait_turn_dps", "wait_map_turn_dps", "link_lost", "max_alert", "alert_level",
    "pilot_cmd_received", "pilot_cmd_fresh", "pilot_cmd_age_s", "sm_pilot", "sm_exec",
    "pilot_axis", "pilot_dir", "exec_axis", "exec_dir", "exact_match",
    "cmd_trk", "cmd_vs", "cmd_gs", "pilot_trk", "pilot_vs", "pilot_gs", "daa_trk", "daa_vs", "daa_gs",
    "bands_trk", "bands_trk_region",
)

#: name tables for the integer-coded fields
CODE_NAMES = {"decision": DECISION_NAMES, "rule": RULE_NAMES, "authority": AUTHORITY_NAMES, "decided_by": DECIDED_BY_NAMES,
              "pilot_axis": AXIS_NAMES, "exec_axis": AXIS_NAMES, "pilot_dir": DIR_NAMES, "exec_dir": DIR_NAMES}

@dataclass
class WaitValue:
    """The wait function's answer for N encounters (arrays ``(N,)``; nan where not applicable)."""

    wait_s: np.ndarray  #: w, s
    p_lowc: np.ndarray  #: the map's P(LoWC within H while waiting)
    in_box: np.ndarray  #: bool, the state was inside the map's box (not clamped)
    turn_dps: np.ndarray  #: estimated turn rate of the intruder read, compass deg/s (+ = right)
    map_turn_dps: np.ndarray  #: conditioning turn rate of the map read, compass deg/s (+ = right)

    @classmethod
    def constant(cls, n: int, value: float) -> "WaitValue":
        nan = np.full(n, np.nan)
        return cls(np.full(n, float(value)), nan, np.zeros(n, bool), nan.copy(), nan.copy())


#: ``lookup(own (N,), intruders (N, M), turn_rate (N, M) compass rad/s) -> WaitValue``
WaitLookup = Callable[[AircraftState, AircraftState, np.ndarray], WaitValue]


@dataclass(frozen=True)
class AllocationPolicy:
    """One experimental group's allocation settings (groups are data, not code paths: see
    :mod:`daa_sil.config.groups`). Times in s."""

    wait_mode: str  #: :data:`WAIT_MODES`: none (w = 0, always DAA), constant, map, always (w = inf)
    constant_wait_s: float = 5.0
    wait_threshold_s: float = 4.0  #: W_T
    projl: bool = True  #: ProjL veto on (the paper) or off (the map alone decides)
    projl_horizon_s: float = 25.0  #: the paper's N
    blending: bool = True  #: False = baseline: unsafe pilot command -> DAA override
    stale_command_s: float = 15.0
    link_timeout_s: float = 20.0
    wait_rule: str = "threshold"  #: :data:`WAIT_RULES`: w(S(k)) >= W_T every step, or a countdown budget
    name: str = "custom"
    #: :data:`UNSAFE_HOLDS`: an unsafe fresh "hold" is blended / overridden like any command (``blend``)
    #: or decided as if no command had arrived (``no-command``)
    unsafe_hold: str = "blend"
    #: :data:`AGENT_ACTIVE`: the agent decides from the corrective alert (``corrective``) or over the
    #: whole encounter, from its start until safe avoidance (``encounter``)
    active_from: str = "corrective"
    #: False = the agent never takes authority: the pilot's last command is always flown, the
    #: decision is always ``none`` (alert levels are still computed); the SIL's ``DAA_ENABLE 0``
    enabled: bool = True

    def __post_init__(self):
        if self.wait_mode not in WAIT_MODES:
            raise UsageError(f"wait_mode must be one of {', '.join(WAIT_MODES)}, got {self.wait_mode!r}")
        if self.wait_rule not in WAIT_RULES:
            raise UsageError(f"wait_rule must be one of {', '.join(WAIT_RULES)}, got {self.wait_rule!r}")
        if self.unsafe_hold not in UNSAFE_HOLDS:
            raise UsageError(f"unsafe_hold must be one of {', '.join(UNSAFE_HOLDS)}, got {self.unsafe_hold!r}")
        if self.active_from not in AGENT_ACTIVE:
            raise UsageError(f"active_from must be one of {', '.join(AGENT_ACTIVE)}, got {self.active_from!r}")


def policy_for_group(group: str) -> AllocationPolicy:
    """The policy of a named group of the group table (:mod:`daa_sil.config.groups`: B-1, ..., ID-2-map)."""
    from daa_sil.config.groups import group_spec

    return group_spec(group).policy()


@dataclass
class PilotInput:
    """Pilot data at the vehicle this step, arrays (N,): ``received`` a command arrived this step,
    ``cmd`` the newest one (nan fields = keep current), ``t_sent``/``t_recv`` its send/arrival time (s),
    ``link_alive_t`` arrival time of the last packet of any kind from the GCS (s; nan = unknown)."""

    received: np.ndarray
    cmd: Command
    t_sent: np.ndarray
    t_recv: np.ndarray
    link_alive_t: np.ndarray

    @classmethod
    def nothing(cls, n: int, link_alive_t=np.nan) -> "PilotInput":
        """No command this step."""
        nan = np.full(n, np.nan)
        return cls(np.zeros(n, bool), Command(nan, nan, nan), nan.copy(), nan.copy(), np.full(n, link_alive_t, float))


@dataclass
class AgentMemory:
    """Batched agent state carried between steps (arrays (N,)). Times in s, angles rad."""

    pilot_trk: np.ndarray  #: last fresh pilot command (resolved at reception)
    pilot_vs: np.ndarray
    pilot_gs: np.ndarray
    pilot_t_sent: np.ndarray  #: its send time (nan = none yet)
    last_packet_t: np.ndarray  #: arrival time of the last GCS packet
    authority: np.ndarray  #: A_* code of the last step
    decision: np.ndarray  #: D_* code of the last step
    exec_trk: np.ndarray  #: command executed last step
    exec_vs: np.ndarray
    exec_gs: np.ndarray
    daa_axis: np.ndarray  #: last DAA resolution (axis, direction) codes, for persistence
    daa_dir: np.ndarray
    wait_start: np.ndarray  #: start of the current waiting streak (nan = none)
    intent_axis: "np.ndarray | None" = None  #: the pilot's (axis, direction) preference, AXIS_* / DIR_*
    intent_dir: "np.ndarray | None" = None
    daa_state: "DaaState | None" = None  #: DAA alert/band hysteresis (only with DaaConfig.stateful)
    encounter_over: "np.ndarray | None" = None  #: bool, safe avoidance reached (``active_from="encounter"``)

    def __post_init__(self):
        n = np.shape(self.pilot_trk)
        if self.intent_axis is None:
            self.intent_axis = np.full(n, AXIS_NONE, np.int8)
        if self.intent_dir is None:
            self.intent_dir = np.zeros(n, np.int8)
        if self.encounter_over is None:
            self.encounter_over = np.zeros(n, bool)

    @classmethod
    def initial(cls, n: int, own: AircraftState, t0: float = 0.0) -> "AgentMemory":
        """Start: the 'last pilot command' is the current course; the link counts as alive at ``t0``."""
        z = np.zeros(n, np.int8)
        return cls(own.trk.copy(), own.vs.copy(), own.gs.copy(), np.full(n, np.nan), np.full(n, float(t0)),
                   z.copy(), z.copy(), own.trk.copy(), own.vs.copy(), own.gs.copy(), z.copy(), z.copy(),
                   np.full(n, np.nan))

    def __getitem__(self, idx) -> "AgentMemory":
        return AgentMemory(*(None if getattr(self, f.name) is None else getattr(self, f.name)[idx] for f in fields(self)))


def _reached(own: AircraftState, cmd: Command) -> np.ndarray:
    dtrk, dvs, dgs = command_deltas(own, cmd)
    return (np.abs(dtrk) < np.radians(0.5)) & (np.abs(dvs) < 0.25) & (np.abs(dgs) < 0.5)


def _wait_values(own, intr, policy: AllocationPolicy, lookup: "WaitLookup | None", turn_rate, idx) -> WaitValue:
    n = len(idx)
    if policy.wait_mode == "none" or n == 0:
        return WaitValue.constant(n, 0.0)
    if policy.wait_mode == "constant":
        return WaitValue.constant(n, policy.constant_wait_s)
    if policy.wait_mode == "always":
        return WaitValue.constant(n, np.inf)
    if lookup is None:
        raise UsageError("policy wait_mode 'map' needs a wait_lookup (daa_sil.agent.make_wait_lookup)")
    rate = np.zeros(intr.shape) if turn_rate is None else np.broadcast_to(np.asarray(turn_rate, float), intr.shape)
    return lookup(own[idx], intr[idx], rate[idx])


def agent_step(t: float, own: AircraftState, intr: AircraftState, pilot: PilotInput, memory: AgentMemory,
               policy: AllocationPolicy, daa_cfg: "DaaConfig | None" = None,
               wait_lookup: "WaitLookup | None" = None, bands=None, turn_rate: "np.ndarray | None" = None
               ) -> tuple[Command, dict, AgentMemory]:
    """One allocation step at sim time ``t`` (s) for ownship ``(N,)`` and intruders ``(N, M)``.

    Returns ``(command to fly, decision record, new memory)``; the record has the keys
    :data:`DECISION_FIELDS` (codes in :data:`CODE_NAMES`; nan where not applicable). ``bands``
    (a :class:`~daa_sil.daa.Bands` for the whole batch) may be passed to avoid recomputing them.
    ``turn_rate`` ``(N, M)`` is each intruder's estimated turn rate (compass rad/s, + = right;
    default 0), which picks the wait map (:class:`daa_sil.onboard.TurnRateEstimator`).
    """
    cfg = daa_cfg if daa_cfg is not None else DaaConfig()
    n = own.shape[0]
    nan = np.full(n, np.nan)
    horizon = cfg.sm_horizon_s
    # --- DAA alerting: stateless, or with DAIDALUS hysteresis / M-of-N / persistence (cfg.stateful) ----
    daa_state = memory.daa_state
    if cfg.stateful:
        daa_state = daa_state.copy() if daa_state is not None else DaaState.initial(n, intr.shape[1], cfg)
        alert = daa_state.update_alerts(t, alert_levels(own, intr, cfg, prev=daa_state.early_alert_level(t)), cfg)
    else:
        alert = alert_levels(own, intr, cfg)
    max_alert = alert.max(axis=1) if alert.shape[1] else np.zeros(n, np.int8)

    # --- link and pilot input -----------------------------------------------------------------
    received = np.asarray(pilot.received, bool)
    link_t = np.fmax(memory.last_packet_t, np.asarray(pilot.link_alive_t, float))
    link_t = np.where(received, np.fmax(link_t, pilot.t_recv), link_t)
    link_lost = (t - link_t) > policy.link_timeout_s
    age = np.where(received, t - np.asarray(pilot.t_sent, float), np.nan)
    fresh = received & (age <= policy.stale_command_s)
    stale = received & ~fresh
    pcmd = pilot.cmd.resolved(own)
    p_trk = np.where(fresh, pcmd.trk, memory.pilot_trk)
    p_vs = np.where(fresh, pcmd.vs, memory.pilot_vs)
    p_gs = np.where(fresh, pcmd.gs, memory.pilot_gs)
    last_pilot = Command(p_trk, p_vs, p_gs)

    # --- active phase -------------------------------------------------------------------------
    prev_exec = Command(memory.exec_trk, memory.exec_vs, memory.exec_gs)
    in_progress = np.isin(memory.decision, (D_WAIT, D_BLEND)) & ~_reached(own, prev_exec)
    # Once the onboard DAA (or a blend) holds authority, handing back to the pilot's course is only
    # done when that course is safe: otherwise the ownship would fly back into the conflict it just
    # resolved as soon as the alert clears, and alternate between the two every step.
    unsafe_revert = np.zeros(n, bool)
    check = (memory.authority == A_DAA) & ~((max_alert >= 2) | in_progress)
    if check.any():
        j = np.nonzero(check)[0]
        unsafe_revert[j] = ~(safety_metric(own[j], intr[j], last_pilot[j], cfg, horizon) > 0)
    encounter_over = memory.encounter_over
    whole = np.zeros(n, bool)
    if policy.active_from == "encounter":  # decide every step from the start until safe avoidance
        encounter_over = encounter_over | safe_avoidance(own, intr, max_alert)
        whole = ~encounter_over
    active = ((max_alert >= 2) | in_progress | unsafe_revert | whole) & bool(policy.enabled)
    ia = np.nonzero(active)[0]
    own_a, intr_a = own[ia], intr[ia]

    # --- DAA: bands and resolution for the active encounters -------------------------------------
    if bands is not None:
        b_a = bands if ia.size == n else bands[ia]
    else:
        lists = conflict_lists(own_a, intr_a, cfg, daa_state.band_early_level(t)[ia]) if cfg.stateful else None
        b_a = compute_bands(own_a, intr_a, cfg, alert[ia], lists)
    if cfg.stateful:  # band, resolution and preferred-direction hysteresis
        b_a = daa_state.update_bands(t, b_a, cfg, ia)
    daa_cmd_a, daa_ax_a, daa_dir_a, daa_tin_a = resolve(own_a, intr_a, cfg, (memory.daa_axis[ia], memory.daa_dir[ia]),
                                                        b_a, return_t_in=True)
    sm_daa = nan.copy()
    sm_daa[ia] = sm_from_tin(daa_tin_a, horizon, cfg)

    # --- pilot command safety -----------------------------------------------------------------
    sm_pilot = nan.copy()
    fa = fresh[ia]
    if fa.any():
        j = ia[fa]
        sm_pilot[j] = safety_metric(own[j], intr[j], pcmd[j], cfg, horizon)
    # The pilot's (axis, direction) preference is the change from the pilot's previous course to the
    # new command, not from the current state: once the DAA or a blend has moved the ownship, a
    # repeated "hold" command would otherwise read as a turn back and flip the blend every step.
    ref = AircraftState(own.x, own.y, own.z, memory.pilot_gs, memory.pilot_trk, memory.pilot_vs)
    n_axis, n_dir = classify_command(ref, pcmd, cfg)
    changed = fresh & (n_axis != AXIS_NONE)
    intent_axis = np.where(changed, n_axis, memory.intent_axis).astype(np.int8)
    intent_dir = np.where(changed, n_dir, memory.intent_dir).astype(np.int8)
    p_axis = np.where(fresh, intent_axis, AXIS_NONE).astype(np.int8)
    p_dir = np.where(fresh, intent_dir, 0).astype(np.int8)

    # an unsafe "hold" decided as no command (policy.unsafe_hold): it carries no maneuver to blend
    as_none = np.zeros(n, bool)
    if policy.unsafe_hold == "no-command":
        as_none = active & fresh & (p_axis == AXIS_NONE) & ~(sm_pilot > 0)
    decide = fresh & ~as_none  #: fresh commands decided as commands

    # --- wait / no wait (no fresh command) ------------------------------------------------------
    wait_s, w_pl, w_turn, w_map = nan.copy(), nan.copy(), nan.copy(), nan.copy()
    w_box = np.zeros(n, bool)
    projl = np.zeros(n, bool)
    if ia.size:
        projl[ia] = proj_lowc(own_a, intr_a, cfg, policy.projl_horizon_s).any(axis=1) if intr.shape[1] else False
    nc = active & ~decide & ~link_lost
    inc = np.nonzero(nc)[0]
    wait_start = np.where(active & ~decide, memory.wait_start, np.nan)
    if inc.size:
        wv = _wait_values(own, intr, policy, wait_lookup, turn_rate, inc)
        w = wv.wait_s
        if policy.wait_rule == "countdown":
            w = w - np.where(np.isfinite(wait_start[inc]), t - wait_start[inc], 0.0)
        wait_s[inc], w_pl[inc], w_box[inc], w_turn[inc], w_map[inc] = w, wv.p_lowc, wv.in_box, wv.turn_dps, wv.map_turn_dps
    veto_map = nc & ~(np.nan_to_num(wait_s, nan=-np.inf) >= policy.wait_threshold_s)
    veto_projl = nc & projl & policy.projl
    wait = nc & ~veto_map & ~veto_projl
    decided_by = np.select([~nc, veto_map & veto_projl, veto_map, veto_projl], [BY_NONE, BY_BOTH, BY_MAP, BY_PROJL],
                           BY_NEITHER).astype(np.int8)
    wait_start = np.where(wait & np.isnan(wait_start), t, wait_start)

    # --- blend for unsafe fresh pilot commands --------------------------------------------------
    pilot_ok = active & decide & ~link_lost & (sm_pilot > 0)
    unsafe = active & decide & ~link_lost & ~(sm_pilot > 0)
    rule = np.zeros(n, np.int8)
    blend_cmd = Command(nan.copy(), nan.copy(), nan.copy())
    sm_blend = nan.copy()
    if policy.blending and unsafe.any():
        sel = unsafe[ia]
        j = ia[sel]
        bc, br, bt_in = search_maneuver(own[j], intr[j], p_axis[j], p_dir[j], cfg, ref=pcmd[j], horizon_s=horizon,
                                        bands=b_a[sel], return_t_in=True)
        blend_cmd.trk[j], blend_cmd.vs[j], blend_cmd.gs[j] = bc.trk, bc.vs, bc.gs
        rule[j] = br
        sm_blend[j] = sm_from_tin(bt_in, horizon, cfg)

    # --- decision codes -----------------------------------------------------------------------
    decision = np.full(n, D_NONE, np.int8)
    decision = np.where(active & link_lost, D_LINK_LOST, decision)
    decision = np.where(pilot_ok, D_PILOT, decision)
    decision = np.where(unsafe, D_BLEND if policy.blending else D_DAA_OVERRIDE, decision)
    decision = np.where(nc & wait, D_WAIT, decision)
    decision = np.where(nc & ~wait, D_NO_WAIT, decision)
    decision = np.where(active & stale & ~link_lost, D_STALE, decision).astype(np.int8)

    daa_cmd = Command(nan.copy(), nan.copy(), nan.copy())
    daa_cmd.trk[ia], daa_cmd.vs[ia], daa_cmd.gs[ia] = daa_cmd_a.trk, daa_cmd_a.vs, daa_cmd_a.gs
    use_daa = active & ~pilot_ok & ~wait & ~(unsafe & policy.blending)
    exec_cmd = last_pilot.where(~active | pilot_ok | wait, blend_cmd.where(unsafe & policy.blending, daa_cmd))
    exec_cmd = exec_cmd.where(~use_daa, daa_cmd)
    authority = np.where(~active | pilot_ok, A_PILOT, np.where(wait, A_HOLD, A_DAA)).astype(np.int8)

    # --- safety of what is executed -------------------------------------------------------------
    # pilot: its SM; blend / DAA: the chosen band candidate's SM (same trajectory model); hold: computed
    sm_exec = np.where(pilot_ok, sm_pilot, np.where(unsafe & policy.blending, sm_blend,
                                                    np.where(use_daa, sm_daa, np.nan)))
    other = active & np.isnan(sm_exec)
    if other.any():
        j = np.nonzero(other)[0]
        sm_exec[j] = safety_metric(own[j], intr[j], exec_cmd[j], cfg, horizon)
    e_axis, e_dir = classify_command(own, exec_cmd, cfg)
    exact = (decision == D_BLEND) & (p_axis != AXIS_NONE) & (e_axis == p_axis) & (e_dir == p_dir)

    bt = np.full((n, b_a.trk.values.shape[1]), np.nan)
    br_ = np.full((n, b_a.trk.values.shape[1]), -1, np.int8)
    bt[ia], br_[ia] = np.degrees(b_a.trk.values), b_a.trk.region
    daa_axis = np.zeros(n, np.int8)
    daa_dir = np.zeros(n, np.int8)
    daa_axis[ia], daa_dir[ia] = daa_ax_a, daa_dir_a

    dec = {
        "active": active, "decision": decision, "rule": rule, "authority": authority, "wait_s": wait_s,
        "projl": projl, "decided_by": decided_by, "wait_p_lowc": w_pl, "wait_in_box": w_box, "wait_turn_dps": w_turn,
        "wait_map_turn_dps": w_map, "link_lost": link_lost, "max_alert": max_alert.astype(np.int8), "alert_level": alert,
        "pilot_cmd_received": received, "pilot_cmd_fresh": fresh, "pilot_cmd_age_s": age, "sm_pilot": sm_pilot, "sm_exec": sm_exec,
        "pilot_axis": p_axis, "pilot_dir": p_dir, "exec_axis": e_axis, "exec_dir": e_dir, "exact_match": exact,
        "cmd_trk": exec_cmd.trk, "cmd_vs": exec_cmd.vs, "cmd_gs": exec_cmd.gs,
        "pilot_trk": p_trk, "pilot_vs": p_vs, "pilot_gs": p_gs,
        "daa_trk": daa_cmd.trk, "daa_vs": daa_cmd.vs, "daa_gs": daa_cmd.gs,
        "bands_trk": bt, "bands_trk_region": br_,
    }
    new_mem = replace(memory, pilot_trk=p_trk, pilot_vs=p_vs, pilot_gs=p_gs,
                      pilot_t_sent=np.where(fresh, pilot.t_sent, memory.pilot_t_sent), last_packet_t=link_t,
                      authority=authority, decision=decision, exec_trk=exec_cmd.trk.copy(),
                      exec_vs=exec_cmd.vs.copy(), exec_gs=exec_cmd.gs.copy(), daa_axis=daa_axis, daa_dir=daa_dir,
                      wait_start=np.where(active & ~decide, wait_start, np.nan),
                      intent_axis=intent_axis, intent_dir=intent_dir, daa_state=daa_state,
                      encounter_over=encounter_over)
    return exec_cmd, dec, new_mem


def decode(decisions: dict) -> dict:
    """Copy of a decision record with the integer-coded fields as string arrays."""
    out = dict(decisions)
    for key, names in CODE_NAMES.items():
        if key in out:
            out[key] = np.asarray(names, dtype=object)[np.asarray(out[key], int)]
    return out


def make_wait_lookup(family, cfg: "DaaConfig | None" = None, outside: str = "clamp") -> WaitLookup:
    """Wrap a wait-map family (``family.lookup(paper_states, turn_rate)``) as a :data:`WaitLookup`.

    Each intruder is converted to the paper frame (:func:`daa_sil.geometry.frames.to_paper_state`) and read
    from the map of its estimated turn rate (compass rad/s, + = right, passed to the family in the
    paper sense, + = left). The wait of the **most threatening** intruder is used: the one with the
    earliest straight-line LoWC over the DAA lookahead (ties: the smallest range). ``outside``
    (:data:`OUTSIDE_BOX`): a state outside the map's box reads the nearest state of the box
    (``clamp``) or w = H, the map's horizon (``far``: the map does not model that intruder; the
    ProjL veto still applies, and a LoWC in progress is always within ProjL's look-ahead).
    """
    cfg = cfg or DaaConfig()
    if outside not in OUTSIDE_BOX:
        raise UsageError(f"outside must be one of {', '.join(OUTSIDE_BOX)}, got {outside!r}")
    horizon = float(family.params.horizon) if outside == "far" else None
    from .geometry import wellclear as wc
    from .daa.alerting import relative_state

    def lookup(own: AircraftState, intr: AircraftState, turn_rate: np.ndarray) -> WaitValue:
        n, m = intr.shape
        if m == 0:
            return WaitValue.constant(n, np.inf)
        paper = to_paper_state(own.position()[:, None], own.velocity()[:, None], intr.position(), intr.velocity())
        rate = np.broadcast_to(np.asarray(turn_rate, float), (n, m))
        res = family.lookup(paper, -rate)
        if horizon is not None:
            res.wait_s = np.where(np.asarray(res.in_box, bool), res.wait_s, horizon)
        s, v = relative_state(own, intr)
        t_in, _ = wc.violation_interval(s, v, cfg.th, 0.0, cfg.lookahead_s)
        key = np.minimum(t_in, 1e9) * 1e6 + wc.horizontal_range(s)
        k = np.argmin(key, axis=1)
        r = np.arange(n)
        return WaitValue(np.asarray(res.wait_s, float)[r, k], np.asarray(res.p_lowc, float)[r, k],
                         np.asarray(res.in_box, bool)[r, k], np.degrees(rate[r, k]),
                         0.0 - np.asarray(res.map_turn_deg, float)[r, k])  # 0.0 - x: no -0.0 for the 0 map

    return lookup


__all__ = ["AllocationPolicy", "WaitValue", "WaitLookup", "WAIT_MODES", "WAIT_RULES", "UNSAFE_HOLDS", "OUTSIDE_BOX", "DECIDED_BY_NAMES", "policy_for_group", "PilotInput", "AgentMemory", "agent_step",
           "make_wait_lookup", "decode", "DECISION_FIELDS", "DECISION_NAMES", "AUTHORITY_NAMES", "CODE_NAMES"]
