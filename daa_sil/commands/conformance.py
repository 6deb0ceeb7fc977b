"""``daa-sil conformance``: agreement of the onboard DAA with DAIDALUS reference outputs (JSONL)."""

from __future__ import annotations

import argparse
import json
import sys

from ..daa import DaaConfig
from ..daa import conformance as conf
from ..errors import UsageError
from daa_sil.config.config_option import add_config_argument
from daa_sil.config.run_config import load_config
from daa_sil.files import to_jsonable
from daa_sil.geometry.thresholds import PRESETS
from .common_args import int_at_least

EXAMPLES = """examples:
  # the project's DAIDALUS v2.0.4 reference set (1,000 encounters), with the daidalus preset
  daa-sil conformance tests/data/daidalus_do365b.jsonl.xz

  # the same encounters judged with today's default preset, and the 5 worst records
  daa-sil conformance tests/data/daidalus_do365b.jsonl.xz --preset do365 --worst 5

  # your own DAIDALUS run, as JSON, failing (exit 1) below the floors of issue 15
  daa-sil conformance my_daidalus_runs.jsonl --json --check

FILE holds one JSON object per line (plain, .gz or .xz) in the format of the conformance set:
own_pos_enu_m, own_vel_enu_mps, int_pos_enu_m, int_vel_enu_mps (ENU, SI) and DAIDALUS's outputs
(dwc_conflict, dwc_t_in_s, dwc_t_out_s, alert_level, track_bands_deg, hs_bands_kt, vs_bands_fpm,
own_*_region, *_resolution_*, *_preferred_direction); docs/daa.md lists every field. Strict JSON:
NaN as null, +-inf as "inf" / "-inf". Classification is scored per degree, per knot and per 100 fpm
over DO_365B_no_SUM.conf's ranges (0-360 deg, 10-700 kt, +-6000 fpm).
"""


def register(sub) -> None:
    p = sub.add_parser("conformance", help="agreement of the onboard DAA with DAIDALUS reference outputs",
                       description="Run the onboard DAA on every record of a DAIDALUS reference file and print "
                                   "the agreement table (DWC interval, alert level, band classification, "
                                   "region names, resolutions, preferred directions).",
                       epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("file", metavar="FILE.jsonl", help="reference records, one JSON object per line (.gz/.xz ok)")
    p.add_argument("--preset", default=None, help=f"DAA preset: {', '.join(PRESETS)} (default: the --config's "
                                                  "thresholds, else daidalus)")
    add_config_argument(p, "daidalus")
    p.add_argument("--json", action="store_true", help="print one JSON object (table, floors, worst records)")
    p.add_argument("--worst", type=int_at_least("--worst", 0), default=0, metavar="K",
                   help="also list the K records with the lowest band agreement (default 0)")
    p.add_argument("--check", action="store_true",
                   help="exit 1 when a quantity is below its floor (the daidalus preset's floors of issue 15)")
    p.set_defaults(func=run)


def run(args) -> int:
    rc = load_config(args.config) if args.config else None
    preset = (args.preset or (rc.thresholds if rc else "daidalus")).lower()
    if preset not in PRESETS:
        raise UsageError(f"unknown --preset {args.preset!r}; allowed: {', '.join(PRESETS)}")
    records = conf.read_records(args.file)
    if not args.json:
        print(f"daa-sil: {len(records)} records from {args.file}; evaluating with preset {preset} ...",
              file=sys.stderr, flush=True)
    table, scores = conf.run(records, DaaConfig.for_preset(preset, **(rc.daa if rc else {})))
    below = conf.failures(table)
    if args.json:
        worst = sorted(scores, key=lambda s: (s.worst(), s.id))[:args.worst]
        out = {"file": str(args.file), "preset": preset,
               "config": (rc.with_(thresholds=preset).to_dict(full=True) if rc else None), "table": table, "floors": conf.FLOORS, "below_floor": below,
               "worst": [{"id": s.id, "classified": s.classified, "region_ok": s.region_ok, "res_ok": s.res_ok,
                          "pref_ok": s.pref_ok, "alert_ok": s.alert_ok, "dwc_err_s": s.dwc_err_s, "detail": s.detail}
                         for s in worst]}
        print(json.dumps(to_jsonable(out), sort_keys=True))
    else:
        print(conf.format_table(table, preset, conf.FLOORS))
        if args.worst:
            print(f"\n{args.worst} records with the lowest band agreement:")
            print(conf.worst_records(scores, args.worst))
        print("\nbelow floor: " + (", ".join(below) if below else "none"))
    return 1 if (args.check and below) else 0
