"""The wait function w(S(k)) of the allocation agent (paper Eq. 11): a constant, "always wait", none,
or the MDP wait map read at the current state (:func:`make_wait_lookup`), per row of a batch by each
row's policy (:func:`wait_values`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from daa_sil.agent.allocation import PolicyRows
from daa_sil.config.choices import OUTSIDE_BOX
from daa_sil.daa.config import DaaConfig
from daa_sil.errors import UsageError
from daa_sil.geometry.frames import to_paper_state
from daa_sil.geometry.kinematics import AircraftState
from daa_sil.geometry import wellclear as wc
from daa_sil.daa.alerting import relative_state


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


def wait_none(constant_s: np.ndarray, lookup: "WaitLookup | None" = None) -> WaitLookup:
    """``none``: w = 0, the agent never waits (B-1, B-2: the DAA decides at once)."""
    return lambda own, intr, turn_rate: WaitValue.constant(intr.shape[0], 0.0)


def wait_constant(constant_s: np.ndarray, lookup: "WaitLookup | None" = None) -> WaitLookup:
    """``constant``: w = each row's ``constant_wait_s`` (s; IC-1)."""

    def constant(own: AircraftState, intr: AircraftState, turn_rate: np.ndarray) -> WaitValue:
        out = WaitValue.constant(intr.shape[0], 0.0)
        out.wait_s[:] = constant_s
        return out

    return constant


def wait_always(constant_s: np.ndarray, lookup: "WaitLookup | None" = None) -> WaitLookup:
    """``always``: w = +inf, the map ignored: wait unless ProjL (the ``ID-2-projl`` ablation)."""
    return lambda own, intr, turn_rate: WaitValue.constant(intr.shape[0], np.inf)


def wait_map(constant_s: np.ndarray, lookup: "WaitLookup | None" = None) -> WaitLookup:
    """``map``: the MDP wait map read at the current state (``lookup``, :func:`make_wait_lookup`)."""
    if lookup is None:
        raise UsageError("policy wait_mode 'map' needs a wait_lookup (daa_sil.agent.step.make_wait_lookup)")
    return lookup


#: the wait functions by name (:data:`daa_sil.config.policy.WAIT_MODES`): each makes a
#: :data:`WaitLookup` from the rows' constant waits (s) and the map lookup (None when no map is read)
WAIT_FUNCTIONS: dict[str, Callable[..., WaitLookup]] = {
    "none": wait_none, "constant": wait_constant, "map": wait_map, "always": wait_always}


def wait_values(own, intr, pol: PolicyRows, lookup: "WaitLookup | None", turn_rate, idx) -> WaitValue:
    """The wait function of rows ``idx`` (ownship (N,), intruders (N, M), estimated turn rates (N, M)
    compass rad/s or None = 0), each by its own policy's wait mode (:data:`WAIT_FUNCTIONS`; one call
    per mode present)."""
    out = WaitValue.constant(len(idx), 0.0)
    rate = np.zeros(intr.shape) if turn_rate is None else np.broadcast_to(np.asarray(turn_rate, float), intr.shape)
    for mode, pos in pol.modes(idx):
        rows = idx[pos]
        w = WAIT_FUNCTIONS[mode](pol.constant_wait_s[rows], lookup)
        wv = w(own[rows], intr[rows], rate[rows])
        out.wait_s[pos], out.p_lowc[pos], out.in_box[pos] = wv.wait_s, wv.p_lowc, wv.in_box
        out.turn_dps[pos], out.map_turn_dps[pos] = wv.turn_dps, wv.map_turn_dps
    return out


def make_wait_lookup(family, cfg: "DaaConfig | None" = None, outside: str = "clamp") -> WaitLookup:
    """Wrap a wait-map family (``family.lookup(paper_states, turn_rate)``) as a :data:`WaitLookup`.

    Each intruder is converted to the paper frame (:func:`daa_sil.geometry.frames.to_paper_state`) and read
    from the map of its estimated turn rate (compass rad/s, + = right, passed to the family in the
    paper sense, + = left). The wait of the **most threatening** intruder is used: the one with the
    earliest straight-line LoWC over the DAA lookahead (ties: the smallest range). ``outside``
    (:data:`~daa_sil.config.choices.OUTSIDE_BOX`): a state outside the map's box reads

    * ``clamp`` -- the nearest state of the box;
    * ``far`` -- w = H, the map's horizon (the map does not model that intruder; the ProjL veto still
      applies, and a LoWC in progress is always within ProjL's look-ahead);
    * ``approach`` -- w = min(H, t_in + w(s_in)): ``t_in`` (s) the time the relative position needs,
      on straight lines at the current velocities, to enter the box, ``s_in`` the state there (same
      speeds and heading); w = H when it never enters. The wait then falls by one second per second
      as the intruder closes on the box, and meets the map's own value at its edge (the paper: "The
      decrease in the wait time is observed as the relative X distance reduces"). ``p_lowc`` is the
      entry state's (0 when it never enters).
    """
    cfg = cfg or DaaConfig()
    if outside not in OUTSIDE_BOX:
        raise UsageError(f"outside must be one of {', '.join(OUTSIDE_BOX)}, got {outside!r}")
    horizon = float(family.params.horizon) if outside == "far" else None
    box = box_bounds(family.grid) if outside == "approach" else None

    def lookup(own: AircraftState, intr: AircraftState, turn_rate: np.ndarray) -> WaitValue:
        n, m = intr.shape
        if m == 0:
            return WaitValue.constant(n, np.inf)
        paper = to_paper_state(own.position()[:, None], own.velocity()[:, None], intr.position(), intr.velocity())
        rate = np.broadcast_to(np.asarray(turn_rate, float), (n, m))
        res = family.lookup(paper, -rate)
        if horizon is not None:
            res.wait_s = np.where(np.asarray(res.in_box, bool), res.wait_s, horizon)
        if box is not None:
            one_s_on = to_paper_state(own.position()[:, None] + own.velocity()[:, None], own.velocity()[:, None],
                                      intr.position() + intr.velocity(), intr.velocity())
            res.wait_s, res.p_lowc = approach_wait(family, paper, one_s_on[..., :3] - paper[..., :3], -rate, res, box)
        s, v = relative_state(own, intr)
        t_in, _ = wc.violation_interval(s, v, cfg.th, 0.0, cfg.lookahead_s)
        key = np.minimum(t_in, 1e9) * 1e6 + wc.horizontal_range(s)
        k = np.argmin(key, axis=1)
        r = np.arange(n)
        return WaitValue(np.asarray(res.wait_s, float)[r, k], np.asarray(res.p_lowc, float)[r, k],
                         np.asarray(res.in_box, bool)[r, k], np.degrees(rate[r, k]),
                         0.0 - np.asarray(res.map_turn_deg, float)[r, k])  # 0.0 - x: no -0.0 for the 0 map

    return lookup


def box_bounds(grid) -> tuple[np.ndarray, np.ndarray]:
    """``(lo, hi)`` (3,) of a grid's box in (dx, dy, dh), m."""
    return (np.array([grid.axes[a].lo for a in range(3)], float), np.array([grid.axes[a].hi for a in range(3)], float))


def box_entry_time(pos: np.ndarray, vel: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Time (s) until the straight line ``pos + vel t`` (``(..., 3)``, m and m/s) enters the box
    ``[lo, hi]``: 0 inside it, ``inf`` when it never enters at t >= 0 (slab method)."""
    pos, vel = np.asarray(pos, float), np.asarray(vel, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = (lo - pos) / vel, (hi - pos) / vel
    still = vel == 0.0
    inside = (pos >= lo) & (pos <= hi)
    near = np.where(still, np.where(inside, -np.inf, np.inf), np.minimum(t1, t2))
    far = np.where(still, np.where(inside, np.inf, -np.inf), np.maximum(t1, t2))
    t_in, t_out = near.max(axis=-1), far.min(axis=-1)
    enters = (t_in <= t_out) & (t_out >= 0.0)
    return np.where(enters, np.maximum(t_in, 0.0), np.inf)


def approach_wait(family, paper: np.ndarray, vrel: np.ndarray, rate_paper: np.ndarray, res, box) -> tuple:
    """The ``approach`` rule's ``(wait_s, p_lowc)`` (``(N, M)``) given the clamped lookup ``res`` at the
    paper states ``paper`` (``(N, M, 6)``) with relative velocities ``vrel`` (``(N, M, 3)``, m/s, the
    paper frame) and the map turn rates ``rate_paper`` (rad/s, + = left): inside the box the map's
    values; outside ``min(H, t_in + w(entry state))`` and the entry state's ``p_lowc`` (``H`` and 0
    when the state never enters)."""
    horizon = float(family.params.horizon)
    inside = np.asarray(res.in_box, bool)
    t_in = box_entry_time(paper[..., :3], vrel, *box)
    enter = ~inside & np.isfinite(t_in)
    wait = np.where(inside, res.wait_s, horizon).astype(float)
    p = np.where(inside, res.p_lowc, 0.0).astype(float)
    if enter.any():
        entry = paper[enter].copy()
        entry[:, :3] += vrel[enter] * t_in[enter][:, None]
        got = family.lookup(entry, np.broadcast_to(rate_paper, enter.shape)[enter])
        wait[enter] = np.minimum(horizon, t_in[enter] + np.asarray(got.wait_s, float))
        p[enter] = got.p_lowc
    return wait, p


__all__ = ["WaitValue", "WaitLookup", "WAIT_FUNCTIONS", "wait_none", "wait_constant", "wait_always", "wait_map",
           "wait_values", "make_wait_lookup", "box_bounds", "box_entry_time", "approach_wait"]
