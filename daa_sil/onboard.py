"""The vehicle's per-step logic as a batched sans-IO state machine (step 2 of the step order).

:class:`OnboardCore` is used by fast-time with N encounters and by the SIL vehicle process with
N = 1, so the two run the same code (parity by construction). It holds the truth state (ownship
``(N,)``, intruders ``(N, M)``, the intruders' scripted controls), the agent memory, the wait-map
lookup, the DAA configuration and the allocation policy. :meth:`OnboardCore.step` at sim time
``t_k``:

1. updates each intruder's turn-rate estimate from the tracks it has seen
   (:class:`TurnRateEstimator`; it picks the wait map), then runs DAA + wait map + agent
   (:func:`daa_sil.agent.step.agent_step`) on the truth state at ``t_k`` with the pilot input that
   arrived at or before ``t_k``;
2. returns the command flown, the decision record and the telemetry for ``t_k`` (ownship,
   intruders, alert levels, band summary) -- the caller downlinks it;
3. advances truth by ``dt`` (ownship :func:`~daa_sil.geometry.kinematics.fly_command`, intruders
   :func:`~daa_sil.geometry.kinematics.advance` with their scripted turn rate / accelerations);
4. evaluates LoWC and NMAC on the continuous segment ``[t_k, t_k + dt]``
   (:func:`daa_sil.geometry.wellclear.segment_events`; an event strictly between samples is detected),
   the time spent in LoWC on the segment, the minimum range on it, and the penetration integral over the segment's LoWC interval
   (:func:`daa_sil.geometry.penetration.segment_penetration`, with the preset's and with the paper's constants).

Sans-IO: no sockets, no clock; the caller supplies ``t`` and the pilot input and moves the bytes.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Callable

import numpy as np

from daa_sil.config.settings import STEP
from daa_sil.agent.decision import Decision
from .geometry import wellclear as wc
from daa_sil.geometry import penetration as pen
from daa_sil.geometry.frames import wrap_pi
from daa_sil.geometry.kinematics import AircraftState, Command, Performance, advance, fly_command
from .daa.alerting import relative_state
from .daa.intervals import interval_soa
from daa_sil.models.intruder_flight import INTRUDER_PERFORMANCE
from daa_sil.geometry.thresholds import Thresholds, get_thresholds
from .daa.config import DEFAULT_CONFIG

#: ``controls(t) -> (turn_rate rad/s compass +right, accel m/s^2, vertical_accel m/s^2)``, each (N, M)
IntruderControls = Callable[[float], "tuple[np.ndarray, np.ndarray, np.ndarray]"]


@dataclass
class Telemetry:
    """What the vehicle downlinks for sim time ``t`` (s): truth states, alert levels, band summary."""

    t: float
    own: AircraftState  #: (N,)
    intruders: AircraftState  #: (N, M)
    alert_level: np.ndarray  #: (N, M) int8, 0..3
    #: the decision record's track bands ``(values (N, K) deg, region codes (N, K))``, None without them
    bands: "tuple[np.ndarray, np.ndarray] | None" = None

    @cached_property
    def extra(self) -> dict:
        """The band summary (:func:`band_intervals` of :attr:`bands`; empty without bands), computed when
        first read: a fast-time step log reads it, the SIL vehicle does not."""
        return band_intervals(*self.bands) if self.bands is not None else {}


@dataclass
class StepOutput:
    """Result of one :meth:`OnboardCore.step` (arrays have a leading encounter axis N)."""

    step: int
    t: float  #: s, the sample time the decision was made at
    own: AircraftState  #: (N,) truth at t
    intruders: AircraftState  #: (N, M) truth at t
    command: Command  #: (N,) command flown over [t, t + dt]
    decisions: "Decision"  #: the agent's decision record (:class:`daa_sil.agent.decision.Decision`)
    telemetry: Telemetry  #: downlink payload for t
    geometry: "dict | None"  #: (N, M) range_m, hmd_m, dh_m, tau_mod_s, wcv at t (None without a step log)
    lowc: np.ndarray  #: (N,) LoWC with any intruder on [t, t + dt]
    nmac: np.ndarray  #: (N,) NMAC with any intruder on [t, t + dt]
    #: the segment's outcome figures fast-time sums (None when the core was built with ``outcomes=False``):
    lowc_time_s: "np.ndarray | None"  #: (N,) s in LoWC on the segment (max over intruders)
    seg_min_range_m: "np.ndarray | None"  #: (N,) minimum horizontal range on the segment (over intruders)
    seg_vsep_m: "np.ndarray | None"  #: (N,) vertical separation at that minimum
    turn_est: "np.ndarray | None" = None  #: (N, M) estimated intruder turn rates, compass rad/s
    # -- PI on the continuous segment (issue 14): integrated over the LoWC interval of [t, t + dt] --
    pi_s: "np.ndarray | None" = None  #: (N,) s, PI on the segment with the preset's constants (max over intruders)
    pi_paper_s: "np.ndarray | None" = None  #: (N,) s, same with the paper's Eq. constants (4000 ft/450 ft/35 s)


class TurnRateEstimator:
    """Each intruder's turn rate from its observed track history (batched, sans-IO).

    :meth:`update` takes the intruders the core sees at sim time ``t`` (s) and returns ``(N, M)``
    estimates in compass rad/s (+ = right): the wrapped track change from the oldest of the last
    ``window`` observations to the newest, over the time between them (0 until two observations).
    Window 3 (2 s at dt = 1 s) follows a constant-rate turn exactly two steps after it starts and
    does not mistake a single step's change for a turn rate. The same object runs in fast-time and
    in the SIL vehicle (inside :class:`OnboardCore`), so both pick the same wait map.
    """

    def __init__(self, shape: tuple[int, int], window: int = 3):
        if window < 2:
            raise ValueError(f"window must be >= 2 observations, got {window}")
        self.window = int(window)
        self._trk: list[np.ndarray] = []
        self._t: list[float] = []
        self.shape = tuple(shape)

    def add_columns(self, trk: np.ndarray) -> None:
        """New intruders (compass tracks now, rad, ``(N, k)``): their history is their track now, so their
        estimates are 0 until they are observed turning."""
        trk = np.asarray(trk, float)
        self._trk = [np.concatenate([a, trk], axis=1) for a in self._trk]
        self.shape = (self.shape[0], self.shape[1] + trk.shape[1])

    def update(self, t: float, intruders: AircraftState) -> np.ndarray:
        """Add the observation at ``t`` and return the current estimates ``(N, M)``, rad/s."""
        self._trk.append(np.array(intruders.trk, float))
        self._t.append(float(t))
        if len(self._t) > self.window:
            self._trk.pop(0)
            self._t.pop(0)
        span = self._t[-1] - self._t[0]
        if span <= 0:
            return np.zeros(self.shape)
        return wrap_pi(self._trk[-1] - self._trk[0]) / span


def band_intervals(values_deg: np.ndarray, region: np.ndarray) -> dict:
    """Merge per-candidate track bands ``(N, K)`` (degrees, low side first; region code, -1 = none)
    into intervals of equal region: ``bands_trk_lo_deg``, ``bands_trk_hi_deg``, ``bands_trk_region``
    padded ``(N, R)`` and ``bands_count`` ``(N,)``.

    The one definition of the step log's band summary (fast-time and the SIL vehicle): a sample with a
    non-finite value or a negative region is left out; each run of equal regions among the samples kept
    is one interval, from its first to its last sample's value (a sample left out does not split a
    run). Vectorised: the kept samples are moved to the front of their row, then run-length encoded."""
    reg = np.asarray(region, dtype=np.int64)
    vals = np.asarray(values_deg, dtype=float)
    n, k = reg.shape
    keep = (reg >= 0) & np.isfinite(vals)
    if not keep.any():  # no bands anywhere (every idle step of the SIL vehicle): nothing to merge
        return {"bands_trk_lo_deg": np.full((n, 0), np.nan), "bands_trk_hi_deg": np.full((n, 0), np.nan),
                "bands_trk_region": np.zeros((n, 0), np.int64), "bands_count": np.zeros(n, np.int64)}
    if not keep.all():
        order = np.argsort(~keep, axis=1, kind="stable")  # kept samples first, in their order
        vals, reg = np.take_along_axis(vals, order, axis=1), np.take_along_axis(reg, order, axis=1)
        keep = np.arange(k)[None, :] < keep.sum(axis=1)[:, None]
        reg = np.where(keep, reg, -1)
    starts = keep.copy()
    starts[:, 1:] &= reg[:, 1:] != reg[:, :-1]
    ends = keep.copy()
    ends[:, :-1] &= reg[:, :-1] != reg[:, 1:]
    count = starts.sum(axis=1)
    width = int(count.max(initial=0))
    s_idx = np.argsort(~starts, axis=1, kind="stable")[:, :width]
    e_idx = np.argsort(~ends, axis=1, kind="stable")[:, :width]
    ok = np.arange(width)[None, :] < count[:, None]
    take = lambda a, i: np.take_along_axis(a, i, axis=1)  # noqa: E731
    return {"bands_trk_lo_deg": np.where(ok, take(vals, s_idx), np.nan),
            "bands_trk_hi_deg": np.where(ok, take(vals, e_idx), np.nan),
            "bands_trk_region": np.where(ok, take(reg, s_idx), 0), "bands_count": count}


class OnboardCore:
    """Batched vehicle logic: truth, DAA, wait map, agent. See the module docstring.

    Parameters: ``own`` (N,) and ``intruders`` (N, M) initial truth states; ``controls`` the
    intruder scripts; ``policy`` an :class:`~daa_sil.config.policy.AllocationPolicy`; ``daa_cfg`` a
    :class:`~daa_sil.daa.config.DaaConfig` (its thresholds are the LoWC volume unless
    ``thresholds`` is given); ``wait_lookup`` from :func:`daa_sil.agent.step.make_wait_lookup` (None when
    the policy needs no map); ``t0`` start time (s); ``dt`` step (s); ``perf`` ownship limits
    (default from ``daa_cfg``); ``intruder_perf`` limits for the scripted intruders. ``outcomes=False``
    skips the segment figures only fast-time's results read (``lowc_time_s``, ``seg_min_range_m``,
    ``seg_vsep_m``, ``pi_s``, ``pi_paper_s`` are then None; ~60 us a step at N = 1): the SIL vehicle
    reads ``lowc`` and ``nmac`` only.
    """

    def __init__(self, own: AircraftState, intruders: AircraftState, controls: IntruderControls, policy,
                 daa_cfg=None, wait_lookup=None, *, thresholds: "Thresholds | str | None" = None,
                 t0: float = 0.0, dt: float = STEP.default, perf: "Performance | None" = None,
                 intruder_perf: "Performance | None" = None, memory=None, step_log: bool = True,
                 outcomes: bool = True):
        from daa_sil.agent import step as agent  # lazy: start-up time

        self._agent = agent
        self.daa_cfg = daa_cfg if daa_cfg is not None else DEFAULT_CONFIG
        self.th = get_thresholds(thresholds) if thresholds is not None else self.daa_cfg.th
        own = own.copy()
        intr = intruders.copy()
        if own.x.ndim != 1 or intr.x.ndim != 2 or intr.shape[0] != own.shape[0]:
            raise ValueError(f"own must be (N,) and intruders (N, M); got {own.shape} and {intr.shape}")
        self.own, self.intruders = own, intr
        self.n, self.m = intr.shape
        self.controls = controls
        self.policy = policy
        self._policy_rows = None
        self.wait_lookup = wait_lookup
        self.dt = float(dt)
        self.t = float(t0)
        self.k = 0
        self.perf = perf if perf is not None else self.daa_cfg.performance()
        # intruders fly scripts beyond the ownship's limits (paper: up to 5 deg/s), as the sampler does
        self.intruder_perf = intruder_perf if intruder_perf is not None else INTRUDER_PERFORMANCE
        self.memory = memory if memory is not None else agent.AgentMemory.initial(self.n, self.own)
        self.turn_estimator = TurnRateEstimator((self.n, self.m))
        self.step_log = bool(step_log)
        self.outcomes = bool(outcomes)

    @classmethod
    def from_encounters(cls, encounters, policy, daa_cfg=None, wait_lookup=None, **kw) -> "OnboardCore":
        """Core for an :class:`~daa_sil.models.encounters.EncounterSet` (initial states at t = 0, its scripts)."""
        return cls(encounters.own, encounters.intr, encounters.intruder_controls, policy, daa_cfg, wait_lookup,
                   dt=encounters.dt_s, **kw)


    def add_intruders(self, intruders: AircraftState) -> None:
        """Fly ``intruders`` (``(N, k)`` states at the current time) from this step on as well: their scripts
        are straight flight at constant speed (no turn, no acceleration). For traffic that appears in
        flight (the SIL vehicle's injected intruders); fast-time never calls it."""
        k = intruders.shape[1]
        if intruders.x.ndim != 2 or intruders.shape[0] != self.n or k < 1:
            raise ValueError(f"intruders must be (N={self.n}, k >= 1); got {intruders.shape}")
        self.intruders = AircraftState(*(np.concatenate([getattr(self.intruders, f), getattr(intruders, f)], axis=1)
                                         for f in ("x", "y", "z", "gs", "trk", "vs")))
        base, n = self.controls, self.n

        def controls(t: float):
            return tuple(np.concatenate([c, np.zeros((n, k))], axis=1) for c in base(t))

        self.controls = controls
        self.m += k
        self.turn_estimator.add_columns(intruders.trk)

    def policy_rows(self):
        """:attr:`policy` as a :class:`~daa_sil.agent.allocation.PolicyRows` of the N rows, made again only when
        :attr:`policy` is replaced (the vehicle may switch it mid-flight), so its settings are read
        once, not on every step."""
        if self._policy_rows is None or self._policy_rows[0] is not self.policy:
            from daa_sil.agent.allocation import PolicyRows  # lazy: start-up time

            self._policy_rows = (self.policy, PolicyRows.of(self.policy, self.n))
        return self._policy_rows[1]

    def geometry(self, s=None, v=None) -> dict:
        """Per-intruder well-clear quantities at the current time, (N, M) each (``s``, ``v``: the
        relative state if already computed)."""
        if s is None:
            s, v = relative_state(self.own, self.intruders)
        return wc.encounter_geometry(s, v, self.th, self.daa_cfg.lookahead_s)

    def step(self, t: float, pilot_input) -> StepOutput:
        """Decide, publish telemetry for ``t`` (s), then advance truth to ``t + dt`` (see module doc)."""
        if not abs(float(t) - self.t) <= 1e-9:  # (nan fails too)
            raise ValueError(f"OnboardCore is at t={self.t:g} s, step() called with t={t:g} s")
        own0, intr0 = self.own, self.intruders
        turn_est = self.turn_estimator.update(t, intr0)
        cmd, dec, self.memory = self._agent.agent_step(t, own0, intr0, pilot_input, self.memory, self.policy_rows(),
                                                       self.daa_cfg, self.wait_lookup, turn_rate=turn_est,
                                                       band_record=self.step_log)
        alert = np.asarray(dec["alert_level"], dtype=np.int8).reshape(self.n, self.m)
        geom = None
        if self.step_log:
            s0, v0 = relative_state(own0, intr0)
            geom = self.geometry(s0, v0)
            telem = Telemetry(t, own0, intr0, alert, (dec["bands_trk"], dec["bands_trk_region"]))
        else:
            s0 = own0.position()[:, None] - intr0.position()  # relative_state's s, without the velocities
            telem = Telemetry(t, own0, intr0, alert)
        # --- truth advances by dt ----------------------------------------------------------------
        turn, acc, vacc = self.controls(t)
        own1 = fly_command(own0, cmd, self.dt, self.perf)
        intr1 = advance(intr0, turn, acc, vacc, self.dt, self.intruder_perf)
        s1 = own1.position()[:, None, :] - intr1.position()
        # LoWC on the segment: its violation interval (what wc.segment_events computes, once)
        v_seg = (s1 - s0) / self.dt
        # (wc.violation_interval over [0, dt], compiled: the same numbers, tests/test_daa_interval_kernel.py)
        t_in, t_out = (a.reshape(self.n, self.m) for a in interval_soa(
            *(c[..., i].reshape(-1) for c in (s0, v_seg) for i in range(3)), self.dt, self.th))
        lowc_m = np.isfinite(t_in)
        nmac_m = np.isfinite(wc.nmac_interval(s0, v_seg, self.th, self.dt)[0])
        out = StepOutput(step=self.k, t=float(t), own=own0, intruders=intr0, command=cmd, decisions=dec,
                         turn_est=turn_est, telemetry=telem, geometry=geom, lowc=lowc_m.any(axis=1),
                         nmac=nmac_m.any(axis=1), lowc_time_s=None, seg_min_range_m=None, seg_vsep_m=None)
        if self.outcomes:
            out.lowc_time_s = np.where(lowc_m, np.maximum(t_out - t_in, 0.0), 0.0).max(axis=1)
            # PI on the same segment and LoWC interval that detect the LoWC (issue 14)
            out.pi_s = pen.segment_penetration(s0, v_seg, t_in, t_out, pen.pi_constants(self.th)).max(axis=1)
            out.pi_paper_s = pen.segment_penetration(s0, v_seg, t_in, t_out, pen.PAPER_PI_CONSTANTS).max(axis=1)
            rmin, vsep = wc.min_separation_on_segment(s0, s1)
            j = np.argmin(rmin, axis=1)
            rows = np.arange(self.n)
            out.seg_min_range_m, out.seg_vsep_m = rmin[rows, j], vsep[rows, j]
        self.own, self.intruders = own1, intr1
        self.k += 1
        self.t = float(t) + self.dt
        return out


def step_columns(out: StepOutput, delay_up: np.ndarray, delay_down: np.ndarray) -> dict:
    """Step-log columns (:mod:`daa_sil.steplog`) of one :class:`StepOutput` (N encounters): the one row
    builder of fast-time and the SIL vehicle (which takes its row with :func:`daa_sil.steplog.step_row`).
    ``delay_up``, ``delay_down``: the link delays (s) at this step, ``(N,)`` or a scalar. Angles in
    degrees; codes stay integers (the step log names them)."""
    d, g, own, intr = out.decisions, out.geometry, out.own, out.intruders
    deg = np.degrees
    cols = {"step": np.full(own.shape[0], out.step, np.int32), "t": np.full(own.shape[0], out.t),
            "own_x": own.x, "own_y": own.y, "own_z": own.z, "own_gs": own.gs, "own_trk_deg": deg(own.trk),
            "own_vs": own.vs, "intr_x": intr.x, "intr_y": intr.y, "intr_z": intr.z, "intr_gs": intr.gs,
            "intr_trk_deg": deg(intr.trk), "intr_vs": intr.vs, "range_m": g["range_m"], "hmd_m": g["hmd_m"],
            "dh_m": g["dh_m"], "tau_mod_s": g["tau_mod_s"], "alert_level": out.telemetry.alert_level,
            "wcv": g["wcv"], "delay_up_s": delay_up, "delay_down_s": delay_down, "lowc": out.lowc, "nmac": out.nmac}
    for k in ("decision", "rule", "authority", "wait_s", "projl", "decided_by", "wait_p_lowc", "wait_in_box",
              "wait_map_turn_dps", "pilot_cmd_received", "pilot_cmd_age_s", "sm_pilot", "sm_exec", "pilot_axis",
              "pilot_dir", "exec_axis", "exec_dir"):
        cols[k] = d[k]
    cols["intr_turn_est_dps"] = deg(out.turn_est)
    for src, dst in (("cmd", "cmd"), ("pilot", "pilot"), ("daa", "daa")):
        cols[f"{dst}_trk_deg"] = deg(d[f"{src}_trk"])
        cols[f"{dst}_vs"] = d[f"{src}_vs"]
        cols[f"{dst}_gs"] = d[f"{src}_gs"]
    cols.update(out.telemetry.extra)
    return cols


