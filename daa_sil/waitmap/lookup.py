"""Wait maps as objects, and vectorised lookup at continuous paper states.

**Lookup rule** (``WaitMap.lookup``; states ``(..., 6)`` = (dx, dy, dh, vi, vh, theta[rad])):

* The state is **clamped** onto the grid's box (every non-periodic axis) and the node fields are
  interpolated multilinearly over the 64 surrounding nodes (theta periodic). Inside the box this is
  plain interpolation; outside it is the paper's "the agent matches the current state with a state
  in the wait map" read as the nearest point of the map. ``in_box`` says whether (dx, dy, dh) was
  inside the box, ``in_grid`` whether every axis was.
* ``evade`` is ``Q_wait < 0`` (``Q_evade = 0``: R_e = 0 and OUT is terminal), interpolated.
* Wait time by the map's ``wait_definition``: ``paper`` interpolates ``p_lowc`` and ``t_lowc``
  **separately** and divides (``W = t_lowc / p_lowc``, a p-weighted mean of the corner waits), then
  applies the map's floor ``p_min`` (``W = H`` below it); interpolating W itself across the edge of
  the ``p = 0`` region would give meaningless midpoints. ``until_evade`` interpolates W. Either way
  ``W = 0`` where ``evade``.
* A state that is in LoWC now (paper Eq. 9, continuous predicate) gets ``W = 0, evade = True,
  p_lowc = 1``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .grid import Grid
from .model import DEG, MdpParams
from .transitions import lowc_states
from .solve import paper_wait


@dataclass
class LookupResult:
    """Per-state lookup answer; all arrays have the batch shape of the query."""

    wait_s: np.ndarray  #: allowed wait, s (0 = act now, H = no constraint)
    p_lowc: np.ndarray  #: P(LoWC within H if the UAS keeps waiting)
    evade: np.ndarray  #: bool, the MDP prefers evade (or LoWC now)
    in_grid: np.ndarray  #: bool, the state was inside every axis range
    in_box: np.ndarray  #: bool, (dx, dy, dh) was inside the map's box (no clamping of positions)
    map_turn_deg: "np.ndarray | None" = None  #: conditioning turn rate of the map read (deg/s, + = left)


def interpolate(grid: Grid, fields: np.ndarray, states: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Multilinear interpolation of ``fields`` (``(*grid.shape, m)``) at ``states`` (``(N, 6)``).

    Returns ``(values (N, m), inside_box (N,), inside_all (N,))``; axes are clamped at their ends.
    All 64 corners at once: an ``(N, 64)`` index matrix (the non-periodic axes' upper node is always
    the lower one + 1, so their corner offsets are constants; theta wraps) and the outer product of
    the per-axis weights.
    """
    w = [grid.axes[a].weights(states[:, a]) for a in range(6)]
    inside_box = w[0][3] & w[1][3] & w[2][3]
    inside_all = inside_box & w[3][3] & w[4][3]
    flat = fields.reshape(-1, fields.shape[-1])
    strides = np.cumprod((1,) + grid.shape[::-1][:-1])[::-1]
    n = states.shape[0]
    base = sum(w[a][0] * strides[a] for a in range(5))
    bits = (np.arange(32)[:, None] >> np.arange(5)[None, :]) & 1  # corner c -> upper node on axis a?
    # an axis with one node (or clamped to one) has i1 == i0: the offset follows the actual indices
    step = np.stack([(w[a][1] - w[a][0]) * strides[a] for a in range(5)], axis=1)  # (N, 5)
    idx5 = base[:, None] + step @ bits.T  # (N, 32)
    idx = (idx5[:, None, :] + np.stack([w[5][0], w[5][1]], axis=1)[:, :, None] * strides[5]).reshape(n, 64)
    wt = np.ones((n, 32))
    for a in range(5):
        wt *= np.where(bits[:, a][None, :] == 1, w[a][2][:, None], 1.0 - w[a][2][:, None])
    wt = (np.stack([1.0 - w[5][2], w[5][2]], axis=1)[:, :, None] * wt[:, None, :]).reshape(n, 64)
    out = np.einsum("nc,ncm->nm", wt, flat[idx].astype(float))
    return out, inside_box, inside_all


#: the node fields a lookup interpolates (stored float32)
FIELDS = ("p_lowc", "t_lowc", "q_wait", "wait_s")


def side_by_side(arrays: list) -> "np.ndarray | None":
    """The ``(..., len(arrays))`` float32 array whose ``[..., i]`` are ``arrays[i]`` when they already are
    such views of one array (as :func:`daa_sil.waitmap.store.load` reads a map's fields), else None."""
    base = arrays[0].base if isinstance(arrays[0], np.ndarray) else None
    if not (isinstance(base, np.ndarray) and base.dtype == np.float32 and base.flags.c_contiguous
            and base.ndim >= 1 and base.shape[-1] == len(arrays)):
        return None
    for i, a in enumerate(arrays):
        if not (isinstance(a, np.ndarray) and a.base is base and a.dtype == np.float32 and a.shape == base.shape[:-1]
                and a.strides == base.strides[:-1] and a.ctypes.data == base.ctypes.data + i * base.itemsize):
            return None
    return base


@dataclass
class WaitMap:
    """One solved wait map on a grid (arrays shaped ``grid.shape``; times in s)."""

    grid: Grid
    params: MdpParams
    turn_rate_deg: float  #: the conditioning initial turn rate, deg/s (+ = left)
    wait_s: np.ndarray  #: node wait time of ``params.wait_definition``
    p_lowc: np.ndarray  #: P(LoWC within H while waiting)
    t_lowc: np.ndarray  #: E[T_LoWC 1{T_LoWC <= H}] while waiting, s
    q_wait: np.ndarray  #: Q(s, wait); Q(s, evade) = 0
    lowc: np.ndarray  #: bool, LoWC nodes
    stats: dict  #: solver statistics and timings
    content_hash: str = ""

    @property
    def evade(self) -> np.ndarray:
        """Evade-optimal or LoWC nodes (bool)."""
        return (self.q_wait < 0.0) | self.lowc

    def __post_init__(self):
        # The interpolated fields side by side in float32, so one gather per corner reads all four;
        # the public arrays are views into it (a family of large maps is held once, also in forked
        # campaign workers). Single precision holds them to ~1e-7 relative.
        shape = np.shape(getattr(self, FIELDS[0]))
        if any(np.shape(getattr(self, n)) != shape for n in FIELDS):
            raise ValueError(f"wait-map fields {FIELDS} must have one shape, got "
                             f"{[np.shape(getattr(self, n)) for n in FIELDS]}")
        f = side_by_side([getattr(self, n) for n in FIELDS])
        if f is None:
            f = np.empty(shape + (len(FIELDS),), np.float32)
            for i, n in enumerate(FIELDS):  # cast in place (the same rounding as astype; no float32 copies to stack)
                f[..., i] = getattr(self, n)
        self._fields = f
        for i, n in enumerate(FIELDS):
            setattr(self, n, f[..., i])
        self.lowc = np.asarray(self.lowc, bool)

    def lookup(self, paper_states) -> LookupResult:
        """Wait time etc. at continuous paper states ``(..., 6)`` (theta in rad). See module docstring."""

        st = np.asarray(paper_states, dtype=float)
        if st.shape[-1:] != (6,):
            raise ValueError(f"paper_states must have shape (..., 6), got {st.shape}")
        batch = st.shape[:-1]
        st = st.reshape(-1, 6)
        vals, in_box, in_all = interpolate(self.grid, self._fields, st)
        H = self.params.horizon
        pl, tl, q = np.clip(vals[:, 0], 0.0, 1.0), vals[:, 1], vals[:, 2]
        ev = q < 0.0
        if self.params.wait_definition == "paper":
            w = paper_wait(tl, pl, ev, self.params)
        else:
            w = np.where(ev, 0.0, np.clip(vals[:, 3], 0.0, H))
        now = lowc_states(st, self.params)
        w = np.where(now, 0.0, w)
        pl = np.where(now, 1.0, pl)
        ev = ev | now
        return LookupResult(w.reshape(batch), pl.reshape(batch), ev.reshape(batch), in_all.reshape(batch),
                            in_box.reshape(batch), np.full(batch, float(self.turn_rate_deg)))


@dataclass
class WaitMapFamily:
    """Maps of one grid/parameter set, one per conditioning turn rate."""

    maps: list  #: list[WaitMap], sorted by turn rate

    @property
    def turn_rates_deg(self) -> np.ndarray:
        return np.array([m.turn_rate_deg for m in self.maps])

    @property
    def grid(self) -> Grid:
        return self.maps[0].grid

    @property
    def params(self) -> MdpParams:
        return self.maps[0].params

    def nearest(self, turn_rate) -> np.ndarray:
        """Index of the map whose condition is nearest to ``turn_rate`` (rad/s, + = left); ties go
        to the map nearer to 0 deg/s (the less extreme assumption)."""
        tr = np.asarray(turn_rate, dtype=float) / DEG
        rates = self.turn_rates_deg
        dist = np.abs(tr[..., None] - rates) + 1e-9 * np.abs(rates)
        return np.argmin(dist, axis=-1)

    def map_for(self, turn_rate_deg: float) -> WaitMap:
        """The map of the nearest condition to a turn rate in deg/s."""
        return self.maps[int(self.nearest(turn_rate_deg * DEG))]

    def lookup(self, paper_states, turn_rate) -> LookupResult:
        """Lookup with per-state turn rates ``(...)`` in rad/s (paper sense, + = left): each state
        reads the map of the nearest conditioning turn rate."""
        st = np.asarray(paper_states, dtype=float)
        batch = st.shape[:-1]
        idx = np.broadcast_to(self.nearest(turn_rate), batch).ravel()
        st = st.reshape(-1, 6)
        n = st.shape[0]
        w, pl, mt = np.zeros(n), np.zeros(n), np.zeros(n)
        ev, ig, ib = np.zeros(n, bool), np.zeros(n, bool), np.zeros(n, bool)
        for i, m in enumerate(self.maps):
            sel = idx == i
            if np.any(sel):
                r = m.lookup(st[sel])
                w[sel], pl[sel], ev[sel], ig[sel], ib[sel] = r.wait_s, r.p_lowc, r.evade, r.in_grid, r.in_box
                mt[sel] = m.turn_rate_deg
        return LookupResult(w.reshape(batch), pl.reshape(batch), ev.reshape(batch), ig.reshape(batch),
                            ib.reshape(batch), mt.reshape(batch))
