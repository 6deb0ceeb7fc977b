"""Value iteration on the sparse factors, and the per-state wait time / LoWC probability.

**Value iteration.** Actions wait (0) and evade (1). ``Q_e = R_e + gamma V(OUT) = 0``;
``Q_w(s) = R(s) + gamma (sum_{s'} P(s, s') V(s') + P(s, EXIT) V_EXIT)`` with ``V = V_LOWC`` on LoWC
nodes; ``V = max(Q_w, Q_e)`` elsewhere (ties go to wait). **Stopping rule** (Puterman Thm 6.3.1):
stop at the first sweep with ``||V_{n+1} - V_n||_inf < eps (1 - gamma) / (2 gamma)``; then
``||V_{n+1} - V*||_inf < eps / 2`` and the greedy policy is eps-optimal. (The span rule used by
pymdptoolbox only bounds the policy, not V; we need V, see ``reference/models.md`` §2.2.)

**Wait time** (``reference/models.md`` §4.3, definition B): with G = LoWC nodes U evade-optimal nodes
and F the rest, ``W_0 = 0``, ``W_{k+1}(s) = 0`` on G and ``dt + P_FF W_k + P(s, EXIT) k dt`` on F;
``wait_s = W_H`` = ``dt E[min(T_G, H)]`` (EXIT counts as waiting to the horizon).
``p_lowc(s)`` = P(LoWC within H if the UAS keeps waiting regardless of the policy) and
``p_act(s)`` = P(reaching G within H), from the same H sweeps.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .model import MdpParams
from .transitions import Transitions


@dataclass
class SolverStats:
    """What value iteration did."""

    iterations: int
    residual: float  #: final ||V_{n+1} - V_n||_inf
    span: float  #: final span(V_{n+1} - V_n)
    threshold: float  #: eps (1 - gamma) / (2 gamma)
    converged: bool
    seconds: float

    def to_dict(self) -> dict:
        return dict(self.__dict__)


def stop_threshold(params: MdpParams) -> float:
    """Sup-norm stopping threshold ``eps (1 - gamma) / (2 gamma)``."""
    return params.epsilon * (1.0 - params.gamma) / (2.0 * params.gamma)


def value_iteration(tr: Transitions, params: MdpParams) -> tuple[np.ndarray, np.ndarray, SolverStats]:
    """Solve the wait/evade MDP on the factored transitions. Returns ``(V, Q_wait, stats)`` over nodes."""
    t0 = time.perf_counter()
    g, vl, vx = params.gamma, params.lowc_terminal, params.exit_value
    base = tr.reward + g * tr.p_exit * vx
    L = tr.lowc
    V = np.where(L, vl, 0.0)
    thr = stop_threshold(params)
    res = span = np.inf
    it = 0
    q = base
    while it < params.max_iter:
        it += 1
        q = base + g * tr.apply(V)
        Vn = np.where(L, vl, np.maximum(q, 0.0))
        d = Vn - V
        res, span = float(np.max(np.abs(d))), float(np.ptp(d))
        V = Vn
        if res < thr:
            break
    q = np.where(L, vl, q)
    stats = SolverStats(it, res, span, thr, res < thr, time.perf_counter() - t0)
    return V, q, stats


def value_iteration_csr(P_wait: sp.csr_matrix, P_evade: sp.csr_matrix, r_wait: np.ndarray, r_evade: np.ndarray,
                        gamma: float, threshold: float, fixed: "dict[int, float] | None" = None,
                        max_iter: int = 20000) -> tuple[np.ndarray, int]:
    """Plain VI on full stacked CSR matrices (the baseline of the benchmark): one SpMV per sweep.

    ``fixed`` pins terminal values (state index -> value). Returns ``(V, sweeps)``.
    """
    n = P_wait.shape[0]
    P = sp.vstack([P_wait, P_evade]).tocsr()
    R = np.concatenate([r_wait, r_evade])
    idx = np.array(sorted(fixed or {}), dtype=np.int64)
    vals = np.array([fixed[i] for i in idx]) if fixed else np.zeros(0)
    V = np.zeros(n)
    V[idx] = vals
    for it in range(1, max_iter + 1):
        Vn = (R + gamma * (P @ V)).reshape(2, n).max(axis=0)
        Vn[idx] = vals
        done = np.max(np.abs(Vn - V)) < threshold
        V = Vn
        if done:
            break
    return V, it


def wait_time(tr: Transitions, evade: np.ndarray, params: MdpParams) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(wait_s, p_lowc, p_act)`` per node after ``H`` batched sweeps (see module docstring)."""
    H, dt = params.n_horizon, params.dt
    G = tr.lowc | evade
    F = ~G
    X = np.zeros((tr.grid.size, 3))
    X[:, 1] = tr.lowc
    X[:, 2] = G
    for k in range(H):
        Y = tr.apply(X)
        W = np.where(F, dt + Y[:, 0] + tr.p_exit * k * dt, 0.0)
        pl = np.where(tr.lowc, 1.0, Y[:, 1])
        pa = np.where(G, 1.0, Y[:, 2])
        X = np.stack([W, pl, pa], axis=1)
    return X[:, 0], X[:, 1], X[:, 2]
