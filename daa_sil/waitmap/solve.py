"""Value iteration on the sparse factors, and the per-state wait time / LoWC probability.

**Value iteration.** Actions wait (0) and evade (1). ``Q_e = R_e + gamma V(OUT) = 0``;
``Q_w(s) = R(s) + gamma (sum_{s'} P(s, s') V(s') + P(s, EXIT) V_EXIT)`` with ``V = V_LOWC`` on LoWC
nodes; ``V = max(Q_w, Q_e)`` elsewhere (ties go to wait). **Stopping rule** (Puterman Thm 6.3.1):
stop at the first sweep with ``||V_{n+1} - V_n||_inf < eps (1 - gamma) / (2 gamma)``; then
``||V_{n+1} - V*||_inf < eps / 2`` and the greedy policy is eps-optimal. (The span rule used by
pymdptoolbox only bounds the policy, not V; the wait map needs V: ``docs/waitmap.md``.)

**Wait time.** Under the *waiting chain* (the UAS keeps waiting whatever the policy says; EXIT is
absorbing and never LoWC), with T the first step in a LoWC node and L the LoWC nodes:

* ``p_lowc(s) = P(T <= H)``: ``p_0 = 1[L]``, ``p_{k+1} = 1`` on L, ``P p_k`` elsewhere;
* ``t_lowc(s) = E[T 1{T <= H}]`` (s): ``m_0 = 0``, ``m_{k+1} = 0`` on L, ``P (m_k + dt p_k)`` elsewhere
  (a path that reaches LoWC one step later takes ``dt`` longer).

``wait_definition = "paper"`` (default; the paper Sec. II: "the expected waiting time ... is the
average of the waiting times of all the paths leading to LoWC weighted by their probabilities"):
``W = t_lowc / p_lowc = E[T | T <= H]``, with ``W = 0`` where evading is optimal (or in LoWC) and
``W = H`` where ``p_lowc < p_min`` (a state that reaches LoWC with less than ``p_min`` probability is
no threat; one fixed floor, so W does not jump from H to a few seconds between neighbouring nodes
because one of them has a 1e-9 chance of LoWC). Lookups interpolate ``p_lowc`` and ``t_lowc``
separately and divide (:mod:`.lookup`).

``wait_definition = "until_evade"`` (an earlier reading, kept as a named alternative): with G = LoWC
nodes U evade-optimal nodes and F the rest, ``W_0 = 0``, ``W_{k+1}(s) = 0`` on G and
``dt + P_FF W_k + P(s, EXIT) k dt`` on F; ``W = W_H = dt E[min(T_G, H)]`` (EXIT counts as waiting
to the horizon). Both come from the same H sweeps.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

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
    li = np.flatnonzero(L)
    V = np.where(L, vl, 0.0)
    Vn, d = np.empty_like(V), np.empty_like(V)
    thr = stop_threshold(params)
    res = span = np.inf
    it = 0
    q = base
    while it < params.max_iter:
        it += 1
        q = tr.apply(V)
        q *= g
        q += base
        np.maximum(q, 0.0, out=Vn)
        Vn[li] = vl
        np.subtract(Vn, V, out=d)
        V, Vn = Vn, V
        res = float(np.max(np.abs(d, out=d)))
        if res < thr:
            break
    span = float(np.ptp(np.where(L, vl, np.maximum(q, 0.0)) - Vn)) if it else span
    q = np.where(L, vl, q)
    stats = SolverStats(it, res, span, thr, res < thr, time.perf_counter() - t0)
    return V, q, stats


def value_iteration_csr(P_wait: sp.csr_matrix, P_evade: sp.csr_matrix, r_wait: np.ndarray, r_evade: np.ndarray,
                        gamma: float, threshold: float, fixed: "dict[int, float] | None" = None,
                        max_iter: int = 20000) -> tuple[np.ndarray, int]:
    """Plain VI on full stacked CSR matrices (the baseline of the benchmark): one SpMV per sweep.

    ``fixed`` pins terminal values (state index -> value). Returns ``(V, sweeps)``.
    """
    import scipy.sparse as sp  # lazy: start-up time; lazily: only building a map needs scipy

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


@dataclass
class WaitFields:
    """Per-node results of the waiting chain (arrays ``(S,)``); times in s."""

    wait_s: np.ndarray  #: the wait time of ``params.wait_definition``
    p_lowc: np.ndarray  #: P(T_LoWC <= H) under the waiting chain
    t_lowc: np.ndarray  #: E[T_LoWC 1{T_LoWC <= H}], s (the paper wait is t_lowc / p_lowc)


def paper_wait(t_lowc: np.ndarray, p_lowc: np.ndarray, evade: np.ndarray, params: MdpParams) -> np.ndarray:
    """The paper's wait time from the two chain moments: ``t_lowc / p_lowc`` where ``p_lowc >= p_min``,
    ``H`` where LoWC is less likely than ``p_min`` (no threat), 0 where evading is optimal or in LoWC."""
    p = np.asarray(p_lowc, float)
    threat = p >= params.p_min
    w = np.where(threat, np.asarray(t_lowc, float) / np.where(threat, p, 1.0), params.horizon)
    return np.where(evade, 0.0, np.clip(w, 0.0, params.horizon))


def wait_time(tr: Transitions, evade: np.ndarray, params: MdpParams,
              definitions: "tuple[str, ...] | None" = None) -> "WaitFields | dict[str, WaitFields]":
    """Wait time and the chain probabilities after ``H`` batched sweeps (see the module docstring).

    ``evade`` marks evade-optimal nodes (LoWC nodes are handled here). Every definition needs
    ``p_lowc`` and ``t_lowc = E[T 1{T <= H}]`` (from ``m_{k+1} = P (m_k + dt p_k)`` off LoWC);
    ``until_evade`` also carries ``W_B``. The sweeps run in single precision (probabilities to
    ~1e-6; the results are float32). With ``definitions`` (e.g. both), returns ``{name: WaitFields}``
    from one pass; else the map's own definition.
    """
    defs = (params.wait_definition,) if definitions is None else tuple(definitions)
    H, dt = params.n_horizon, params.dt
    L = tr.lowc
    G = L | evade
    F = ~G
    f32 = np.float32
    pe = tr.p_exit.astype(f32)
    p_lowc, t_lowc = L.astype(f32), np.zeros(tr.grid.size, f32)
    w_b = np.zeros(tr.grid.size, f32) if "until_evade" in defs else None
    for k in range(H):
        y_m = tr.apply(t_lowc + f32(dt) * p_lowc, f32)  # E[(dt + T') 1{T' <= k}] one step later
        p_lowc = np.where(L, f32(1), tr.apply(p_lowc, f32))
        t_lowc = np.where(L, f32(0), y_m)
        if w_b is not None:
            w_b = np.where(F, f32(dt) + tr.apply(w_b, f32) + pe * f32(k * dt), f32(0))
    p_lowc = np.clip(p_lowc, 0.0, 1.0)
    t_lowc = np.clip(t_lowc, 0.0, params.horizon)
    out = {}
    for name in defs:
        w = paper_wait(t_lowc, p_lowc, G, params) if name == "paper" else np.clip(w_b, 0.0, params.horizon)
        out[name] = WaitFields(wait_s=np.asarray(w, f32), p_lowc=p_lowc, t_lowc=t_lowc)
    return out if definitions is not None else out[defs[0]]
