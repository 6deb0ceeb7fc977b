"""``daa-sil campaign run|report``: the paper's fast-time Monte Carlo study over groups."""

from __future__ import annotations

import argparse
import json
import re
import shlex
import sys
from pathlib import Path

from ..errors import UsageError
from daa_sil.config.overrides import Overrides, add_flags, flag_dest
from daa_sil.config.settings import (BATCH_ROWS, BOOTSTRAP_REPLICATES, CHUNK_SIZE, DURATION, ENCOUNTERS, GAMMA,
                                     INTRUDERS, PRESET, SEED, WORKERS_PER_CORE)
from daa_sil.config.config_option import add_config_argument
from daa_sil.config.run_config import load_config
from daa_sil.files import to_jsonable
from daa_sil.sil.children import Interrupted, interrupt_signum, interruptible
from daa_sil.config.readings import DEFAULT_READING, READINGS, parse_reading_settings, readings_help
from daa_sil.geometry.thresholds import PRESETS
from .common_args import add_allow_large, finite_float, int_at_least, setting_int, workers_option
from daa_sil.config.readings import canonical_name
from daa_sil.config.readings import reading_for
from daa_sil.errors import OutputError
from daa_sil.files import check_output_path

RUN_EXAMPLES = """examples:
  # the paper's study (reading 'paper'): 10,000 encounters x 5 groups (B-1, B-2, IC-1, ID-1, ID-2), T = 240 s
  daa-sil campaign run --out runs/paper --workers 2

  # the same under our extension (alerting-region wait maps, one-way delays; formerly 'literal')
  daa-sil campaign run --reading extended --out runs/extended --workers 2

  # a quick look: 200 encounters of two groups, in-process
  daa-sil campaign run --groups B-2,ID-2 --encounters 200 --seed 7 --out runs/quick

  # continue a campaign that was interrupted (complete chunks are skipped; same final tables)
  daa-sil campaign run --out runs/paper --resume

  # the wait-map ablation: what the map adds to ProjL alone, on the paper's own grid
  daa-sil campaign run --groups ID-2,ID-2-projl,ID-2-map --waitmap paper --out runs/ablation

  # every knob of the agent from the command line (recorded in campaign.json, checked on --resume)
  daa-sil campaign run --groups B-2,ID-2 --wt 8 --projl-horizon 15 --latency gauss:5,3 --out runs/knobs

  # your own groups (YAML: name -> fields, 'base: ID-2' to start from a built-in group)
  daa-sil campaign run --groups mygroups.yaml --out runs/mine

  # on a Dask cluster (pip install 'daa-sil[dist]'), or a local Dask cluster with 2 workers
  daa-sil campaign run --out runs/paper --scheduler tcp://head:8786
  daa-sil campaign run --out runs/paper --scheduler local-dask --workers 2

Groups (daa_sil/data/groups.yaml; paper Table 2 plus ablations): B-1 baseline, const 4 s |
B-2 baseline, Gaussian(5,3) s | IC-1 integrated, const 5 s, wait 5 s | ID-1 integrated, const 4 s,
wait map | ID-2 integrated, Gaussian(5,3) s, wait map | ID-2-projl: ID-2 with the map ignored
(wait unless ProjL) | ID-2-map: ID-2 with the map alone (no ProjL).
Wait maps (--waitmap): alerting (default; the DO-365 alerting region, 120 s horizon), paper (the
paper's +-1,500 m grid, 60 s; states outside read the nearest point of the box), fine, a grid spec,
or a directory from 'daa-sil waitmap build'. Built once and cached in ~/.cache/daa-sil.
Results: DIR/<group>/encounters-<chunk>.parquet, DIR/<group>/decisions-<chunk>.parquet,
DIR/encounters.parquet (the shared encounter set) and DIR/campaign.json.

Readings (--reading, default paper; docs/results/paper-study.md quotes the sentence each setting of
'paper' rests on; daa_sil/config/readings.py):
""" + readings_help() + """
"""

SWEEP_EXAMPLES = """examples:
  # W_T from 2 to 16 s for the baseline and ID-2 (one campaign per value, same encounters)
  daa-sil campaign sweep --vary wt=2,4,8,16 --groups B-2,ID-2 --out runs/sweep-wt --workers 2

  # link latency, constant and Gaussian (values containing commas are separated by ';')
  daa-sil campaign sweep --vary 'latency=const:0.2;const:1;const:5;gauss:5,3' --groups B-2,ID-2,ID-2-projl --out runs/sweep-lat

  # discount, map grid, two intruders against one; continue an interrupted sweep
  daa-sil campaign sweep --vary gamma=0.9,0.95,0.99 --groups ID-2 --out runs/sweep-gamma
  daa-sil campaign sweep --vary grid=paper,alerting --groups ID-2,ID-2-projl --out runs/sweep-grid
  daa-sil campaign sweep --vary intruders=1,2 --groups B-2,ID-2 --out runs/sweep-m --resume

  # the pilot's response time (the paper does not give it): Guendel (~19 s) against a 5 s Rayleigh pilot
  daa-sil campaign sweep --vary pilot=guendel,nasa_rayleigh5 --groups B-2,ID-2,ID-2-projl --out runs/sweep-pilot

  # one page from several sweeps (docs/results/sensitivity.md is made this way)
  daa-sil campaign sweep --collate runs/sweep-wt runs/sweep-lat --out docs/results

Writes DIR/sweep.json, DIR/points/NAME=VALUE/ (campaign directories), DIR/sweep.csv, DIR/sweep.md and
DIR/sensitivity_<metric>.png: DAA allocations and pilot commands received per encounter, exact
(axis, direction) match, LoWC rate and mean PI against the varied value, with 95 % CIs.
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
    _add_run_options(r)
    r.set_defaults(func=interruptible(run_cmd))  # SIGTERM / SIGHUP stop it as Ctrl-C does

    sw = verbs.add_parser("sweep", help="the study at several values of one setting (sensitivity)",
                          description="Run the study once per value of one setting into one directory "
                                      "(resumable), then write a table and sensitivity plots with "
                                      "encounter-level 95 % CIs.", epilog=SWEEP_EXAMPLES,
                          formatter_class=argparse.RawDescriptionHelpFormatter)
    sw.add_argument("--vary", default=None, metavar="NAME=V1,V2,...",
                    help="wt, gamma, grid, intruders, latency (values separated by ';'), projl, reading or "
                         "pilot (response mode: guendel, nasa_rayleigh5, no_atc, fixed, deterministic)")
    sw.add_argument("--collate", nargs="+", default=None, metavar="SWEEP_DIR",
                    help="instead of running: one sensitivity.md page from these sweep directories into --out")
    _add_run_options(sw)
    sw.set_defaults(func=interruptible(sweep_cmd))

    rep = verbs.add_parser("report", help="Markdown + PNG report of one or more campaign directories",
                           description="Write every finding of the paper with our value, its encounter-level "
                                       "95 % CI and a verdict under each reading (one campaign directory per "
                                       "reading), plus the paper's tables and figures.", epilog=REPORT_EXAMPLES,
                           formatter_class=argparse.RawDescriptionHelpFormatter)
    rep.add_argument("dirs", nargs="+", metavar="DIR",
                     help="campaign directories (from 'campaign run'), one per reading")
    rep.add_argument("--out", default=None, metavar="DIR2", help="report directory (default: FIRST_DIR/report)")
    rep.add_argument("--replicates", type=setting_int("--replicates", BOOTSTRAP_REPLICATES), default=None,
                     metavar="B", help=BOOTSTRAP_REPLICATES.flag_help("bootstrap replicates"))
    rep.add_argument("--bootstrap-seed", type=int_at_least("--bootstrap-seed", 0), default=None, metavar="S",
                     help="bootstrap seed (default 14)")
    rep.add_argument("--recount", action="append", default=[], metavar="NAME:key=value[,...]",
                     help="add a reading counted differently from the same results (keys: received, window); "
                          "repeatable")
    rep.add_argument("--note", action="append", default=[], metavar="TEXT",
                     help="a paragraph printed under the report's introduction (e.g. the seeds used while "
                          "developing); repeatable")
    rep.add_argument("--json", action="store_true", help="print a JSON summary (paths, verdict counts) on stdout")
    rep.set_defaults(func=report_cmd)


def _add_run_options(r) -> None:
    """The options of ``campaign run`` (also taken by ``campaign sweep``)."""
    r.add_argument("--groups", metavar="G1,G2,...|FILE.yaml", default=None,
                   help="comma-separated groups of the group table, or a YAML file of group definitions "
                        "(default: B-1,B-2,IC-1,ID-1,ID-2)")
    r.add_argument("--waitmap", default=None, metavar="PRESET|GRID|DIR",
                   help="wait maps of the map groups: alerting (default), paper, fine, a grid spec or a "
                        "'waitmap build' directory")
    r.add_argument("--gamma", type=finite_float("--gamma", *GAMMA.range), default=None,
                   help="MDP discount of the wait maps (default: the map preset's, 0.95)")
    add_flags(r)  # --wt, --projl-horizon, ...: every per-group setting (daa_sil.config.settings)
    r.add_argument("--latency", default=None, metavar="SPEC",
                   help="latency of every group: const:4, gauss:5,3, uniform:1,8 (default: each group's); "
                        "the reading's rule applies it (paper: the round trip, half on each link; extended: "
                        "one-way on both links)")
    r.add_argument("--intruders", type=setting_int("--intruders", INTRUDERS), default=None, metavar="M",
                   help=INTRUDERS.flag_help())
    r.add_argument("--reading", default=None, metavar="NAME",
                   help=f"a named reading of the paper's simulator (default {DEFAULT_READING}; see 'Readings' "
                        f"below): {', '.join(READINGS)}")
    r.add_argument("--reading-set", default=None, metavar="KEY=VALUE,...",
                   help="override settings of the reading: units=metres|feet, pilot_start=corrective|preventive|"
                        "detection, pilot_stop=alert|safe-avoidance, hold_commands=true|false, "
                        "unsafe_hold=blend|no-command, waitmap=paper|alerting|..., outside=clamp|far, "
                        "latency=one-way|round-trip, wait_rule=threshold|countdown, window=active|whole, "
                        "received=arrived|pilot+blend|executed, blends=all|maneuvers")
    r.add_argument("--encounters", type=setting_int("--encounters", ENCOUNTERS), default=None, metavar="N",
                   help=ENCOUNTERS.flag_help() + "; a campaign whose estimated peak memory exceeds the machine's "
                                                  "is refused before it starts (see --allow-large)")
    r.add_argument("--seed", type=setting_int("--seed", SEED), default=None, metavar="S",
                   help=f"campaign seed (default {SEED.default})")
    r.add_argument("--duration", type=finite_float("--duration", *DURATION.range), default=None, metavar="S",
                   help=DURATION.flag_help())
    r.add_argument("--chunk-size", type=setting_int("--chunk-size", CHUNK_SIZE), default=None, metavar="C",
                   help=f"encounters per chunk (default {CHUNK_SIZE.default}): one result file per group and chunk "
                        "(results do not depend on it)")
    r.add_argument("--batch-rows", type=setting_int("--batch-rows", BATCH_ROWS), default=None, metavar="R",
                   help="encounter rows per task: several chunks of several groups run side by side in one "
                        f"batch (default {BATCH_ROWS.default}, about 0.4 GiB per worker; results do not depend on it)")
    r.add_argument("--out", required=True, metavar="DIR",
                   help="output directory (must be empty unless --resume or --force; held by this run while it "
                        "writes, so a second run into it is refused)")
    r.add_argument("--workers", type=workers_option(), default=None, metavar="K",
                   help=f"worker processes (1 = in-process; default 1; at most {WORKERS_PER_CORE} per core); not "
                        "with a remote --scheduler")
    r.add_argument("--scheduler", default=None, metavar="ADDRESS|local-dask",
                   help="run on a Dask cluster at ADDRESS (tcp://host:8786) or a local one (local-dask)")
    r.add_argument("--resume", action="store_true", help="continue the campaign in DIR (skips complete chunks)")
    r.add_argument("--force", action="store_true",
                   help="replace the campaign in a non-empty DIR (its campaign.json, encounter set and chunk files)")
    add_allow_large(r, "the campaign")
    r.add_argument("--preset", default=None, help=f"threshold preset: {', '.join(PRESETS)} (default {PRESET.default})")
    add_config_argument(r)
    r.add_argument("--no-progress", action="store_true", help="no progress bars")
    r.add_argument("--json", action="store_true", help="print a JSON summary on stdout")


def _config_from_args(args):
    from daa_sil.study.campaign.run import parse_groups  # lazy: start-up time
    from daa_sil.study.campaign.config import CampaignConfig  # lazy: start-up time
    from daa_sil.study.campaign.files import load_campaign_json  # lazy: start-up time

    given = {"groups": parse_groups(args.groups) if args.groups is not None else None,
             "n_encounters": args.encounters, "seed": args.seed, "chunk_size": args.chunk_size,
             "preset": args.preset.lower() if args.preset else None, "duration_s": args.duration,
             "waitmap": args.waitmap, "gamma": args.gamma, "latency": args.latency, "n_intruders": args.intruders,
             "reading": args.reading,
             "reading_set": parse_reading_settings(args.reading_set) if args.reading_set else None}
    if args.preset and args.preset.lower() not in PRESETS:
        raise UsageError(f"unknown --preset {args.preset!r}; allowed: {', '.join(PRESETS)}")
    base = CampaignConfig.from_run_config(load_config(args.config)) if args.config else CampaignConfig()
    out = Path(args.out)
    if args.resume and (out / "campaign.json").is_file():
        if args.config:
            raise UsageError("--config does not go with --resume: the campaign's configuration is in "
                             f"{out / 'campaign.json'} (drop --config)")
        base = CampaignConfig.from_dict(load_campaign_json(out)["config"], str(out / "campaign.json"))
    if args.reading is not None:
        _, notice = canonical_name(args.reading)
        if notice:
            print(f"daa-sil: note: {notice}", file=sys.stderr)
    fields = {k: (v if v is not None else getattr(base, k)) for k, v in given.items()}
    fields = _waitmap_into_reading(fields, args.waitmap)
    settings = Overrides.from_args(args).over(base.settings)  # the flags over the file's
    return CampaignConfig(dt_s=base.dt_s, daa=base.daa, pilot=base.pilot, settings=settings, **fields).validate()


def _waitmap_into_reading(fields: dict, given: "str | None") -> dict:
    """An explicit ``--waitmap`` under a reading that sets its own grid (e.g. ``paper``) sets the
    reading's grid (recorded as ``reading_set.waitmap``); otherwise it is the campaign's."""
    from daa_sil.waitmap.source import DEFAULT_MAP  # lazy: start-up time

    if given is None:
        return fields
    rset = dict(fields.get("reading_set") or {})
    if reading_for(fields["reading"], **rset).waitmap is None:
        return fields
    rset["waitmap"] = given
    return {**fields, "reading_set": rset, "waitmap": DEFAULT_MAP}


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


def _check_resume_force(args) -> None:
    if args.resume and args.force:
        raise UsageError("--resume continues what is in --out and --force replaces it: give one of them")


def _interrupted(exc: KeyboardInterrupt, detail: str) -> Interrupted:
    """The one line a Ctrl-C (or SIGTERM / SIGHUP) of a campaign ends with: what is kept, how to go on."""
    return Interrupted(interrupt_signum(exc), detail)


def run_cmd(args) -> int:
    from daa_sil.study.campaign.run import run_campaign  # lazy: start-up time

    _check_resume_force(args)
    cfg = _config_from_args(args)
    check_scheduler(args.scheduler, args.workers)
    batch = {"batch_rows": args.batch_rows} if args.batch_rows is not None else {}
    written = []
    try:
        summary = run_campaign(cfg, args.out, workers=args.workers or 1, scheduler=args.scheduler, resume=args.resume,
                               progress=not args.no_progress and not args.json, on_chunk=written.append,
                               allow_large=args.allow_large, force=args.force, **batch)
    except KeyboardInterrupt as exc:
        out = shlex.quote(str(args.out))
        raise _interrupted(exc, f"({len(written)} chunks written in this run are kept in {args.out}); continue with: "
                                f"daa-sil campaign run --out {out} --resume") from None
    rate = summary.encounter_steps / summary.wall_s if summary.wall_s > 0 else float("nan")
    info = {"out": str(summary.out_dir), "groups": list(cfg.group_names), "encounters": cfg.n_encounters,
            "seed": cfg.seed, "preset": cfg.preset, "chunks_total": summary.chunks_total,
            "chunks_skipped": summary.chunks_skipped, "chunks_run": summary.chunks_run,
            "chunks_damaged": summary.chunks_damaged,
            "wall_s": round(summary.wall_s, 3), "encounter_steps_per_s": rate,
            "config": cfg.to_dict(), "resolved_config": cfg.resolved()}
    if args.json:
        print(json.dumps(to_jsonable(info), indent=2, sort_keys=True))
    else:
        redone = f" ({len(summary.chunks_damaged)} of them damaged on disk)" if summary.chunks_damaged else ""
        print(f"campaign {summary.out_dir}: {summary.chunks_run} chunks run{redone}, {summary.chunks_skipped} skipped "
              f"({len(cfg.groups)} groups x {cfg.n_encounters} encounters, preset {cfg.preset}, wait maps "
              f"{cfg.map_source}, reading {cfg.effective_reading.name}) in "
              f"{summary.wall_s:.1f} s ({rate:,.0f} encounter-steps/s)", file=sys.stderr)
        print(f"next: daa-sil campaign report {shlex.quote(str(summary.out_dir))}   (findings, tables and figures "
              f"next to the paper's)", file=sys.stderr)
    return 0


def sweep_cmd(args) -> int:
    from daa_sil.study.analysis import sweep  # lazy: start-up time

    if args.collate:
        if args.vary:
            raise UsageError("--collate and --vary do not go together: collate existing sweeps or run one")
        path = sweep.collate(args.collate, args.out)
        print(str(path))
        return 0
    if not args.vary:
        raise UsageError("campaign sweep needs --vary NAME=V1,V2,... (or --collate SWEEP_DIR ...)")
    _check_resume_force(args)
    vary = sweep.parse_vary(args.vary)
    if vary.setting is not None:
        flag, given = vary.setting.flag, getattr(args, flag_dest(vary.setting), None)
    else:
        flag, given = f"--{vary.field}", getattr(args, vary.field, None)
    if (vary.setting is not None or vary.field in ("waitmap", "gamma", "latency", "reading")) and given is not None:
        raise UsageError(f"--vary {vary.name} sets the {flag[2:]} of every point; drop {flag}")
    base = _config_from_args(args)  # the sweep directory has no campaign.json: defaults + the options given
    check_scheduler(args.scheduler, args.workers)
    quiet = args.no_progress or args.json
    try:
        meta = sweep.run_sweep(base, vary, args.out, workers=args.workers or 1, scheduler=args.scheduler,
                               resume=args.resume, progress=not quiet, batch_rows=args.batch_rows,
                               allow_large=args.allow_large, force=args.force,
                               say=None if args.json else (lambda m: print(f"daa-sil: {m}", file=sys.stderr, flush=True)))
    except KeyboardInterrupt as exc:
        raise _interrupted(exc, f"(the points and chunks finished so far are kept in {args.out}); continue with the "
                                f"same command and --resume") from None
    if args.json:
        print(json.dumps(to_jsonable({"out": args.out, "vary": meta["vary"], "values": meta["values"]}), sort_keys=True))
    else:
        print(f"sweep {args.out}: {len(meta['values'])} points of {meta['vary']}; table {Path(args.out) / 'sweep.md'}",
              file=sys.stderr)
    return 0


def report_cmd(args) -> int:
    from daa_sil.study.report import pages as report  # lazy: start-up time
    from daa_sil.study.analysis.report_input import parse_recount  # lazy: start-up time
    from daa_sil.study.analysis.findings import VERDICTS  # lazy: start-up time
    from daa_sil.study.analysis.stats import DEFAULT_REPLICATES, DEFAULT_SEED  # lazy: start-up time

    dirs = [Path(d) for d in args.dirs]
    for d in dirs:
        if not (d / "campaign.json").is_file():
            raise UsageError(f"{d} is not a campaign directory (no campaign.json)")
    if len(set(map(str, (d.resolve() for d in dirs)))) != len(dirs):
        raise UsageError("a campaign directory is given twice")
    for spec in args.recount:
        parse_recount(spec)  # one-line error before anything is read or written
    out = Path(args.out) if args.out else dirs[0] / "report"

    try:  # a bad name (UTF-8, length) now; an unwritable directory when the report is written (exit 1)
        check_output_path(out, "--out", directory=True)
    except OutputError:
        pass
    reps = args.replicates or DEFAULT_REPLICATES
    seed = DEFAULT_SEED if args.bootstrap_seed is None else args.bootstrap_seed
    path = report.write_report(dirs if len(dirs) > 1 else dirs[0], out, replicates=reps, seed=seed,
                               recount=args.recount, notes=args.note)
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
