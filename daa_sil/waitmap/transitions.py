"""Transition model, rewards and the LoWC set of the wait-map MDP (paper Eq. 1-8, Table 1).

Kinematics per step (paper Eq. 1-6, ownship at ``v_own`` along +X, Y left, theta CCW):
``dx' = dx + (vi cos theta - v_own) dt``, ``dy' = dy + vi sin theta dt``, ``dh' = dh + vh dt``
(the position update uses the current velocity, so it does not depend on the maneuver), and
``vi' = vi + dvi``, ``theta' = theta + dtheta``, ``vh' = vh + dvh`` from the maneuver outcome.

Because positions move deterministically and the maneuver does not depend on position, the
waiting transition matrix factorises exactly (flat index = ``x * nk + k`` with ``x`` = (dx, dy, dh)
and ``k`` = (vi, vh, theta)):

    P_wait = Sp @ kron(I_nx, K)

* ``Sp`` (S x S, CSR): the spatial step, split over the <= 8 neighbouring (dx, dy, dh) nodes by
  multilinear weights, same ``k``. A row is empty when the next position leaves the box: that mass
  (``1 - rowsum``) goes to EXIT; nothing is clamped to the edge.
* ``K`` (nk x nk, CSR): the intruder maneuver, ``p_h A_vi (x) I_vh (x) A_theta + (1 - p_h) I_vi (x) A_vh (x) I_theta``,
  each ``A`` splitting the next value over its two neighbouring nodes. Speeds vi, vh **saturate** at
  their axis limits (the intruder's performance envelope); theta is periodic.

:func:`assemble` multiplies the factors into the full ``(S+3) x (S+3)`` CSR matrices with the special
states EXIT, LOWC and OUT appended (mass landing on a LoWC node goes to LOWC); the solver uses the
factors directly (about 5x fewer multiply-adds per sweep).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from daa_sil.geometry import wellclear as wc
from .grid import Grid
from .model import MdpParams, Outcome, outcomes
from .model import turn_distribution

#: offsets of the special states after the S grid states
EXIT, LOWC, OUT = 0, 1, 2


def relative_sv(dx, dy, dh, vi, vh, theta, v_own: float) -> tuple[np.ndarray, np.ndarray]:
    """Well-clear relative state (ownship minus intruder) ``(s, v)`` from paper-state components.

    The paper frame is a right-handed horizontal frame; all well-clear quantities are invariant to
    rotation, so it is used directly as the (x, y) plane.
    """
    dx, dy, dh, vi, vh, theta = np.broadcast_arrays(*(np.asarray(a, float) for a in (dx, dy, dh, vi, vh, theta)))
    s = np.stack([-dx, -dy, -dh], axis=-1)
    v = np.stack([v_own - vi * np.cos(theta), -vi * np.sin(theta), -vh], axis=-1)
    return s, v


def lowc_states(paper_states: np.ndarray, params: MdpParams) -> np.ndarray:
    """Paper Eq. 9 LoWC predicate (|d_h| <= d_h*, HMD <= HMD*, 0 <= tau_mod <= tau*) per state, bool."""
    p = np.asarray(paper_states, float)
    s, v = relative_sv(*(p[..., i] for i in range(6)), params.v_own)
    return wc.wcv(s, v, params.thresholds)


def reward_of(dxn, dyn, dhn, vin, thn, params: MdpParams) -> np.ndarray:
    """Paper Eq. 12 wait reward of arriving in S': ``-min(C1/HMD, C2/|d_h|) + C3 dt``.

    HMD is the horizontal miss distance of S' within ``hmd_horizon`` s (straight-line projection,
    t_cpa clipped to [0, T] as DAIDALUS ``hmd(s, v, T)``; T = tau_mod* by default, so an encounter
    whose CPA is further away than the alerting look-ahead is not yet penalised); HMD and |d_h| are
    floored at ``sep_floor`` so the divisions are finite.
    """
    s, v = relative_sv(dxn, dyn, 0.0, vin, 0.0, thn, params.v_own)
    h = np.maximum(wc.hmd(s, v, params.hmd_horizon), params.sep_floor)
    d = np.maximum(np.abs(dhn), params.sep_floor)
    return -np.minimum(params.c1 / h, params.c2 / d) + params.c3 * params.dt


def _axis_matrix(axis, deltas: np.ndarray, probs: np.ndarray) -> sp.csr_matrix:
    """n x n matrix of the next node of one kinematic axis: value + delta, saturated or periodic."""
    import scipy.sparse as sp  # lazy: start-up time; lazily: only building a map needs scipy

    vals = axis.values
    nxt = vals[:, None] + deltas[None, :]
    i0, i1, w1, _ = axis.weights(nxt)  # clamps (saturates) non-periodic axes at their ends
    rows = np.repeat(np.arange(axis.n), deltas.size)
    pr = np.tile(probs, axis.n)
    data = np.concatenate([pr * (1.0 - w1.ravel()), pr * w1.ravel()])
    m = sp.csr_matrix((data, (np.tile(rows, 2), np.concatenate([i0.ravel(), i1.ravel()]))),
                      shape=(axis.n, axis.n))
    m.sum_duplicates()
    m.eliminate_zeros()
    return m


def kinematic_matrix(grid: Grid, params: MdpParams, turn_rate_deg: float) -> sp.csr_matrix:
    """K (nk x nk, CSR, rows sum to 1): the intruder maneuver over the (vi, vh, theta) nodes."""
    import scipy.sparse as sp  # lazy: start-up time; lazily: only building a map needs scipy


    a_vi_d = np.array([v for v, _ in params.dv]) * params.dt
    a_vi_p = np.array([p for _, p in params.dv])
    tv, tp = turn_distribution(params, turn_rate_deg)
    a_vh_d = np.array([v for v, _ in params.dvh]) * params.dt
    a_vh_p = np.array([p for _, p in params.dvh])
    vi, vh, th = grid.axis("vi"), grid.axis("vh"), grid.axis("theta")
    a_vi = _axis_matrix(vi, a_vi_d, a_vi_p)
    a_th = _axis_matrix(th, tv * params.dt, tp)
    a_vh = _axis_matrix(vh, a_vh_d, a_vh_p)
    kh = sp.kron(sp.kron(a_vi, sp.identity(vh.n)), a_th)
    kv = sp.kron(sp.kron(sp.identity(vi.n), a_vh), sp.identity(th.n))
    k = (params.p_horizontal * kh + (1.0 - params.p_horizontal) * kv).tocsr()
    k.eliminate_zeros()
    return k


def spatial_matrix(grid: Grid, params: MdpParams) -> sp.csr_matrix:
    """Sp (S x S, CSR): the deterministic position step split over <= 8 nodes; EXIT rows are empty."""
    import scipy.sparse as sp  # lazy: start-up time; lazily: only building a map needs scipy

    shape = grid.shape
    nk = shape[3] * shape[4] * shape[5]
    ax = [grid.axes[i].values for i in range(6)]
    dx, dy, dh, vi, vh, th = np.meshgrid(*ax, indexing="ij", sparse=True)
    dxn = dx + (vi * np.cos(th) - params.v_own) * params.dt
    dyn = dy + vi * np.sin(th) * params.dt
    dhn = dh + vh * params.dt
    wts = [grid.axes[i].weights(np.broadcast_to(a, shape).ravel()) for i, a in enumerate((dxn, dyn, dhn))]
    inside = wts[0][3] & wts[1][3] & wts[2][3]
    k = np.arange(grid.size) % nk
    S = grid.size
    cols = np.empty((S, 8), np.int64)
    data = np.empty((S, 8))
    for c in range(8):
        bits = [(c >> b) & 1 for b in range(3)]
        idx = [wts[a][1] if bits[a] else wts[a][0] for a in range(3)]
        w = np.ones(S)
        for a in range(3):
            w = w * (wts[a][2] if bits[a] else 1.0 - wts[a][2])
        cols[:, c] = ((idx[0] * shape[1] + idx[1]) * shape[2] + idx[2]) * nk + k
        data[:, c] = np.where(inside, w, 0.0)
    m = sp.csr_matrix((data.ravel(), cols.ravel(), np.arange(0, 8 * S + 1, 8)), shape=(S, S))
    m.eliminate_zeros()
    return m


def expected_reward(grid: Grid, params: MdpParams, turn_rate_deg: float) -> np.ndarray:
    """Expected wait reward ``E[R_w(S') | S]`` per grid state (shape ``grid.shape``).

    Evaluated at the *continuous* next states of every maneuver outcome (including those that
    leave the box), with vi saturated at its axis limits like the transitions. The HMD term of an
    outcome depends on (dx, dy, vi, theta) only and the vertical term on ``dh' = dh + vh dt`` only,
    so ``C1/HMD`` is computed once per outcome and combined with each distinct ``dh'``.
    """
    out: Outcome = outcomes(params, turn_rate_deg)
    g = grid
    dx = g.axis("dx").values[:, None, None, None, None]
    dy = g.axis("dy").values[None, :, None, None, None]
    vi = g.axis("vi").values[None, None, :, None, None]
    th = g.axis("theta").values[None, None, None, :, None]
    dxn = dx + (vi * np.cos(th) - params.v_own) * params.dt
    dyn = dy + vi * np.sin(th) * params.dt
    vin = np.clip(vi + out.dvi, g.axis("vi").lo, g.axis("vi").hi)
    thn = th + out.dtheta
    s, v = relative_sv(dxn, dyn, 0.0, vin, 0.0, thn, params.v_own)
    a_h = params.c1 / np.maximum(wc.hmd(s, v, params.hmd_horizon), params.sep_floor)  # (ndx, ndy, nvi, nth, M)
    dhn = g.axis("dh").values[:, None] + g.axis("vh").values[None, :] * params.dt  # (ndh, nvh)
    a_v = params.c2 / np.maximum(np.abs(dhn), params.sep_floor)
    R = np.empty(g.shape)
    for ih in range(g.shape[2]):
        for iv in range(g.shape[4]):
            R[:, :, ih, :, iv, :] = params.c3 * params.dt - np.minimum(a_h, a_v[ih, iv]) @ out.prob
    return R


@dataclass
class Transitions:
    """The waiting dynamics of one map: factors, exit mass, LoWC nodes and expected reward."""

    grid: Grid
    spatial: sp.csr_matrix  #: Sp, S x S
    kin: sp.csr_matrix  #: K, nk x nk
    p_exit: np.ndarray  #: (S,) probability of leaving the box in one step
    lowc: np.ndarray  #: (S,) bool, LoWC grid nodes
    reward: np.ndarray  #: (S,) expected wait reward

    @property
    def nk(self) -> int:
        return self.kin.shape[0]

    def _kin_T(self) -> sp.csr_matrix:
        # K^T as CSR: ``V (nx, nk) @ K^T`` is a dense-times-sparse product with no transposed copies
        # (and no BLAS threads, which under load were 3-10x slower than this for small nk)
        if getattr(self, "_kt", None) is None:
            self._kt = self.kin.T.tocsr()
        return self._kt

    def apply(self, V: np.ndarray, dtype=np.float64) -> np.ndarray:
        """``P_in @ V`` over grid states (EXIT mass excluded); ``V`` is ``(S,)`` or ``(S, m)``.

        Columns are applied one at a time (a 1-D sparse product is faster than scipy's multi-vector
        one). ``dtype=np.float32`` runs the products in single precision (used for the wait-time
        probabilities, which need ~1e-6, not for value iteration)."""
        if V.ndim == 2:
            return np.stack([self.apply(V[:, j], dtype) for j in range(V.shape[1])], axis=1)
        S, nk = self.grid.size, self.nk
        kt, spm = self._kin_T(), self.spatial
        if dtype == np.float32:
            if getattr(self, "_f32", None) is None:
                self._f32 = (kt.astype(np.float32), spm.astype(np.float32))
            kt, spm = self._f32
        U = np.asarray(np.ascontiguousarray(V, dtype=dtype).reshape(S // nk, nk) @ kt)
        return spm @ U.reshape(S)


def build_transitions(grid: Grid, params: MdpParams, turn_rate_deg: float) -> Transitions:
    """All waiting-dynamics ingredients for one map (vectorised; no per-state loop)."""
    spm = spatial_matrix(grid, params)
    kin = kinematic_matrix(grid, params, turn_rate_deg)
    p_exit = np.clip(1.0 - np.asarray(spm.sum(axis=1)).ravel(), 0.0, 1.0)
    lowc = lowc_states(grid.nodes(), params).ravel()
    reward = expected_reward(grid, params, turn_rate_deg).ravel()
    return Transitions(grid, spm, kin, p_exit, lowc, reward)


def assemble(tr: Transitions) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """Full ``(S+3) x (S+3)`` CSR matrices ``(P_wait, P_evade)``; rows sum to 1.

    States ``0..S-1`` are the grid, then EXIT, LOWC, OUT. Mass arriving on a LoWC node goes to
    LOWC; LoWC nodes themselves are absorbed into LOWC; EXIT, LOWC and OUT are absorbing. Evade
    sends every non-special state to OUT (paper Eq. 14).
    """
    import scipy.sparse as sp  # lazy: start-up time; lazily: only building a map needs scipy

    S = tr.grid.size
    nx = S // tr.nk
    pw = (tr.spatial @ sp.kron(sp.identity(nx, format="csr"), tr.kin, format="csr")).tocsr()
    pw = sp.hstack([pw, sp.csr_matrix((tr.p_exit[:, None]), shape=(S, 1)), sp.csr_matrix((S, 2))]).tocsr()
    # redirect columns of LoWC nodes to LOWC
    to_lowc = sp.csr_matrix(np.asarray(pw[:, np.flatnonzero(tr.lowc)].sum(axis=1)))
    keep = sp.diags((~tr.lowc).astype(float).tolist() + [1.0, 1.0, 1.0], format="csr")
    pw = (pw @ keep).tocsr()
    pw = pw + sp.hstack([sp.csr_matrix((S, S + 1)), to_lowc, sp.csr_matrix((S, 1))]).tocsr()
    # LoWC node rows -> LOWC; special rows absorbing
    lowc_rows = sp.csr_matrix((np.ones(tr.lowc.sum()), (np.flatnonzero(tr.lowc), np.full(tr.lowc.sum(), S + LOWC))),
                              shape=(S, S + 3))
    rowmask = sp.diags((~tr.lowc).astype(float), format="csr")
    top = (rowmask @ pw + lowc_rows).tocsr()
    bottom = sp.csr_matrix((np.ones(3), (np.arange(3), S + np.arange(3))), shape=(3, S + 3))
    P_wait = sp.vstack([top, bottom]).tocsr()
    P_wait.eliminate_zeros()
    ev_cols = np.concatenate([np.full(S, S + OUT), S + np.arange(3)])
    P_evade = sp.csr_matrix((np.ones(S + 3), (np.arange(S + 3), ev_cols)), shape=(S + 3, S + 3))
    return P_wait, P_evade
