"""The three named sub-steps of the allocation agent's step (:func:`daa_sil.agent.step.agent_step`),
each a pure function over arrays (N,) that returns a small record:

1. :func:`link_step` -- the link: is it alive, did a pilot command arrive, is it fresh;
2. :func:`wait_step` -- wait / no wait without a fresh command (Algorithm 1, paper Eq. 11): wait
   iff the wait function's w(S) >= W_T and no ProjL within N;
3. :func:`blend_step` -- a fresh command: flown if safe, else blended toward the pilot's intent
   (Algorithm 2) or overridden by the DAA resolution (the baseline groups).

Times s, angles rad.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from daa_sil.agent.memory import AgentMemory, PilotInput
from daa_sil.agent.allocation import PolicyRows
from daa_sil.daa import DaaConfig, proj_lowc, search_maneuver, sm_from_tin
from daa_sil.agent.decision import A_DAA, BY_BOTH, BY_KEPT, BY_MAP, BY_NEITHER, BY_NONE, BY_PROJL
from daa_sil.geometry.kinematics import AircraftState, Command
from daa_sil.agent.wait_function import WaitLookup, WaitValue, wait_values


@dataclass
class LinkStep:
    """Sub-step 1, the link (Algorithm 1's input): what arrived from the GCS this step. Arrays (N,)."""

    received: np.ndarray  #: bool, a pilot command arrived
    link_t: np.ndarray  #: arrival time of the last GCS packet (s)
    link_lost: np.ndarray  #: bool, none for ``link_timeout_s``
    age: np.ndarray  #: the arrived command's age by its send time (s), nan when none
    fresh: np.ndarray  #: bool, it arrived and is not older than ``stale_command_s``
    stale: np.ndarray  #: bool, it arrived stale (never flown nor stored)
    pcmd: Command  #: the arrived command, resolved against the current state
    last_pilot: Command  #: the pilot's latest fresh command (this one if fresh)


def link_step(t: float, own: AircraftState, pilot: PilotInput, memory: AgentMemory, pol: PolicyRows) -> LinkStep:
    """Sub-step 1: link liveness, command freshness and the pilot's latest command at time ``t`` (s)."""
    received = np.asarray(pilot.received, bool)
    link_t = np.fmax(memory.last_packet_t, np.asarray(pilot.link_alive_t, float))
    link_t = np.where(received, np.fmax(link_t, pilot.t_recv), link_t)
    link_lost = (t - link_t) > pol.link_timeout_s
    age = np.where(received, t - np.asarray(pilot.t_sent, float), np.nan)
    fresh = received & (age <= pol.stale_command_s)
    pcmd = pilot.cmd.resolved(own)
    last_pilot = Command(np.where(fresh, pcmd.trk, memory.pilot_trk), np.where(fresh, pcmd.vs, memory.pilot_vs),
                         np.where(fresh, pcmd.gs, memory.pilot_gs))
    return LinkStep(received, link_t, link_lost, age, fresh, received & ~fresh, pcmd, last_pilot)


@dataclass
class WaitStep:
    """Sub-step 2, wait / no wait (Algorithm 1 without a fresh command, paper Eq. 11). Arrays (N,)."""

    nc: np.ndarray  #: bool, decided here: active, no command decided as one, link alive
    wait: np.ndarray  #: bool, the agent waits (w >= W_T and no ProjL veto)
    value: WaitValue  #: the wait function read (nan / False where not read)
    projl: np.ndarray  #: bool, a LoWC projected within the row's look-ahead N
    decided_by: np.ndarray  #: int8, BY_* code: what vetoed the wait
    wait_start: np.ndarray  #: start of the current waiting streak (s, nan = none)


def wait_step(t: float, own: AircraftState, intr: AircraftState, cfg: DaaConfig, pol: PolicyRows, memory: AgentMemory,
              active: np.ndarray, decide: np.ndarray, link_lost: np.ndarray, wait_lookup: "WaitLookup | None",
              turn_rate, max_alert: "np.ndarray | None" = None) -> WaitStep:
    """Sub-step 2: wait (hold the pilot's last command) iff w(S) >= W_T and no ProjL within N. A row
    whose policy keeps the DAA's authority (``daa_authority = "until-clear"``) does not wait while the
    DAA held authority last step and an intruder still raises an alert (``max_alert`` (N,) >= 1)."""
    n = own.shape[0]
    ia = np.nonzero(active)[0]
    projl = np.zeros(n, bool)
    if ia.size and intr.shape[1]:  # element-wise per encounter: one call per look-ahead present
        horizons = pol.projl_horizon_s[ia]
        for h in np.unique(horizons):
            r = ia[horizons == h]
            projl[r] = proj_lowc(own[r], intr[r], cfg, float(h)).any(axis=1)
    nc = active & ~decide & ~link_lost
    inc = np.nonzero(nc)[0]
    wait_start = np.where(active & ~decide, memory.wait_start, np.nan)
    value = WaitValue.constant(n, np.nan)
    if inc.size:
        wv = wait_values(own, intr, pol, wait_lookup, turn_rate, inc)
        w = wv.wait_s
        countdown = pol.wait_rule[inc] == "countdown"
        if countdown.any():  # the wait is a budget counted from the start of the streak
            w = np.where(countdown, w - np.where(np.isfinite(wait_start[inc]), t - wait_start[inc], 0.0), w)
        value.wait_s[inc], value.p_lowc[inc], value.in_box[inc] = w, wv.p_lowc, wv.in_box
        value.turn_dps[inc], value.map_turn_dps[inc] = wv.turn_dps, wv.map_turn_dps
    if inc.size:
        veto_map = nc & ~(np.nan_to_num(value.wait_s, nan=-np.inf) >= pol.wait_threshold_s)
        veto_projl = nc & projl & pol.projl.astype(bool)
        wait = nc & ~veto_map & ~veto_projl
        # the first that holds of: not decided here, both vetoes, the map's, ProjL's, neither
        decided_by = np.where(~nc, BY_NONE, np.where(veto_map & veto_projl, BY_BOTH, np.where(
            veto_map, BY_MAP, np.where(veto_projl, BY_PROJL, BY_NEITHER)))).astype(np.int8)
        keep = pol.daa_authority == "until-clear"
        if keep.any() and max_alert is not None:  # the extension: the DAA keeps its authority until clear
            kept = wait & keep & (memory.authority == A_DAA) & (np.asarray(max_alert) >= 1)
            wait = wait & ~kept
            decided_by = np.where(kept, BY_KEPT, decided_by).astype(np.int8)
    else:  # no row decides a wait (every idle step): no veto, no wait
        veto_map = veto_projl = wait = np.zeros(n, bool)
        decided_by = np.full(n, BY_NONE, np.int8)
    wait_start = np.where(wait & np.isnan(wait_start), t, wait_start)
    return WaitStep(nc, wait, value, projl, decided_by, wait_start)


@dataclass
class BlendStep:
    """Sub-step 3, a fresh command (Algorithm 1) and the blend (Algorithm 2). Arrays (N,)."""

    pilot_ok: np.ndarray  #: bool, the pilot's command is safe (SM > 0): flown
    unsafe: np.ndarray  #: bool, it is not: blended, or overridden by the DAA (baseline groups)
    blend: np.ndarray  #: bool, blended
    command: Command  #: the blended command (nan elsewhere)
    rule: np.ndarray  #: int8, the blend's rule code (0 elsewhere)
    sm: np.ndarray  #: SM of the blended command (s; nan elsewhere)


def blend_step(own: AircraftState, intr: AircraftState, cfg: DaaConfig, active: np.ndarray, decide: np.ndarray,
               link_lost: np.ndarray, sm_pilot: np.ndarray, blending: np.ndarray, p_axis: np.ndarray,
               p_dir: np.ndarray, pcmd: Command, parts: list) -> BlendStep:
    """Sub-step 3: fly a safe fresh command; blend an unsafe one toward the pilot's (axis, direction),
    closest to it (:func:`daa_sil.daa.search_maneuver`, one call per DAA batch in ``parts``)."""
    n = own.shape[0]
    nan = np.full(n, np.nan)
    horizon = cfg.sm_horizon_s
    pilot_ok = active & decide & ~link_lost & (sm_pilot > 0)
    unsafe = active & decide & ~link_lost & ~(sm_pilot > 0)
    blend = unsafe & blending
    rule = np.zeros(n, np.int8)
    blend_cmd = Command(nan.copy(), nan.copy(), nan.copy())
    sm_blend = nan.copy()
    for r, b in parts:
        sel = blend[r]
        if sel.any():
            j = r[sel]
            bc, br, bt_in = search_maneuver(own[j], intr[j], p_axis[j], p_dir[j], cfg, ref=pcmd[j], horizon_s=horizon,
                                            bands=b[sel], return_t_in=True)
            blend_cmd.trk[j], blend_cmd.vs[j], blend_cmd.gs[j] = bc.trk, bc.vs, bc.gs
            rule[j] = br
            sm_blend[j] = sm_from_tin(bt_in, horizon, cfg)
    return BlendStep(pilot_ok, unsafe, blend, blend_cmd, rule, sm_blend)


__all__ = ["LinkStep", "WaitStep", "BlendStep", "link_step", "wait_step", "blend_step"]
