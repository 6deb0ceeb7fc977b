"""Wait-map performance: paper grid (build + solve + wait time, target <= 2 s) and the fine grid
(>= 1e6 states, target <= 60 s and <= 4 GiB peak RSS), with a baseline measured in the same run:
plain value iteration on the assembled full CSR (one SpMV over the stacked (2S) x S matrix per
sweep, the ``reference/models.md`` §2.4 solver) on the paper grid.

    python benchmarks/bench_waitmap.py [--skip-fine]
"""

from __future__ import annotations

import argparse
import resource
import time

import numpy as np

from daa_sil.waitmap import MdpParams, build_map, fine_grid, paper_grid
from daa_sil.waitmap.solve import stop_threshold, value_iteration, value_iteration_csr
from daa_sil.waitmap.transitions import EXIT, LOWC, OUT, assemble, build_transitions


def peak_rss_gib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20  # ru_maxrss is KiB on Linux


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--skip-fine", action="store_true")
    args = ap.parse_args()
    p = MdpParams()

    t = time.perf_counter()
    wm = build_map(paper_grid(), p, 5.0)
    paper_s = time.perf_counter() - t
    st = wm.stats
    print(f"paper grid 72,000 states: total {paper_s:.2f} s (transitions {st['build_s']:.2f}, VI {st['seconds']:.2f} s / "
          f"{st['iterations']} sweeps, wait time {st['wait_time_s']:.2f}) target <= 2 s: {'OK' if paper_s <= 2 else 'MISSED'}")

    tr = build_transitions(paper_grid(), p, 5.0)
    t = time.perf_counter()
    V, q, stats = value_iteration(tr, p)
    ours = time.perf_counter() - t
    t = time.perf_counter()
    Pw, Pe = assemble(tr)
    S = tr.grid.size
    asm = time.perf_counter() - t
    t = time.perf_counter()
    rw = np.concatenate([tr.reward, np.zeros(3)])
    fixed = {S + EXIT: p.exit_value, S + LOWC: p.lowc_terminal, S + OUT: 0.0}
    Vb, sweeps = value_iteration_csr(Pw, Pe, rw, np.zeros(S + 3), p.gamma, stop_threshold(p), fixed)
    base = time.perf_counter() - t
    F = ~tr.lowc
    print(f"baseline full-CSR VI (nnz {Pw.nnz:,}): assemble {asm:.2f} s + solve {base:.2f} s / {sweeps} sweeps; "
          f"factored VI {ours:.2f} s / {stats.iterations} sweeps -> speed-up x{(asm + base) / ours:.1f} "
          f"(solve only x{base / ours:.1f}); max |V diff| {np.max(np.abs(V[F] - Vb[:S][F])):.1e}")

    if not args.skip_fine:
        g = fine_grid()
        t = time.perf_counter()
        wf = build_map(g, p, 5.0)
        fine_s = time.perf_counter() - t
        rss = peak_rss_gib()
        s2 = wf.stats
        print(f"fine grid {g.size:,} states: total {fine_s:.1f} s (transitions {s2['build_s']:.1f}, VI {s2['seconds']:.1f} s / "
              f"{s2['iterations']} sweeps, wait time {s2['wait_time_s']:.1f}), peak RSS {rss:.2f} GiB; "
              f"targets <= 60 s, <= 4 GiB: {'OK' if fine_s <= 60 and rss <= 4 else 'MISSED'}")


if __name__ == "__main__":
    main()
