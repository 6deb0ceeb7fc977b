"""``daa-sil campaign run|report``: the paper's fast-time Monte Carlo study over groups."""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

from ..errors import UsageError
from ..io import to_jsonable
from ..thresholds import PRESETS
from ._args import finite_float, int_at_least

RUN_EXAMPLES = """examples:
  # the paper's study: 10,000 encounters x 5 groups (B-1, B-2, IC-1, ID-1, ID-2), T = 240 s
  daa-sil campaign run --out runs/paper --workers 2

  # a quick look: 200 encounters of two groups, in-process
  daa-sil campaign run --groups B-2,ID-2 --encounters 200 --seed 7 --out runs/quick

  # continue a campaign that was interrupted (complete chunks are skipped; same final tables)
  daa-sil campaign run --out runs/paper --resume

  # on a Dask cluster (pip install 'daa-sil[dist]'), or a local Dask cluster with 2 workers
  daa-sil campaign run --out runs/paper --scheduler tcp://head:8786
  daa-sil campaign run --out runs/paper --scheduler local-dask --workers 2

Groups (paper Table 2): B-1 baseline, const 4 s | B-2 baseline, Gaussian(5,3) s | IC-1 integrated,
const 5 s, wait 5 s | ID-1 integrated, const 4 s, wait map | ID-2 integrated, Gaussian(5,3) s, wait map.
Results: DIR/<group>/encounters-<chunk>.parquet, DIR/<group>/decisions-<chunk>.parquet,
DIR/encounters.parquet (the shared encounter set) and DIR/campaign.json.
"""

REPORT_EXAMPLES = """examples:
  daa-sil campaign report runs/paper                 # writes runs/paper/report/
  daa-sil campaign report runs/paper --out reports/paper

  # several readings side by side (one campaign directory per reading; the name comes from
  # campaign.json config.reading, "default" when absent)
  daa-sil campaign report runs/literal runs/paper-counts --out reports/readings

  # the same simulation counted another way as an extra reading (received = pilot + blend,
  # the paper's Table 5 arithmetic)
  daa-sil campaign report runs/literal --recount paper-arith:received=pilot+blend

  # more bootstrap replicates, another bootstrap seed (both recorded in the report)
  daa-sil campaign report runs/paper --replicates 5000 --bootstrap-seed 3

Writes report.md (findings table with verdicts, per-group tables, ablation, provenance, methods),
findings.json and PNG figures with 95 % CIs.
"""


def register(sub) -> None:
    p = sub.add_parser("campaign", help="fast-time Monte Carlo campaigns over the paper's groups",
                       description="Run the paper's fast-time study (chunked, resumable, on any executor) "
                                   "and report it next to the published numbers.",
                       epilog=RUN_EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    verbs = p.add_subparsers(dest="verb", metavar="VERB")
    verbs.required = True
    r = verbs.add_parser("run", help="run or resume a campaign", description="Run or resume a campaign.",
                         epilog=RUN_EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    r.add_argument("--groups", metavar="G1,G2,...", default=None,
                   help="comma-separated groups (default: B-1,B-2,IC-1,ID-1,ID-2)")
    r.add_argument("--encounters", type=int_at_least("--encounters", 1), default=None, metavar="N",
                   help="encounters per group (default 10000)")
    r.add_argument("--seed", type=int_at_least("--seed", 0), default=None, metavar="S", help="campaign seed (default 0)")
    r.add_argument("--duration", type=finite_float("--duration", 10.0, 3600.0), default=None, metavar="S",
                   help="encounter length T, s (default 240 as in the paper; CPA at T/2)")
    r.add_argument("--chunk-size", type=int_at_least("--chunk-size", 1), default=None, metavar="C",
                   help="encounters per task (default 2000, about 0.2 GB per worker; smaller chunks resume at a finer grain but run slower)")
    r.add_argument("--out", required=True, metavar="DIR", help="output directory (must be empty unless --resume)")
    r.add_argument("--workers", type=int_at_least("--workers", 1), default=None, metavar="K",
                   help="worker processes (1 = in-process; default 1); not with a remote --scheduler")
    r.add_argument("--scheduler", default=None, metavar="ADDRESS|local-dask",
                   help="run on a Dask cluster at ADDRESS (tcp://host:8786) or a local one (local-dask)")
    r.add_argument("--resume", action="store_true", help="continue the campaign in DIR (skips complete chunks)")
    r.add_argument("--preset", default=None, help=f"threshold preset: {', '.join(PRESETS)} (default paper)")
    r.add_argument("--no-progress", action="store_true", help="no progress bars")
    r.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    r.set_defaults(func=run_cmd)

    rep = verbs.add_parser("report", help="Markdown + PNG report of one or more campaign directories",
                           description="Write every finding of the paper with our value, its encounter-level "
                                       "95 % CI and a verdict under each reading (one campaign directory per "
                                       "reading), plus the paper's tables and figures.", epilog=REPORT_EXAMPLES,
                           formatter_class=argparse.RawDescriptionHelpFormatter)
    rep.add_argument("dirs", nargs="+", metavar="DIR",
                     help="campaign directories (from 'campaign run'), one per reading")
    rep.add_argument("--out", default=None, metavar="DIR2", help="report directory (default: FIRST_DIR/report)")
    rep.add_argument("--replicates", type=int_at_least("--replicates", 100), default=None, metavar="B",
                     help="bootstrap replicates (default 2000)")
    rep.add_argument("--bootstrap-seed", type=int_at_least("--bootstrap-seed", 0), default=None, metavar="S",
                     help="bootstrap seed (default 14)")
    rep.add_argument("--recount", action="append", default=[], metavar="NAME:key=value[,...]",
                     help="add a reading counted differently from the same results (keys: received, window); "
                          "repeatable")
    rep.add_argument("--json", action="store_true", help="print a JSON summary (paths, verdict counts) on stdout")
    rep.set_defaults(func=report_cmd)


def _config_from_args(args):
    from ..campaign import CampaignConfig, load_campaign_json, parse_groups

    given = {"groups": parse_groups(args.groups) if args.groups is not None else None,
             "n_encounters": args.encounters, "seed": args.seed, "chunk_size": args.chunk_size,
             "preset": args.preset.lower() if args.preset else None, "duration_s": args.duration}
    if args.preset and args.preset.lower() not in PRESETS:
        raise UsageError(f"unknown --preset {args.preset!r}; allowed: {', '.join(PRESETS)}")
    base = CampaignConfig()
    out = Path(args.out)
    if args.resume and (out / "campaign.json").is_file():
        base = CampaignConfig.from_dict(load_campaign_json(out)["config"], str(out / "campaign.json"))
    fields = {k: (v if v is not None else getattr(base, k)) for k, v in given.items()}
    return CampaignConfig(groups=tuple(fields["groups"]), n_encounters=fields["n_encounters"],
                          seed=fields["seed"], chunk_size=fields["chunk_size"], preset=fields["preset"],
                          duration_s=fields["duration_s"], dt_s=base.dt_s).validate()


_SCHEDULER = re.compile(r"^([a-z][a-z0-9+]*://)?[^\s:/]+:\d{1,5}$")


def check_scheduler(scheduler: "str | None", workers: "int | None") -> None:
    """Refuse a malformed ``--scheduler`` address, and ``--workers`` with a remote cluster (its
    workers are the cluster's), before anything starts or is written."""
    if scheduler is None:
        return
    if scheduler != "local-dask" and not _SCHEDULER.match(scheduler):
        raise UsageError(f"--scheduler must be an address like tcp://HOST:8786 or 'local-dask', got {scheduler!r}")
    if scheduler != "local-dask" and workers is not None:
        raise UsageError("--workers applies to local runs and --scheduler local-dask; a remote --scheduler "
                         "uses the cluster's own workers (drop --workers)")


def run_cmd(args) -> int:
    from ..campaign import run_campaign

    cfg = _config_from_args(args)
    check_scheduler(args.scheduler, args.workers)
    summary = run_campaign(cfg, args.out, workers=args.workers or 1, scheduler=args.scheduler, resume=args.resume,
                           progress=not args.no_progress and not args.json)
    rate = summary.encounter_steps / summary.wall_s if summary.wall_s > 0 else float("nan")
    info = {"out": str(summary.out_dir), "groups": list(cfg.groups), "encounters": cfg.n_encounters,
            "seed": cfg.seed, "preset": cfg.preset, "chunks_total": summary.chunks_total,
            "chunks_skipped": summary.chunks_skipped, "chunks_run": summary.chunks_run,
            "wall_s": round(summary.wall_s, 3), "encounter_steps_per_s": rate}
    if args.json:
        print(json.dumps(to_jsonable(info), indent=2, sort_keys=True))
    else:
        print(f"campaign {summary.out_dir}: {summary.chunks_run} chunks run, {summary.chunks_skipped} skipped "
              f"({len(cfg.groups)} groups x {cfg.n_encounters} encounters, preset {cfg.preset}) in "
              f"{summary.wall_s:.1f} s ({rate:,.0f} encounter-steps/s)", file=sys.stderr)
    return 0


def report_cmd(args) -> int:
    from .. import report
    from ..findings import VERDICTS
    from ..stats import DEFAULT_REPLICATES, DEFAULT_SEED

    dirs = [Path(d) for d in args.dirs]
    for d in dirs:
        if not (d / "campaign.json").is_file():
            raise UsageError(f"{d} is not a campaign directory (no campaign.json)")
    if len(set(map(str, (d.resolve() for d in dirs)))) != len(dirs):
        raise UsageError("a campaign directory is given twice")
    for spec in args.recount:
        report.parse_recount(spec)  # one-line error before anything is read or written
    out = Path(args.out) if args.out else dirs[0] / "report"
    reps = args.replicates or DEFAULT_REPLICATES
    seed = DEFAULT_SEED if args.bootstrap_seed is None else args.bootstrap_seed
    path = report.write_report(dirs if len(dirs) > 1 else dirs[0], out, replicates=reps, seed=seed,
                               recount=args.recount)
    if args.json:
        data = json.loads((out / "findings.json").read_text(encoding="utf-8"))
        counts = {r["label"]: {v: sum(1 for f in data["findings"] if f["outcomes"][r["label"]]["verdict"] == v)
                               for v in VERDICTS} for r in data["readings"]}
        print(json.dumps({"report": str(path), "findings": str(out / "findings.json"), "bootstrap": data["bootstrap"],
                          "verdicts": counts}, indent=2, sort_keys=True))
    else:
        print(f"report written to {out}", file=sys.stderr)
        print(str(path))
    return 0
