"""Wait maps as objects, and vectorised lookup at continuous paper states.

**Lookup rule** (``WaitMap.lookup``; states ``(..., 6)`` = (dx, dy, dh, vi, vh, theta[rad])):

* Inside the box (dx, dy, dh within the grid's range): W, p_lowc, Q_wait and Q_evade are
  interpolated multilinearly over the 64 surrounding nodes (theta periodic; vi and vh outside
  their range are clamped to the nearest node and reported ``in_grid = False``). ``evade`` is
  ``Q_evade > Q_wait`` (ties wait), and ``W = 0`` where evade holds.
* Anywhere, a state that is in LoWC now (paper Eq. 9, continuous predicate) gets
  ``W = 0, evade = True, p_lowc = 1`` ("inside": no waiting at all).
* Outside the box and not in LoWC ("far"): ``W = min(H, straight-line time to LoWC)`` (so a
  diverging or passing intruder gives ``W = H``, no constraint), ``p_lowc`` = 1 if that straight-line
  LoWC happens within H else 0, ``evade`` only if ``W == 0``, ``in_grid = False``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import wellclear as wc
from .grid import Grid
from .model import DEG, MdpParams
from .transitions import lowc_states, relative_sv


@dataclass
class LookupResult:
    """Per-state lookup answer; all arrays have the batch shape of the query."""

    wait_s: np.ndarray  #: allowed wait, s (0 = act now, H = no constraint)
    p_lowc: np.ndarray  #: P(LoWC within H if the UAS keeps waiting)
    evade: np.ndarray  #: bool, the MDP prefers evade (or LoWC now)
    in_grid: np.ndarray  #: bool, the state was inside every axis range


def interpolate(grid: Grid, fields: np.ndarray, states: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Multilinear interpolation of ``fields`` (``(*grid.shape, m)``) at ``states`` (``(N, 6)``).

    Returns ``(values (N, m), inside_box (N,), inside_all (N,))``; axes are clamped at their ends.
    """
    w = [grid.axes[a].weights(states[:, a]) for a in range(6)]
    inside_box = w[0][3] & w[1][3] & w[2][3]
    inside_all = inside_box & w[3][3] & w[4][3]
    flat = fields.reshape(-1, fields.shape[-1])
    strides = np.cumprod((1,) + grid.shape[::-1][:-1])[::-1]
    out = np.zeros((states.shape[0], fields.shape[-1]))
    for c in range(64):
        idx = np.zeros(states.shape[0], np.int64)
        wt = np.ones(states.shape[0])
        for a in range(6):
            hi = (c >> a) & 1
            idx += (w[a][1] if hi else w[a][0]) * strides[a]
            wt *= w[a][2] if hi else 1.0 - w[a][2]
        out += wt[:, None] * flat[idx]
    return out, inside_box, inside_all


@dataclass
class WaitMap:
    """One solved wait map on a grid (arrays shaped ``grid.shape``)."""

    grid: Grid
    params: MdpParams
    turn_rate_deg: float  #: the conditioning initial turn rate, deg/s (+ = left)
    wait_s: np.ndarray
    p_lowc: np.ndarray
    p_act: np.ndarray  #: P(LoWC or an evade-optimal state within H while waiting)
    q_wait: np.ndarray
    q_evade: np.ndarray
    lowc: np.ndarray  #: bool, LoWC nodes
    stats: dict  #: solver statistics and timings
    content_hash: str = ""

    @property
    def evade(self) -> np.ndarray:
        """Evade-optimal or LoWC nodes (bool)."""
        return (self.q_evade > self.q_wait) | self.lowc

    def lookup(self, paper_states) -> LookupResult:
        """Wait time etc. at continuous paper states ``(..., 6)`` (theta in rad). See module docstring."""
        st = np.asarray(paper_states, dtype=float)
        if st.shape[-1:] != (6,):
            raise ValueError(f"paper_states must have shape (..., 6), got {st.shape}")
        batch = st.shape[:-1]
        st = st.reshape(-1, 6)
        fields = np.stack([self.wait_s, self.p_lowc, self.q_wait, self.q_evade], axis=-1)
        vals, in_box, in_all = interpolate(self.grid, fields, st)
        H = self.params.horizon
        ev = vals[:, 3] > vals[:, 2]
        w = np.where(ev, 0.0, np.clip(vals[:, 0], 0.0, H))
        pl = np.clip(vals[:, 1], 0.0, 1.0)
        if not np.all(in_box):
            s, v = relative_sv(*(st[:, i] for i in range(6)), self.params.v_own)
            t_in = wc.time_to_violation(s, v, self.params.thresholds, lookahead=H)
            far_w = np.where(np.isfinite(t_in), np.minimum(t_in, H), H)
            w = np.where(in_box, w, far_w)
            pl = np.where(in_box, pl, np.isfinite(t_in).astype(float))
            ev = np.where(in_box, ev, far_w <= 0.0)
        now = lowc_states(st, self.params)
        w = np.where(now, 0.0, w)
        pl = np.where(now, 1.0, pl)
        ev = ev | now
        return LookupResult(w.reshape(batch), pl.reshape(batch), ev.reshape(batch), in_all.reshape(batch))


@dataclass
class WaitMapFamily:
    """Maps of one grid/parameter set, one per conditioning turn rate."""

    maps: list  #: list[WaitMap], sorted by turn rate

    @property
    def turn_rates_deg(self) -> np.ndarray:
        return np.array([m.turn_rate_deg for m in self.maps])

    def nearest(self, turn_rate) -> np.ndarray:
        """Index of the map whose condition is nearest to ``turn_rate`` (rad/s, + = left)."""
        tr = np.asarray(turn_rate, dtype=float) / DEG
        return np.argmin(np.abs(tr[..., None] - self.turn_rates_deg), axis=-1)

    def map_for(self, turn_rate_deg: float) -> WaitMap:
        """The map of the nearest condition to a turn rate in deg/s."""
        return self.maps[int(self.nearest(turn_rate_deg * DEG))]

    def lookup(self, paper_states, turn_rate) -> LookupResult:
        """Lookup with per-state turn rates ``(...)`` in rad/s (paper sense, + = left)."""
        st = np.asarray(paper_states, dtype=float)
        batch = st.shape[:-1]
        idx = np.broadcast_to(self.nearest(turn_rate), batch).ravel()
        st = st.reshape(-1, 6)
        w = np.zeros(st.shape[0])
        pl = np.zeros(st.shape[0])
        ev = np.zeros(st.shape[0], bool)
        ig = np.zeros(st.shape[0], bool)
        for i, m in enumerate(self.maps):
            sel = idx == i
            if np.any(sel):
                r = m.lookup(st[sel])
                w[sel], pl[sel], ev[sel], ig[sel] = r.wait_s, r.p_lowc, r.evade, r.in_grid
        return LookupResult(w.reshape(batch), pl.reshape(batch), ev.reshape(batch), ig.reshape(batch))
