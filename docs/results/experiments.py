"""The experiments that explain the paper reading's misses (single factor, on the same encounters):
run them, then write ``experiments.json`` and the experiments page.

    python docs/results/experiments.py --runs RUNS --seed SEED --small 2000 --large 10000 [--workers 2]
    python docs/results/experiments.py --runs RUNS --seed SEED --small 2000 --large 10000 --only unmitigated
    python docs/results/experiments.py --runs RUNS --seed SEED ... --analyse-only --out docs/results

RUNS must hold the readings' campaigns of the same seed (``RUNS/paper``, ``RUNS/paper-clamp``, ...:
``docs/results/regenerate.py`` runs them; the experiments read ``paper`` and the readings listed in
``daa_sil.study.campaign.experiments.READINGS_USED``). The experiment campaigns go to ``RUNS/exp-<name>-<N>``
(resumable: an interrupted call picks up where it stopped). ``--out`` gets ``experiments.json`` and
``experiments.md``. Never run it on the report seed while developing.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))


def main(argv=None) -> int:
    from daa_sil.study.campaign.experiments import RUNS

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                 epilog="experiments: " + ", ".join(r.name for r in RUNS))
    ap.add_argument("--runs", type=Path, required=True, help="the runs directory (with the readings' campaigns)")
    ap.add_argument("--seed", type=int, required=True, help="the campaign seed of every run")
    ap.add_argument("--small", type=int, default=2000, help="encounters per group of the small runs (default 2000)")
    ap.add_argument("--large", type=int, default=10000,
                    help="encounters per group of the rare-event runs (default 10000)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--only", default=None, help="comma-separated experiment runs (default: all)")
    ap.add_argument("--analyse-only", action="store_true", help="no runs: only the figures of the runs present")
    ap.add_argument("--replicates", type=int, default=1000, help="bootstrap replicates (default 1000)")
    ap.add_argument("--out", type=Path, default=None, help="where experiments.json and experiments.md go "
                                                            "(default: RUNS)")
    args = ap.parse_args(argv)
    for name in ("small", "large", "workers", "replicates"):
        if getattr(args, name) < 1:
            ap.error(f"--{name} must be at least 1")
    from daa_sil.errors import UsageError
    from daa_sil.files import atomic_write_json, atomic_write_text, ensure_dir
    from daa_sil.study.report.experiment_page import experiments_page
    from daa_sil.study.analysis.experiment_suite import analyse
    from daa_sil.study.campaign.experiments import run_experiments

    try:
        if not args.analyse_only:
            only = tuple(s for s in args.only.split(",") if s) if args.only else None
            run_experiments(args.runs, args.seed, args.small, args.large, args.workers, only)
        res = analyse(args.runs, args.seed, args.small, args.large, args.replicates)
    except UsageError as exc:
        print(f"experiments: {exc}", file=sys.stderr)
        return 2
    out = ensure_dir(args.out or args.runs)
    atomic_write_json(out / "experiments.json", res)
    atomic_write_text(out / "experiments.md", experiments_page(res), overwrite=True)
    print(f"wrote {out / 'experiments.json'} and {out / 'experiments.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
