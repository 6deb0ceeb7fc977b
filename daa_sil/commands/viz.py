"""``daa-sil viz steplog|replay``: Rerun visualisation of step logs and of campaign encounters."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from ..errors import FileFormatError, OutputError, UsageError
from daa_sil.config.settings import STANDARD_PRESET
from daa_sil.geometry.thresholds import PRESETS
from .common_args import finite_float
from daa_sil.sil.children import interruptible
from daa_sil.viz.warning import one_line_warnings
from daa_sil.sil.web_ports import add_web_viewer_arguments, check_web_viewer_arguments
from daa_sil.files import check_output_path
from ..viz import SinkOptions
from .. import steplog, viz

STEPLOG_EX = """examples:
  daa-sil viz steplog runs/headon/steps.parquet --rrd headon.rrd
  daa-sil viz steplog steps.parquet --encounter 42 --rrd enc42.rrd --until 150
  daa-sil viz steplog steps.parquet --serve-web            # http://127.0.0.1:9090, Ctrl-C to stop
  daa-sil viz steplog steps.parquet --connect rerun+http://127.0.0.1:9876/proxy

A step log holds one row per encounter per step (SIL run or fast-time). --until keeps the steps up to
that sim time, so a viewer opens the file at that moment.
"""

REPLAY_EX = """examples:
  daa-sil viz replay results/ --group ID-1 --worst --rrd worst.rrd
  daa-sil viz replay results/ --group B-1 --encounter 1234 --rrd b1-1234.rrd
  daa-sil viz replay results/ --group IC-1 --worst --serve-web

Re-simulates one encounter of a fast-time campaign (same encounter set, seed, group policy and latency
model) with full step logging. --worst picks the encounter of the group with the largest penetration
integral among those that lost well clear, ties broken by the smallest minimum range (or the smallest
minimum range if none lost well clear).
"""


def _sink_args(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("where the visualisation goes (at least one)")
    g.add_argument("--rrd", metavar="FILE", help="write a Rerun .rrd file (atomically)")
    g.add_argument("--force", action="store_true", help="overwrite an existing --rrd file")
    g.add_argument("--spawn-viewer", action="store_true", help="open the native Rerun viewer (needs a display)")
    g.add_argument("--connect", metavar="URL", help="stream to a running viewer, e.g. rerun+http://127.0.0.1:9876/proxy")
    add_web_viewer_arguments(g, "serve the web viewer until Ctrl-C")
    p.add_argument("--json", action="store_true", help="print a JSON summary")


def register(sub) -> None:
    p = sub.add_parser("viz", help="Rerun visualisation of step logs and campaign encounters",
                       description="Rerun visualisation: 3-D encounter, top-down view, bands, decisions, plots.")
    vs = p.add_subparsers(dest="viz_command", metavar="VERB", parser_class=type(p))
    vs.required = True
    s = vs.add_parser("steplog", help="convert a step log (SIL or fast-time) to Rerun", epilog=STEPLOG_EX,
                      formatter_class=argparse.RawDescriptionHelpFormatter)
    s.add_argument("steplog", metavar="STEPLOG.parquet")
    s.add_argument("--encounter", type=int, metavar="ID", help="encounter id (needed if the log holds several)")
    s.add_argument("--preset", help=f"threshold preset for the well-clear volume: {', '.join(PRESETS)} "
                                    f"(default: the log's metadata, else {STANDARD_PRESET.default})")
    s.add_argument("--until", type=finite_float("--until", 0.0), metavar="S", help="keep steps with t <= S")
    _sink_args(s)
    s.set_defaults(func=interruptible(run_steplog))
    r = vs.add_parser("replay", help="re-simulate one campaign encounter with step logging", epilog=REPLAY_EX,
                      formatter_class=argparse.RawDescriptionHelpFormatter)
    r.add_argument("results", metavar="RESULTS", help="campaign results directory (with campaign.json)")
    r.add_argument("--group", required=True, help="group, e.g. ID-1")
    which = r.add_mutually_exclusive_group(required=True)
    which.add_argument("--encounter", type=int, metavar="ID", help="encounter id")
    which.add_argument("--worst", action="store_true", help="the worst LoWC of the group by penetration integral")
    r.add_argument("--until", type=finite_float("--until", 0.0), metavar="S", help="keep steps with t <= S")
    r.add_argument("--save-steplog", metavar="FILE", help="also write the step log as Parquet")
    _sink_args(r)
    r.set_defaults(func=interruptible(run_replay))


def output_name_ok(path, option: str) -> None:
    """A bad output name (not UTF-8, too long) is a one-line usage error now; whether its directory can
    be written is found out after the input was read (bad input is reported first)."""

    try:
        check_output_path(path, option)
    except OutputError:
        pass


def sink_options(args):
    """SinkOptions from the CLI flags (UsageError if none is chosen)."""

    if not (args.rrd or args.spawn_viewer or args.connect or args.serve_web):
        raise UsageError("choose an output: --rrd FILE, --serve-web, --spawn-viewer or --connect URL")
    check_web_viewer_arguments(args)
    if args.rrd and not str(args.rrd).endswith(".rrd"):
        raise UsageError(f"--rrd {args.rrd!r} should end in .rrd")
    for option, path in (("--rrd", args.rrd), ("--save-steplog", getattr(args, "save_steplog", None))):
        if path:
            output_name_ok(path, option)
    return SinkOptions(rrd=args.rrd, spawn=args.spawn_viewer, connect=args.connect, serve_web=args.serve_web,
                       bind=args.bind, web_port=args.web_port, grpc_port=args.grpc_port, overwrite=args.force)


def _finish(args, path, logger, summary: dict) -> int:
    summary.update({"rrd": str(path) if path else None, "steps": logger.steps_logged,
                    "web_url": logger.web.url if logger.web is not None and logger.web.alive() else None})

    def report() -> None:
        if args.json:
            print(json.dumps(summary, sort_keys=True))
        else:
            if path:
                print(f"wrote {path} ({Path(path).stat().st_size / 1000:.0f} kB, {logger.steps_logged} steps)")
            if summary["web_url"]:
                print(f"web viewer: {summary['web_url']}  (Ctrl-C to stop)")
        sys.stdout.flush()

    if summary["web_url"] and not (args.rrd and path is None):
        logger.wait_serving(announce=report)  # a Ctrl-C / SIGTERM right after the URL is a clean stop
        return 0
    report()
    if args.rrd and path is None:
        return 1
    if args.serve_web and not summary["web_url"]:
        raise OutputError(f"--serve-web: the Rerun web viewer did not start on {args.bind} "
                          f"(ports {args.web_port}, {args.grpc_port}); nothing is served")
    return 0


def run_steplog(args) -> int:
    opts = sink_options(args)
    table = steplog.read_steplog(args.steplog)
    meta = steplog.steplog_metadata(args.steplog)
    preset = args.preset or meta.get("preset") or STANDARD_PRESET.default
    if preset.lower() not in PRESETS:
        raise UsageError(f"unknown --preset {preset!r}; allowed: {', '.join(PRESETS)}")
    if table.num_rows == 0:
        raise FileFormatError(f"step log {args.steplog} has no rows")
    with one_line_warnings():
        path, logger = viz.log_steplog(table, opts, encounter_id=args.encounter, preset=preset.lower(),
                                       keep_serving=args.serve_web, until_s=args.until)
        return _finish(args, path, logger, {"steplog": args.steplog, "encounter_id": logger.encounter_id,
                                            "preset": preset.lower()})


def pick_encounter(results, group: str, encounter: "int | None", worst: bool) -> tuple[int, dict]:
    """The encounter id to replay and its result row (``--worst``: max PI among LoWC, else min range)."""
    from daa_sil.study.campaign import files as campaign_files  # lazy: start-up time

    rows = campaign_files.read_results(results, "encounters", groups=[group])
    ids = np.asarray(rows.column("encounter_id").to_numpy(zero_copy_only=False))
    if worst:
        lowc = np.asarray(rows.column("lowc").to_numpy(zero_copy_only=False), bool)
        rng = np.asarray(rows.column("min_range_m").to_numpy(zero_copy_only=False), float)
        if lowc.any():
            pi = np.nan_to_num(np.asarray(rows.column("pi").to_numpy(zero_copy_only=False), float), nan=0.0)
            cand = np.flatnonzero(lowc)
            k = int(cand[np.lexsort((rng[cand], -pi[cand]))[0]])  # largest PI, then smallest range
        else:
            k = int(np.nanargmin(rng))
    else:
        hits = np.flatnonzero(ids == encounter)
        if hits.size == 0:
            raise UsageError(f"encounter {encounter} has no result in group {group} of {results}")
        k = int(hits[0])
    return int(ids[k]), rows.slice(k, 1).to_pylist()[0]


def campaign_group(results, name: str) -> str:
    """The campaign's group named ``name`` (case-insensitive), or a one-line error listing its groups."""
    from daa_sil.study.campaign import run as campaign  # lazy: start-up time
    from daa_sil.study.campaign import files as campaign_files  # lazy: start-up time

    out = Path(results)
    cfg = campaign.CampaignConfig.from_dict(campaign_files.load_campaign_json(out)["config"], str(out / "campaign.json"))
    for g in cfg.group_names:
        if g.upper() == str(name).strip().upper():
            return g
    raise UsageError(f"group {name} is not in the campaign {out} (it ran {', '.join(cfg.group_names)})")


def replay_steplog(results, group: str, encounter_id: int):
    """Re-simulate one encounter of a campaign with step logging; returns (steplog, encounter row, config)."""
    from daa_sil.study.campaign import run as campaign  # lazy: start-up time
    from daa_sil.study.campaign import files as campaign_files  # lazy: start-up time
    from daa_sil.models.encounter_files import load_encounters  # lazy: start-up time

    out = Path(results)
    cfg = campaign.CampaignConfig.from_dict(campaign_files.load_campaign_json(out)["config"], str(out / "campaign.json"))
    if group not in cfg.group_names:
        raise UsageError(f"group {group} is not in the campaign {out} (it ran {', '.join(cfg.group_names)})")
    encs = load_encounters(out / "encounters.parquet")
    pos = np.flatnonzero(np.asarray(encs.encounter_id) == encounter_id)
    if pos.size == 0:
        raise UsageError(f"encounter {encounter_id} is not in {out / 'encounters.parquet'}")
    one = encs.subset(pos[:1])
    seeds = campaign.encounter_seeds(cfg.seed, np.array([encounter_id]))
    # the campaign's own settings (reading, pilot, DAA, link legs): the replay flies what the campaign flew
    enc_rows, _, steps = campaign.simulate_group(cfg, group, one, seeds, record_steps=True)
    return steps, enc_rows.to_pylist()[0], cfg


def run_replay(args) -> int:
    opts = sink_options(args)
    group = campaign_group(args.results, args.group)
    enc_id, stored = pick_encounter(args.results, group, args.encounter, args.worst)
    steps, row, cfg = replay_steplog(args.results, group, enc_id)
    for key in ("lowc", "nmac"):
        if bool(row[key]) != bool(stored[key]):
            print(f"daa-sil: warning: the replay gives {key}={row[key]}, the campaign stored {stored[key]} "
                  f"(different code version?)", file=sys.stderr)
    if args.save_steplog:
        steplog.write_steplog(steps, args.save_steplog, metadata={"preset": cfg.preset, "group": group},
                              overwrite=args.force)
    with one_line_warnings():
        path, logger = viz.log_steplog(steps, opts, encounter_id=enc_id, preset=cfg.preset,
                                       keep_serving=args.serve_web, until_s=args.until)
        summary = {"results": args.results, "group": group, "encounter_id": enc_id, "preset": cfg.preset,
                   "lowc": bool(row["lowc"]), "nmac": bool(row["nmac"]), "pi": row["pi"],
                   "min_range_m": row["min_range_m"]}
        if not args.json:
            print(f"{group} encounter {enc_id}: LoWC {'yes' if row['lowc'] else 'no'}, PI {row['pi']:.3g}, "
                  f"min range {row['min_range_m']:.0f} m")
        return _finish(args, path, logger, summary)
