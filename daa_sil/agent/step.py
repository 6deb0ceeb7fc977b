"""The allocation agent (paper Algorithm 1 + Algorithm 2) as a pure, batched step function.

:func:`agent_step` reads in the order of the algorithms: the alert levels, then three named
sub-steps (:mod:`daa_sil.agent.substeps`) -- :func:`link_step` (is the link alive, did a fresh pilot
command arrive), :func:`wait_step` (no fresh command: wait or not, Eq. 11, with the wait function
picked by name from :data:`daa_sil.agent.wait_function.WAIT_FUNCTIONS`) and :func:`blend_step` (a fresh
command: fly it, blend it, or override it) -- then the decision code, the command flown and the
authority, returned as a :class:`~daa_sil.agent.decision.Decision` record.

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
* Authority: ``pilot`` (pilot command or inactive), ``waiting`` (a wait: the agent keeps the pilot's
  last command while it waits for the delayed pilot), ``daa`` (DAA resolution, blend, override, link
  lost). Named ``hold`` up to bba2fd8, which clashed with the pilot's "hold" command kind; old logs
  are read through :data:`daa_sil.steplog.RENAMED`.
"""

from __future__ import annotations

import functools
from dataclasses import replace

import numpy as np

from daa_sil.daa.alerting import safe_avoidance
from daa_sil.daa import (AXIS_NONE, DaaConfig, DaaState, alert_levels, classify_command, compute_bands, conflict_lists,
                  resolve, safety_metric, sm_from_tin)
from daa_sil.daa.resolution import command_deltas
from daa_sil.agent.allocation import PolicyRows
from daa_sil.config.choices import WAIT_RULES
from daa_sil.config.groups import policy_for_group
from daa_sil.config.policy import WAIT_MODES, AllocationPolicy
from daa_sil.agent.decision import (A_DAA, A_PILOT, A_WAITING, AUTHORITY_NAMES, BY_BOTH, BY_MAP, BY_NEITHER, BY_NONE,
                              BY_PROJL, CODE_NAMES, D_BLEND, D_DAA_OVERRIDE, D_LINK_LOST, D_NO_WAIT, D_NONE,
                              D_PILOT, D_STALE, D_WAIT, DECIDED_BY_NAMES, DECISION_FIELDS, DECISION_NAMES, Decision,
                              decode)
from daa_sil.agent.memory import AgentMemory, PilotInput
from daa_sil.agent.substeps import BlendStep, LinkStep, WaitStep, blend_step, link_step, wait_step
from daa_sil.agent.wait_function import WaitLookup, WaitValue, make_wait_lookup
from daa_sil.geometry.kinematics import AircraftState, Command


def _reached(own: AircraftState, cmd: Command) -> np.ndarray:
    dtrk, dvs, dgs = command_deltas(own, cmd)
    return (np.abs(dtrk) < np.radians(0.5)) & (np.abs(dvs) < 0.25) & (np.abs(dgs) < 0.5)


#: False: every SM(u) the agent needs is computed, none reused (the reference the tests compare with)
REUSE_SM = True


def _same_command(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(R,) bool: rows of ``(R, 3)`` commands equal field by field, bit for bit (nan equal to nan)."""
    same = (a.view(np.int64) == b.view(np.int64)) | (np.isnan(a) & np.isnan(b))
    return same.all(axis=1)


class _SafetyOnce:
    """SM(u) of the step's state (``own``, ``intr``) for the commands the agent asks about, each (row,
    command) computed once: a later request for the same command of a row (bit for bit) takes the value
    computed before. Exact, as each row's SM is what a call of its own gives whatever rows share a call."""

    def __init__(self, own: AircraftState, intr: AircraftState, cfg: DaaConfig, horizon: float):
        self.own, self.intr, self.cfg, self.horizon = own, intr, cfg, horizon
        self.known: list = []  #: (rows ascending, (R, 3) commands, (R,) SM) of the calls made

    def __call__(self, rows: np.ndarray, cmd: Command) -> np.ndarray:
        """SM (s) of ``cmd`` (one per row of ``rows``, ascending row indices)."""
        want = np.empty((rows.size, 3))
        want[:, 0], want[:, 1], want[:, 2] = cmd.trk, cmd.vs, cmd.gs
        out = np.full(rows.size, np.nan)
        todo = np.ones(rows.size, bool)
        for k_rows, k_cmd, k_sm in self.known if REUSE_SM else ():
            pos = np.minimum(np.searchsorted(k_rows, rows), k_rows.size - 1)
            hit = todo & (k_rows[pos] == rows)
            hit[hit] = _same_command(k_cmd[pos[hit]], want[hit])
            out[hit] = k_sm[pos[hit]]
            todo &= ~hit
        if todo.any():
            every = bool(todo.all())
            r = rows if every else rows[todo]
            n = self.own.shape[0]
            if r.size == n and r[0] == 0 and r[-1] == n - 1:  # every row of the step, in order: no copies
                o, i_ = self.own, self.intr
            else:
                o, i_ = self.own[r], self.intr[r]
            got = safety_metric(o, i_, cmd if every else cmd[todo], self.cfg, self.horizon)
            out[todo] = got
            self.known.append((r, want if every else want[todo], got))
        return out


def _alerting(t: float, own: AircraftState, intr: AircraftState, memory: AgentMemory, cfg: DaaConfig):
    """``(alert (N, M), max alert (N,), DaaState or None)``: stateless, or with DAIDALUS hysteresis /
    M-of-N / persistence (``cfg.stateful``)."""
    n = own.shape[0]
    daa_state = memory.daa_state
    if cfg.stateful:
        daa_state = daa_state.copy() if daa_state is not None else DaaState.initial(n, intr.shape[1], cfg)
        alert = daa_state.update_alerts(t, alert_levels(own, intr, cfg, prev=daa_state.early_alert_level(t)), cfg)
    else:
        alert = alert_levels(own, intr, cfg)
    max_alert = alert.max(axis=1) if alert.shape[1] else np.zeros(n, np.int8)
    return alert, max_alert, daa_state


def _daa_resolutions(t: float, own: AircraftState, intr: AircraftState, cfg: DaaConfig, memory: AgentMemory,
                     ia: np.ndarray, alert, daa_state, bands):
    """Bands and the DAA resolution of the active rows ``ia``, in one call: ``(command, SM (s), axis, direction,
    [(rows, Bands)])`` (no part when no row is active); nan / 0 on inactive rows."""
    n = own.shape[0]
    nan = np.full(n, np.nan)
    sm_daa = nan.copy()
    daa_cmd = Command(nan.copy(), nan.copy(), nan.copy())
    daa_axis = np.zeros(n, np.int8)
    daa_dir = np.zeros(n, np.int8)
    parts: list = []
    if ia.size:
        r = ia
        o, i_ = own[r], intr[r]
        if bands is not None:
            b = bands if r.size == n else bands[r]
        else:
            lists = conflict_lists(o, i_, cfg, daa_state.band_early_level(t)[r]) if cfg.stateful else None
            b = compute_bands(o, i_, cfg, alert[r], lists)
        if cfg.stateful:  # band, resolution and preferred-direction hysteresis
            b = daa_state.update_bands(t, b, cfg, r)
        cmd_b, ax_b, dir_b, tin_b = resolve(o, i_, cfg, (memory.daa_axis[r], memory.daa_dir[r]), b, return_t_in=True)
        sm_daa[r] = sm_from_tin(tin_b, cfg.sm_horizon_s, cfg)
        daa_cmd.trk[r], daa_cmd.vs[r], daa_cmd.gs[r] = cmd_b.trk, cmd_b.vs, cmd_b.gs
        daa_axis[r], daa_dir[r] = ax_b, dir_b
        parts.append((r, b))
    return daa_cmd, sm_daa, daa_axis, daa_dir, parts


def agent_step(t: float, own: AircraftState, intr: AircraftState, pilot: PilotInput, memory: AgentMemory,
               policy: "AllocationPolicy | PolicyRows", daa_cfg: "DaaConfig | None" = None,
               wait_lookup: "WaitLookup | None" = None, bands=None, turn_rate: "np.ndarray | None" = None,
               *, band_record: bool = True) -> tuple[Command, Decision, AgentMemory]:
    """One allocation step at sim time ``t`` (s) for ownship ``(N,)`` and intruders ``(N, M)``.

    Returns ``(command to fly, decision record, new memory)``; the record is a
    :class:`~daa_sil.agent.decision.Decision` (codes in :data:`CODE_NAMES`; nan where not applicable).
    ``policy`` one :class:`~daa_sil.config.policy.AllocationPolicy` for every row, or a
    :class:`~daa_sil.agent.allocation.PolicyRows` (each row its own). ``bands`` (a
    :class:`~daa_sil.daa.Bands` for the whole batch) may be passed to avoid recomputing them.
    ``turn_rate`` ``(N, M)`` is each intruder's estimated turn rate (compass rad/s, + = right;
    default 0), which picks the wait map (:class:`daa_sil.onboard.TurnRateEstimator`).
    ``band_record=False`` leaves ``bands_trk``/``bands_trk_region`` None (nobody reads them).
    Every row's outputs are those of a call of its own (the DAA decides everything per encounter), so a
    batch is stepped in one call whatever its rows are.
    """
    cfg = daa_cfg if daa_cfg is not None else DaaConfig()
    n = own.shape[0]
    pol = PolicyRows.of(policy, n)
    horizon = cfg.sm_horizon_s
    alert, max_alert, daa_state = _alerting(t, own, intr, memory, cfg)
    lk = link_step(t, own, pilot, memory, pol)  # sub-step 1: the link
    fresh, link_lost, pcmd = lk.fresh, lk.link_lost, lk.pcmd

    # --- active phase -------------------------------------------------------------------------
    prev_exec = Command(memory.exec_trk, memory.exec_vs, memory.exec_gs)
    in_progress = ((memory.decision == D_WAIT) | (memory.decision == D_BLEND)) & ~_reached(own, prev_exec)
    # Once the onboard DAA (or a blend) holds authority, handing back to the pilot's course is only
    # done when that course is safe: otherwise the ownship would fly back into the conflict it just
    # resolved as soon as the alert clears, and alternate between the two every step.
    # SM(u) of this state, once per row and command (the revert check's, the pilot's, the executed one's)
    safety = _SafetyOnce(own, intr, cfg, horizon)
    unsafe_revert = np.zeros(n, bool)
    check = (memory.authority == A_DAA) & ~((max_alert >= 2) | in_progress)
    if check.any():
        j = np.nonzero(check)[0]
        unsafe_revert[j] = ~(safety(j, lk.last_pilot[j]) > 0)
    # active_from "encounter" (per row): decide every step from the start until safe avoidance
    encounter_over = memory.encounter_over
    whole = np.zeros(n, bool)
    from_start = pol.active_from == "encounter"
    if from_start.any():
        encounter_over = encounter_over | (from_start & safe_avoidance(own, intr, max_alert))
        whole = from_start & ~encounter_over
    active = ((max_alert >= 2) | in_progress | unsafe_revert | whole) & pol.enabled.astype(bool)
    ia = np.nonzero(active)[0]
    daa_cmd, sm_daa, daa_axis, daa_dir, parts = _daa_resolutions(t, own, intr, cfg, memory, ia, alert, daa_state,
                                                                  bands)

    # --- the pilot's command: its safety and its (axis, direction) ------------------------------
    sm_pilot = np.full(n, np.nan)
    fa = fresh & active
    if fa.any():
        j = np.nonzero(fa)[0]
        sm_pilot[j] = safety(j, pcmd[j])
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
    as_none = (pol.unsafe_hold == "no-command") & active & fresh & (p_axis == AXIS_NONE) & ~(sm_pilot > 0)
    decide = fresh & ~as_none  #: fresh commands decided as commands

    ws = wait_step(t, own, intr, cfg, pol, memory, active, decide, link_lost, wait_lookup, turn_rate,
                   max_alert)  # sub-step 2
    wait = ws.wait
    bl = blend_step(own, intr, cfg, active, decide, link_lost, sm_pilot, pol.blending.astype(bool),
                    p_axis, p_dir, pcmd, parts)  # sub-step 3
    pilot_ok, blend = bl.pilot_ok, bl.blend

    # --- decision, command flown and authority ----------------------------------------------------
    decision = np.full(n, D_NONE, np.int8)
    decision = np.where(active & link_lost, D_LINK_LOST, decision)
    decision = np.where(pilot_ok, D_PILOT, decision)
    decision = np.where(blend, D_BLEND, np.where(bl.unsafe, D_DAA_OVERRIDE, decision))
    decision = np.where(ws.nc & wait, D_WAIT, decision)
    decision = np.where(ws.nc & ~wait, D_NO_WAIT, decision)
    decision = np.where(active & lk.stale & ~link_lost, D_STALE, decision).astype(np.int8)
    use_daa = active & ~pilot_ok & ~wait & ~blend
    exec_cmd = lk.last_pilot.where(~active | pilot_ok | wait, bl.command.where(blend, daa_cmd))
    exec_cmd = exec_cmd.where(~use_daa, daa_cmd)
    authority = np.where(~active | pilot_ok, A_PILOT, np.where(wait, A_WAITING, A_DAA)).astype(np.int8)

    # --- safety of what is executed -------------------------------------------------------------
    # pilot: its SM; blend / DAA: the chosen band candidate's SM (same trajectory model); hold: the
    # last pilot command's SM (computed, or the one computed for it already this step)
    sm_exec = np.where(pilot_ok, sm_pilot, np.where(blend, bl.sm, np.where(use_daa, sm_daa, np.nan)))
    other = active & np.isnan(sm_exec)
    if other.any():
        j = np.nonzero(other)[0]
        sm_exec[j] = safety(j, exec_cmd[j])
    e_axis, e_dir = classify_command(own, exec_cmd, cfg)
    exact = (decision == D_BLEND) & (p_axis != AXIS_NONE) & (e_axis == p_axis) & (e_dir == p_dir)
    bt, br_ = _band_record(cfg, n, parts) if band_record else (None, None)

    wv, p = ws.value, lk.last_pilot
    dec = Decision(
        active=active, decision=decision, rule=bl.rule, authority=authority, wait_s=wv.wait_s, projl=ws.projl,
        decided_by=ws.decided_by, wait_p_lowc=wv.p_lowc, wait_in_box=wv.in_box, wait_turn_dps=wv.turn_dps,
        wait_map_turn_dps=wv.map_turn_dps, link_lost=link_lost, max_alert=max_alert.astype(np.int8), alert_level=alert,
        pilot_cmd_received=lk.received, pilot_cmd_fresh=fresh, pilot_cmd_age_s=lk.age, sm_pilot=sm_pilot,
        sm_exec=sm_exec, pilot_axis=p_axis, pilot_dir=p_dir, exec_axis=e_axis, exec_dir=e_dir, exact_match=exact,
        cmd_trk=exec_cmd.trk, cmd_vs=exec_cmd.vs, cmd_gs=exec_cmd.gs, pilot_trk=p.trk, pilot_vs=p.vs, pilot_gs=p.gs,
        daa_trk=daa_cmd.trk, daa_vs=daa_cmd.vs, daa_gs=daa_cmd.gs, bands_trk=bt, bands_trk_region=br_)
    new_mem = replace(memory, pilot_trk=p.trk, pilot_vs=p.vs, pilot_gs=p.gs,
                      pilot_t_sent=np.where(fresh, pilot.t_sent, memory.pilot_t_sent), last_packet_t=lk.link_t,
                      authority=authority, decision=decision, exec_trk=exec_cmd.trk.copy(),
                      exec_vs=exec_cmd.vs.copy(), exec_gs=exec_cmd.gs.copy(), daa_axis=daa_axis, daa_dir=daa_dir,
                      wait_start=np.where(active & ~decide, ws.wait_start, np.nan),
                      intent_axis=intent_axis, intent_dir=intent_dir, daa_state=daa_state,
                      encounter_over=encounter_over)
    return exec_cmd, dec, new_mem


def _band_record(cfg: DaaConfig, n: int, parts: list) -> tuple[np.ndarray, np.ndarray]:
    """The track bands of the record, ``(N, K)`` deg and region codes (nan / -1 on inactive rows)."""
    k_trk = (parts[0][1] if parts else _empty_bands(cfg)).trk.values.shape[1]
    if len(parts) == 1:  # the bands of the whole batch's rows r (read in place: no copy of their rows)
        r, b = parts[0]
        base, idx = b.trk.source()
        if base.values.shape[0] == n and (r.size == n if idx is None else np.array_equal(idx, r)):
            bt, br_ = np.degrees(base.values), base.region.copy()
            if r.size < n:
                off = np.ones(n, bool)
                off[r] = False
                bt[off], br_[off] = np.nan, -1
            return bt, br_
    bt = np.full((n, k_trk), np.nan)
    br_ = np.full((n, k_trk), -1, np.int8)
    for r, b in parts:
        bt[r], br_[r] = np.degrees(b.trk.values), b.trk.region
    return bt, br_


@functools.lru_cache(maxsize=8)
def _empty_bands(cfg: DaaConfig):
    """Bands of an empty batch (their shapes: the track candidates of ``cfg``)."""
    e = AircraftState(*(np.zeros(0) for _ in range(6)))
    return compute_bands(e, AircraftState(*(np.zeros((0, 1)) for _ in range(6))), cfg)



#: the decision codes are :mod:`daa_sil.agent.decision`'s; the agent's namespace offers them to its callers
__all__ = ["AllocationPolicy", "WaitValue", "WaitLookup", "WAIT_MODES", "WAIT_RULES", "policy_for_group", "PilotInput",
           "AgentMemory", "LinkStep", "WaitStep", "BlendStep", "link_step", "wait_step", "blend_step", "agent_step",
           "make_wait_lookup", "decode", "Decision", "DECISION_FIELDS", "DECISION_NAMES", "DECIDED_BY_NAMES",
           "AUTHORITY_NAMES", "CODE_NAMES", "D_NONE", "D_WAIT", "D_NO_WAIT", "D_PILOT", "D_BLEND", "D_DAA_OVERRIDE",
           "D_STALE", "D_LINK_LOST", "BY_NONE", "BY_MAP", "BY_PROJL", "BY_BOTH", "BY_NEITHER", "A_PILOT", "A_DAA",
           "A_WAITING"]
