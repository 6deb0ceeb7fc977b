"""Benchmark ``campaign report``: the encounter-level bootstrap report against the old analytic one.

Usage::

    python benchmarks/bench_report.py                    # synthetic 10,000 encounters x 5 groups
    python benchmarks/bench_report.py --dir runs/paper   # a real campaign directory
    python benchmarks/bench_report.py --encounters 2000 --replicates 5000

Prints, for the same results in the same process: the old analytic report (per-step Poisson /
Clopper-Pearson intervals; the report module of commit 78937b1, the branch point of issue 14, run
unchanged on the current metrics), the new report (cluster bootstrap, findings, verdicts, ablation,
provenance, figures), their difference (target: the bootstrap adds at most 10 s for 10,000
encounters x 5 groups) and ratio, and the statistics alone (the study + verdicts, no figures).
Each figure is the best of ``--repeat`` runs.

The synthetic campaign has the shape of a real one: 15 % of encounters active, clustered step
counts, 3.5 % LoWC encounters, and decision tables (about 40 rows per active encounter) carrying
``decided_by`` and ``in_box``, so the provenance path is timed too.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

BASELINE_COMMIT = "78937b1"
GROUPS = ("B-1", "B-2", "IC-1", "ID-1", "ID-2")


def synth_campaign(d: Path, n: int, seed: int = 0) -> Path:
    """A campaign directory with realistic per-encounter and per-decision tables."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from daa_sil.study.simulation.fasttime import ENCOUNTER_SCHEMA
    from daa_sil.study.simulation.fasttime_results import SUPERSEDED_COLUMNS

    rng = np.random.default_rng(seed)
    active = rng.random(n) < 0.15
    steps = np.where(active, 1 + rng.poisson(40, n), 0)
    base_p = rng.beta(2, 3, n)
    lowc = rng.random(n) < 0.035
    turns = rng.random(n) < 0.58
    for gi, g in enumerate(GROUPS):
        integrated = g not in ("B-1", "B-2")
        p = np.clip(base_p * rng.uniform(0.8, 1.2, n), 0, 1)
        wait = rng.binomial(steps, 0.6 * p) if integrated else np.zeros(n, np.int64)
        no_wait = rng.binomial(steps, (0.1 if integrated else 0.9) * p)
        blend = rng.binomial(steps, 0.5 * p) if integrated else np.zeros(n, np.int64)
        intent = rng.binomial(blend, 0.3)
        exact = rng.binomial(intent, 0.72)
        axis = rng.binomial(intent - exact, 0.7)
        override = np.zeros(n, np.int64) if integrated else rng.binomial(steps, 0.2 * p)
        pexec = rng.binomial(steps, 0.05)
        lw = lowc ^ (rng.random(n) < 0.005)
        dur = np.where(lw, rng.exponential(3.0, n) + 0.1, 0.0)
        pi = np.where(lw, dur * rng.uniform(0.1, 0.6, n), 0.0)
        cols = {"group": [g] * n, "encounter_id": np.arange(n), "seed": rng.integers(0, 2**62, n),
                "duration_s": np.full(n, 240.0), "lowc": lw, "nmac": np.zeros(n, bool), "lowc_duration_s": dur,
                "pi": pi, "pi_paper": pi * 1.07, "min_range_m": rng.uniform(0, 3000, n),
                "vsep_at_min_range_m": rng.uniform(0, 300, n), "dev_h_m": rng.exponential(200, n),
                "dev_v_m": rng.exponential(8, n), "n_active_steps": steps, "n_wait": wait, "n_no_wait": no_wait,
                "n_pilot_received": pexec + blend + override, "n_pilot_exec": pexec, "n_blend": blend,
                "n_blend_exact": exact, "n_blend_axis": axis, "n_blend_intent": intent, "n_daa_override": override,
                "n_stale": np.zeros(n, np.int64), "n_link_lost": np.zeros(n, np.int64), "intruder_turns": turns,
                "preset": ["paper"] * n}
        # the wait-map bookkeeping and whole-encounter counts (present in every real campaign)
        by_map = rng.binomial(wait + no_wait, 0.5)
        cols.update({"n_by_map": by_map, "n_by_projl": rng.binomial(wait + no_wait - by_map, 0.5),
                     "n_by_both": np.zeros(n, np.int64), "n_lookup_in_box": rng.binomial(steps, 0.1),
                     "n_pilot_received_whole": cols["n_pilot_received"] + rng.poisson(5, n),
                     "n_pilot_exec_whole": pexec + rng.poisson(2, n)})
        # commands superseded within their step, the highest alert level, other deviation definitions
        sup = rng.poisson(1.0, n)
        cols.update({c: sup if c.endswith("whole") else np.zeros(n, np.int64) for c in SUPERSEDED_COLUMNS})
        cols.update({"max_alert_level": rng.integers(0, 4, n), "dev_h_tmean_m": cols["dev_h_m"] / 2,
                     "dev_v_tmean_m": cols["dev_v_m"] / 2, "dev_xtrack_m": cols["dev_h_m"] * 0.9,
                     "dev_h_end_m": cols["dev_h_m"]})
        missing = [f.name for f in ENCOUNTER_SCHEMA if f.name not in cols]
        if missing:
            raise SystemExit(f"bench_report: the synthetic table lacks {missing} (ENCOUNTER_SCHEMA changed)")
        (d / g).mkdir(parents=True)
        pq.write_table(pa.table(cols, schema=ENCOUNTER_SCHEMA), d / g / "encounters-00000.parquet")
        rows = np.repeat(np.arange(n), steps)
        k = rows.size
        dec = {"group": [g] * k, "encounter_id": rows, "t": rng.uniform(0, 240, k),
               "decision": rng.choice(["wait", "no_wait", "blend", "pilot"], k),
               "decided_by": rng.choice(["map", "projl", "both", "neither"], k),
               "in_box": rng.random(k) < 0.1}
        pq.write_table(pa.table(dec), d / g / "decisions-00000.parquet")
    cfg = {"groups": list(GROUPS), "n_encounters": n, "seed": seed, "chunk_size": n, "preset": "paper",
           "duration_s": 240.0, "dt_s": 1.0}
    (d / "campaign.json").write_text(json.dumps({"format": 1, "config": cfg, "status": "complete"}))
    return d


def old_report_module():
    """The report module as of the branch point (analytic intervals), or None without git history."""
    root = Path(__file__).resolve().parents[1]
    try:
        src = subprocess.run(["git", "-C", str(root), "show", f"{BASELINE_COMMIT}:daa_sil/report.py"],
                             capture_output=True, text=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        return None
    spec = importlib.util.spec_from_loader("daa_sil._report_baseline", loader=None)
    mod = importlib.util.module_from_spec(spec)
    mod.__package__ = "daa_sil"
    # the baseline's relative imports name the modules by their paths of that commit
    import daa_sil.files
    import daa_sil.study.analysis.metrics
    aliases = {"daa_sil.io": daa_sil.files, "daa_sil.metrics": daa_sil.study.analysis.metrics}
    added = [k for k in aliases if k not in sys.modules]
    sys.modules.update({k: aliases[k] for k in added})
    try:
        exec(compile(src, f"{BASELINE_COMMIT}:daa_sil/report.py", "exec"), mod.__dict__)  # noqa: S102
    finally:
        for k in added:
            del sys.modules[k]
    return mod


def best(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--dir", type=Path, default=None, help="a campaign directory (default: synthetic)")
    ap.add_argument("--encounters", type=int, default=10_000, help="synthetic encounters per group")
    ap.add_argument("--replicates", type=int, default=None, help="bootstrap replicates (default: the report's)")
    ap.add_argument("--repeat", type=int, default=2, help="runs per figure (best is printed)")
    args = ap.parse_args()

    from daa_sil.study.report import pages as report
    from daa_sil.study.analysis import report_input
    from daa_sil.study.analysis.verdicts import evaluate_all
    from daa_sil.study.analysis.study import Study
    from daa_sil.study.analysis.stats import DEFAULT_REPLICATES

    reps = args.replicates or DEFAULT_REPLICATES
    with tempfile.TemporaryDirectory(prefix="bench-report-") as tmp:
        tmp = Path(tmp)
        d = args.dir or synth_campaign(tmp / "camp", args.encounters)
        blocks = report_input.build_blocks(d)
        n = Study(blocks[0].enc, replicates=10).n
        groups = len(set(np.asarray(blocks[0].enc["group"]).astype(str)))
        print(f"results: {d} ({n:,} encounters x {groups} groups), {reps:,} bootstrap replicates")
        old = old_report_module()
        if old is None:
            print(f"old analytic report: unavailable (no git history with {BASELINE_COMMIT})")
            t_old = float("nan")
        else:
            t_old = best(lambda: old.write_report(d, tmp / "old"), args.repeat)
            print(f"old analytic report ({BASELINE_COMMIT}): {t_old:.2f} s")
        t_new = best(lambda: report.write_report(d, tmp / "new", replicates=reps), args.repeat)
        print(f"new report (bootstrap, findings, figures): {t_new:.2f} s")

        def stats_only():
            b = report_input.build_blocks(d)[0]
            evaluate_all({b.label: Study(b.enc, b.reading, dec=b.dec, replicates=reps)})

        t_stats = best(stats_only, args.repeat)
        print(f"statistics alone (load + study + verdicts, no figures): {t_stats:.2f} s")
        added = t_new - t_old
        print(f"added by the new report: {added:+.2f} s (target <= 10 s for 10,000 x 5), "
              f"ratio new / old = {t_new / t_old:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
