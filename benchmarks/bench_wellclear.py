"""Benchmark: exact well-clear violation intervals for 10^6 random pairs.

Prints pairs/s of the vectorised closed form and two ratios measured in the same run on a
subsample: against the straightforward per-pair loop (calling the same function once per pair),
and against a hand-written scalar pure-Python version of the closed form (``math`` module, early
exits), which is the strongest loop baseline. Results are cross-checked for agreement.

    python benchmarks/bench_wellclear.py [--pairs 1000000] [--loop-pairs 20000]

Targets (issue 3): >= 5e6 pairs/s on one core, >= 100x the loop.
"""

from __future__ import annotations

import argparse
import math
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from daa_sil.geometry import wellclear as wc  # noqa: E402
from daa_sil.geometry.thresholds import DO365  # noqa: E402


def interval_loop(s, v, D, H, TT, TC, B, T):
    """Per-pair Python version of the DAIDALUS closed form (baseline)."""
    sx, sy, sz = s
    vx, vy, vz = v
    if abs(vz) < 1e-12:
        if abs(sz) > H:
            return math.inf, -math.inf
        vlo, vhi = B, T
    else:
        sg = 1.0 if vz > 0 else -1.0
        h_ent = max(H, abs(vz) * TC)
        vlo = max(B, (-sg * h_ent - sz) / vz)
        vhi = min(T, (sg * H - sz) / vz)
        if vlo > vhi:
            return math.inf, -math.inf
    L = vhi - vlo
    px, py = sx + vlo * vx, sy + vlo * vy
    a = vx * vx + vy * vy
    p2 = px * px + py * py
    pv = px * vx + py * vy
    if a < 1e-12:
        return (vlo, vhi) if p2 <= D * D else (math.inf, -math.inf)
    t_exit = (-pv + math.sqrt(max(pv * pv - a * (p2 - D * D), 0.0))) / a
    if p2 <= D * D:
        return vlo, vlo + min(L, t_exit)
    if pv >= 0:
        return math.inf, -math.inf
    b = 2 * pv + TT * a
    c = p2 + TT * pv - D * D
    disc = b * b - 4 * a * c
    if disc < 0 or D * D * a - (px * vy - py * vx) ** 2 < 0:
        return math.inf, -math.inf
    t_tau = (-b - math.sqrt(disc)) / (2 * a)
    if t_tau > L:
        return math.inf, -math.inf
    return vlo + max(0.0, t_tau), vlo + min(L, t_exit)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--pairs", type=int, default=1_000_000)
    ap.add_argument("--loop-pairs", type=int, default=20_000)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    n = args.pairs
    s = np.column_stack([rng.uniform(-10000, 10000, n), rng.uniform(-10000, 10000, n), rng.uniform(-600, 600, n)])
    v = np.column_stack([rng.uniform(-300, 300, n), rng.uniform(-300, 300, n), rng.uniform(-15, 15, n)])
    th = DO365
    best = math.inf
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        t_in, t_out = wc.violation_interval(s, v, th, 0.0, 180.0)
        best = min(best, time.perf_counter() - t0)
    vec_rate = n / best

    m = args.loop_pairs
    k = max(m // 10, 1)
    t0 = time.perf_counter()
    for i in range(k):
        wc.violation_interval(s[i], v[i], th, 0.0, 180.0)
    call_rate = k / (time.perf_counter() - t0)
    t0 = time.perf_counter()
    loop = [interval_loop(s[i], v[i], th.dthr, th.zthr, th.tthr, th.tcoa, 0.0, 180.0) for i in range(m)]
    loop_rate = m / (time.perf_counter() - t0)
    lo = np.array([a for a, _ in loop])
    hi = np.array([b for _, b in loop])
    finite = np.isfinite(lo)
    agree = (np.array_equal(finite, np.isfinite(t_in[:m]))
             and np.allclose(lo[finite], t_in[:m][finite], atol=1e-9)
             and np.allclose(hi[finite], t_out[:m][finite], atol=1e-9))
    print(f"pairs: {n:,}  conflicts within 180 s: {np.isfinite(t_in).mean():.1%}")
    print(f"vectorised violation_interval: {vec_rate:,.0f} pairs/s (best of {args.repeat}, {best * 1e3:.1f} ms)")
    print(f"baseline 1, per-pair loop calling the same function ({k:,} pairs): {call_rate:,.0f} pairs/s "
          f"-> ratio {vec_rate / call_rate:,.0f}x")
    print(f"baseline 2, scalar pure-Python closed form ({m:,} pairs): {loop_rate:,.0f} pairs/s "
          f"-> ratio {vec_rate / loop_rate:,.0f}x   (results agree: {agree})")
    print(f"targets: >= 5,000,000 pairs/s -> {'met' if vec_rate >= 5e6 else 'NOT met'}; "
          f">= 100x the per-pair loop -> {'met' if vec_rate / call_rate >= 100 else 'NOT met'}")


if __name__ == "__main__":
    main()
