"""Solver and wait-time oracles: dense cross-check, Monte Carlo, mirror symmetry, paper findings."""

import numpy as np
import pytest

from daa_sil import waitmap
from daa_sil.waitmap import MdpParams, build_map, oracles, paper_grid, resolve_grid
from daa_sil.waitmap.solve import stop_threshold, value_iteration, wait_time
from daa_sil.waitmap.transitions import EXIT, LOWC, OUT, assemble, build_transitions

SMALL = "paper,dx=6,dy=6,dh=3,vi=3,vh=3,theta=4"


@pytest.fixture(scope="module")
def families():
    """The production wait-map families: the paper grid (the literal reading) and the default
    alerting-region grid, exactly as campaigns and the SIL load them (built once, cached)."""
    return {"paper": waitmap.family_for("paper"), "alerting": waitmap.family_for("alerting")}


def test_factored_solver_matches_dense_brute_force():
    g = resolve_grid("paper,dx=4,dy=4,dh=2,vi=2,vh=2,theta=4")
    p = MdpParams(epsilon=1e-9)
    tr = build_transitions(g, p, 5.0)
    V, q, stats = value_iteration(tr, p)
    assert stats.converged and stats.residual < stop_threshold(p)
    Pw, Pe = assemble(tr)
    Pw, Pe = Pw.toarray(), Pe.toarray()
    S = g.size
    Rw = np.concatenate([tr.reward, np.zeros(3)])
    fixed = {S + EXIT: p.exit_value, S + LOWC: p.lowc_terminal, S + OUT: 0.0}
    Vd = np.zeros(S + 3)
    for _ in range(5000):  # plain dense Bellman sweeps, textbook form
        Vn = np.maximum(Rw + p.gamma * Pw @ Vd, 0.0 + p.gamma * Pe @ Vd)
        for i, v in fixed.items():
            Vn[i] = v
        done = np.max(np.abs(Vn - Vd)) < 1e-12
        Vd = Vn
        if done:
            break
    F = ~tr.lowc
    assert np.max(np.abs(V[F] - Vd[:S][F])) < 1e-7
    qd = Rw[:S] + p.gamma * Pw[:S] @ Vd
    clear = F & (np.abs(qd) > 1e-6)
    assert np.array_equal((q < 0)[clear], (qd < 0)[clear])


@pytest.fixture(scope="module")
def small_map():
    g = resolve_grid(SMALL)
    p = MdpParams()
    return g, p, build_map(g, p, 2.5), build_transitions(g, p, 2.5)


def test_wait_time_invariants(small_map):
    g, p, wm, tr = small_map
    ev, H = wm.evade, p.horizon
    assert ev.any() and (~ev).any()
    assert np.all(wm.wait_s[ev] == 0.0)  # evade (or LoWC) => no waiting
    assert np.all((wm.wait_s >= 0) & (wm.wait_s <= H))
    threat = ~ev & (wm.p_lowc >= p.p_min)
    calm = ~ev & (wm.p_lowc < p.p_min)
    assert threat.any() and calm.any()
    assert np.all(wm.wait_s[threat] >= p.dt - 1e-5)  # LoWC is at least one step away
    assert np.all(wm.wait_s[calm] == H)  # no threat: no constraint
    assert np.all((wm.p_lowc >= 0) & (wm.p_lowc <= 1)) and np.all(wm.p_lowc[wm.lowc] == 1)
    assert np.all(wm.t_lowc <= H * wm.p_lowc + 1e-4)  # E[T 1{T<=H}] <= H P(T<=H)
    # one more sweep of the recursions reproduces the stored values (to float32 rounding)
    prev = wait_time(tr, ev.ravel() & ~tr.lowc, p.with_(horizon=H - p.dt))
    L = tr.lowc
    p_rhs = np.where(L, 1.0, tr.apply(prev.p_lowc.astype(float)))
    t_rhs = np.where(L, 0.0, tr.apply(prev.t_lowc.astype(float) + p.dt * prev.p_lowc))
    assert np.max(np.abs(wm.p_lowc.ravel() - p_rhs)) < 1e-5
    assert np.max(np.abs(wm.t_lowc.ravel() - t_rhs)) < 1e-4


def _rollouts(P, start, stop, H, n, rng):
    """Discrete-chain rollouts from ``start`` for at most H steps: ``(end, T)``, the first ``stop``
    state entered and the step count when it was (``end = -1, T = H`` if none within H)."""
    cum = np.cumsum(P.data)
    row_start = np.concatenate([[0.0], cum])[P.indptr[:-1]]
    s = np.full(n, start)
    t = np.full(n, float(H))
    end = np.full(n, -1)
    for k in range(H):
        u = row_start[s] + rng.random(n) * (cum[P.indptr[s + 1] - 1] - row_start[s])
        nxt = P.indices[np.minimum(np.searchsorted(cum, u, side="right"), P.indptr[s + 1] - 1)]
        alive = end < 0
        s = np.where(alive, nxt, s)
        new = alive & stop[s]
        t[new] = k + 1
        end[new] = s[new]
    return end, t


def _probe_states(wm, rng, k, lo=0.05, hi=0.95):
    """k random wait-optimal nodes whose LoWC probability and wait are both far from trivial."""
    w, pl = wm.wait_s.ravel(), wm.p_lowc.ravel()
    cand = np.flatnonzero(~wm.evade.ravel() & (pl > lo) & (pl < hi) & (w > 2) & (w < wm.params.horizon - 2))
    assert cand.size >= k
    return rng.choice(cand, size=k, replace=False)


def test_monte_carlo_rollouts_agree_with_the_paper_wait_on_the_paper_grid():
    """P(LoWC within H) and E[T | LoWC within H] of rollouts of the discrete waiting chain agree with
    the map within 3 standard errors, on the production paper grid (turn +5 deg/s map)."""
    g, p = paper_grid(), MdpParams()
    wm, tr = build_map(g, p, 5.0), build_transitions(g, p, 5.0)
    Pw, _ = assemble(tr)
    S = g.size
    stop = np.zeros(S + 3, bool)
    stop[S + LOWC] = True
    rng = np.random.default_rng(7)
    picks = _probe_states(wm, rng, 6)
    n = 4000
    for s0 in picks:
        end, t = _rollouts(Pw, s0, stop, p.n_horizon, n, rng)
        hit = end == S + LOWC
        pl, w = float(wm.p_lowc.ravel()[s0]), float(wm.wait_s.ravel()[s0])
        se_p = np.sqrt(pl * (1 - pl) / n)
        assert abs(hit.mean() - pl) < 3 * se_p, (s0, hit.mean(), pl, se_p)
        th = t[hit]
        se_w = th.std(ddof=1) / np.sqrt(th.size)
        assert abs(th.mean() - w) < 3 * se_w + 1e-3, (s0, th.mean(), w, se_w)


def test_monte_carlo_rollouts_agree_with_the_until_evade_wait(small_map):
    """The alternative definition: E[min(T_G, H)] with G = LoWC or evade-optimal, EXIT counting as
    waiting to the horizon."""
    g, p, _, tr = small_map
    pb = p.with_(wait_definition="until_evade")
    wm = build_map(g, pb, 2.5)
    Pw, _ = assemble(tr)
    S = g.size
    stop = np.zeros(S + 3, bool)
    stop[:S] = wm.evade.ravel()
    stop[[S + LOWC, S + EXIT]] = True
    rng = np.random.default_rng(11)
    n = 4000
    for s0 in _probe_states(wm, rng, 4, lo=0.0, hi=1.0):
        end, t = _rollouts(Pw, s0, stop, pb.n_horizon, n, rng)
        t = np.where(end == S + EXIT, pb.n_horizon, t)
        w = float(wm.wait_s.ravel()[s0])
        se = t.std(ddof=1) / np.sqrt(n)
        assert 2 < w < pb.horizon - 2 and se > 0
        assert abs(t.mean() - w) < 3 * se + 1e-3, (s0, t.mean(), w, se)


def test_mirror_images_and_symmetric_zero_map_on_the_production_grids(families):
    for name, fam in families.items():
        m = oracles.mirror_error(fam)
        assert m["zero_map"] < 1e-4, name
        for rate, d in m["pairs"].items():
            assert d["mirror_error_s"] < 1e-4, (name, rate)
            assert d["plain_difference_s"] > 1.0, (name, rate)  # the turn does matter


def test_head_on_waits_shorter_than_overtaking_on_the_production_grids(families):
    for name, fam in families.items():
        r = oracles.head_on_vs_overtaking(fam.map_for(0.0))
        assert r.n >= 20, (name, r.n)  # a population of non-trivial pairs, not an empty pass
        assert r.holds, (name, r.failures[:3])


def test_waits_shrink_along_converging_lines_on_the_production_grids(families):
    for name, fam in families.items():
        r = oracles.converging_lines(fam.map_for(0.0))
        assert r.n >= 10, (name, r.n)
        assert r.holds, (name, r.failures[:3])


def test_faster_turning_intruder_waits_less(families):
    """Paper Fig. 5b vs 6a: at +5 deg/s the 300 m/s map waits less than the 155 m/s map. Over every
    (dx, dy, dh, vh, theta) node where both are non-trivial, most are lower at the faster speed."""
    for name, fam in families.items():
        wm = fam.map_for(5.0)
        H = wm.params.horizon
        st = wm.grid.nodes()[:, :, :, 0].reshape(-1, 6).copy()
        w = {}
        for vi in (155.0, min(300.0, wm.grid.axis("vi").hi)):
            st[:, 3] = vi
            w[vi] = wm.lookup(st).wait_s
        slow, fast = w.values()
        nt = (slow > 0) & (slow < H) & (fast > 0) & (fast < H)
        assert nt.sum() > 1000
        assert np.mean(fast[nt] < slow[nt]) > 0.5 and fast[nt].mean() < slow[nt].mean(), name


def test_paper_grid_histogram_has_the_papers_range_not_its_shape(families, capsys):
    h = oracles.histogram(families["paper"])
    q = h["quartiles_s"]
    with capsys.disabled():
        print(f"\n[waitmap] paper grid, threatening states n={h['n']}: min {h['min_s']:.2f} s, quartiles "
              f"{q[0]:.2f} / {q[1]:.2f} / {q[2]:.2f} s, max {h['max_s']:.2f} s, 5 s bins {h['counts'][:9]}")
    assert h["n"] > 10000
    assert h["min_s"] <= 2.0 and h["max_s"] <= 45.0  # the paper's range: 1-40 s
    # its bulk is not: most states wait under 5 s and the tail runs toward H (right skewed), so the
    # paper's shape (most states 5-10 s, left skewed) is reported as not reproduced (docs/waitmap.md)
    checks = oracles.shape_checks(h)
    assert checks["min about 1 s (<= 2 s)"] and not checks["most states within 5-10 s (> 50 %)"]
    assert not oracles.paper_shape(h)
