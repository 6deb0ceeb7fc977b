"""Benchmark the fast-time campaign: encounter-steps/s, vectorised vs per-encounter loop, memory vs N.

Usage::

    python benchmarks/bench_campaign.py                       # full: 10,000 x 5 groups x 240 s, 2 workers
    python benchmarks/bench_campaign.py --encounters 1000     # a smaller full-pipeline run
    python benchmarks/bench_campaign.py --skip-campaign       # only the loop ratio and memory checks

Prints (1) the campaign throughput (target: 10,000 encounters x 5 groups x 240 s within 60 s on
2 cores), (2) the ratio of the vectorised simulator to a per-encounter loop over the same functions
(``simulate`` called with one encounter at a time) on a small subsample, measured in the same run,
and (3) the peak RSS of one chunk's simulation for growing N (chunking keeps it flat).
"""

from __future__ import annotations

import argparse
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def _loop_ratio(n: int, group: str) -> float:
    from daa_sil.study.campaign import campaign_family
    from daa_sil.study.campaign_config import CampaignConfig
    from daa_sil.models.encounters import sample_encounters
    from daa_sil.study.fasttime import simulate
    from daa_sil.config.groups import group_spec

    spec = group_spec(group)
    model = spec.delay_model()
    fam = campaign_family(CampaignConfig()) if spec.uses_map else None
    es = sample_encounters(n, seed=99, preset="paper")
    t0 = time.perf_counter()
    vec = simulate(es, spec.policy(), model, model, wait_family=fam, group=group)[0]
    t_vec = time.perf_counter() - t0
    t0 = time.perf_counter()
    rows = [simulate(es.subset([i]), spec.policy(), model, model, wait_family=fam, group=group)[0] for i in range(n)]
    t_loop = time.perf_counter() - t0
    same = all(r["n_active_steps"][0].as_py() == vec["n_active_steps"][i].as_py() for i, r in enumerate(rows))
    steps = n * 240
    print(f"[loop ratio, {group}, {n} encounters] vectorised {t_vec:.2f} s ({steps / t_vec:,.0f} enc-steps/s), "
          f"per-encounter loop {t_loop:.2f} s ({steps / t_loop:,.0f} enc-steps/s): x{t_loop / t_vec:.1f} "
          f"(identical counts: {same})")
    return steps / t_loop


_MEM_CHILD = """
import resource, sys
from daa_sil.study.campaign import CampaignConfig, ChunkTask, run_chunk
from daa_sil.models.encounters import sample_encounters
n = int(sys.argv[1]); chunk = int(sys.argv[2])
es = sample_encounters(n, seed=1, preset="paper")
from daa_sil.config.groups import parse_groups
cfg = CampaignConfig(groups=parse_groups("B-2"), n_encounters=n, chunk_size=chunk)
for c in range(cfg.n_chunks):
    lo, hi = cfg.chunk_range(c)
    run_chunk(ChunkTask("B-2", c, cfg, es.subset(list(range(lo, hi))), es.seed[lo:hi]))
print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0)
"""


def _lookup_cost(n: int, waitmap: str) -> None:
    """One ID-2 chunk with the wait map against the same chunk with the map replaced by 'always wait'
    (same encounters, same process): what the map lookup (turn-rate map choice + 64-corner
    interpolation + the most-threatening-intruder selection) costs the campaign."""
    from dataclasses import replace

    from daa_sil.study.campaign import campaign_family
    from daa_sil.study.campaign_config import CampaignConfig
    from daa_sil.models.encounters import sample_encounters
    from daa_sil.study.fasttime import simulate
    from daa_sil.config.groups import group_spec

    spec = group_spec("ID-2")
    model = spec.delay_model()
    fam = campaign_family(CampaignConfig(waitmap=waitmap))
    es = sample_encounters(n, seed=99, preset="paper")
    times = {}
    for name, pol in (("map", spec.policy()), ("always", replace(spec.policy(), wait_mode="always"))):
        simulate(es.subset(list(range(min(20, n)))), pol, model, model, wait_family=fam)  # warm-up
        t0 = time.perf_counter()
        simulate(es, pol, model, model, wait_family=fam)
        times[name] = time.perf_counter() - t0
    print(f"[lookup cost, ID-2, {n} encounters] with the {waitmap} wait map {times['map']:.2f} s, with 'always wait' "
          f"(no lookup) {times['always']:.2f} s: x{times['map'] / times['always']:.2f}")


def _memory(chunk: int, sizes: list[int]) -> None:
    for n in sizes:
        res = subprocess.run([sys.executable, "-c", _MEM_CHILD, str(n), str(chunk)], capture_output=True,
                             text=True, check=True)
        print(f"[memory] N={n:6d} in chunks of {chunk}: peak RSS {float(res.stdout.strip()):.0f} MiB")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--encounters", type=int, default=10_000)
    ap.add_argument("--groups", default="B-1,B-2,IC-1,ID-1,ID-2")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--chunk-size", type=int, default=None, help="encounters per task (default: the campaign's, 2000)")
    ap.add_argument("--loop-n", type=int, default=40, help="subsample size for the per-encounter loop ratio")
    ap.add_argument("--skip-campaign", action="store_true")
    ap.add_argument("--waitmap", default="alerting", help="wait maps of the map groups (default alerting, the study's)")
    ap.add_argument("--lookup-n", type=int, default=2000, help="encounters of the wait-map lookup cost check")
    ap.add_argument("--memory-sizes", default="200,800,1600",
                    help="N of the memory check, in chunks of the first (comma-separated)")
    args = ap.parse_args()

    from daa_sil.study.campaign import parse_groups, run_campaign
    from daa_sil.study.campaign_config import DEFAULT_CHUNK, CampaignConfig

    args.chunk_size = args.chunk_size or DEFAULT_CHUNK
    loop_rates = [_loop_ratio(args.loop_n, "B-2"), _loop_ratio(args.loop_n, "ID-2")]
    _lookup_cost(args.lookup_n, args.waitmap)
    sizes = [int(x) for x in args.memory_sizes.split(",")]
    _memory(sizes[0], sizes)
    _memory(args.chunk_size, [args.chunk_size, 3 * args.chunk_size])
    if args.skip_campaign:
        return
    groups = parse_groups(args.groups)
    cfg = CampaignConfig(groups=groups, n_encounters=args.encounters, seed=0, chunk_size=args.chunk_size,
                         waitmap=args.waitmap)
    from daa_sil.study.campaign import campaign_family

    campaign_family(cfg)  # built/loaded before the clock starts (cached after the first run)
    with tempfile.TemporaryDirectory(prefix="bench-campaign-") as tmp:
        s = run_campaign(cfg, Path(tmp) / "c", workers=args.workers, progress=False)
    steps = s.encounter_steps
    print(f"[campaign] {len(groups)} groups x {args.encounters} encounters x 240 s, {args.workers} workers, "
          f"chunks of {args.chunk_size}: {s.wall_s:.1f} s wall ({steps / s.wall_s:,.0f} encounter-steps/s; "
          f"target 60 s for 10,000 x 5 with the {args.waitmap} wait maps); worker compute {s.compute_s:.1f} s; driver peak RSS "
          f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB")
    per_core = steps / s.compute_s
    loop = sum(loop_rates) / len(loop_rates)
    print(f"[campaign] per worker core {per_core:,.0f} encounter-steps/s = x{per_core / loop:.0f} the per-encounter "
          f"loop over the same functions ({loop:,.0f} encounter-steps/s, same run)")


if __name__ == "__main__":
    main()
