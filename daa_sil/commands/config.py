"""``daa-sil config show PRESET|FILE``: print a run configuration (YAML or JSON)."""

from __future__ import annotations

import argparse
import json

import yaml

from daa_sil.config.run_config import PRESET_NAMES, load_config
from daa_sil.config.settings import describe
from daa_sil.files import to_jsonable

EXAMPLES = """examples:
  # the paper preset, as a file to edit and pass back with --config
  daa-sil config show paper > my.yaml

  # what a file resolves to: every DAA, pilot and group value it implies
  daa-sil config show my.yaml --full

  # the DAIDALUS DO_365B configuration as JSON
  daa-sil config show daidalus --full --json

A configuration file names a preset under 'base' and changes any subset of its sections
(thresholds, daa, waitmap, allocation, groups, pilot, latency, link, reading, study);
daa_sil/config/run_config.py documents each one. Every command that takes --config lets its
explicit flags override the file, and records the full configuration in its outputs.
"""


def register(sub) -> None:
    p = sub.add_parser("config", help="run configurations: presets and YAML files",
                       description="Show a run configuration (a preset or a YAML file).",
                       epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    verbs = p.add_subparsers(dest="verb", metavar="VERB", parser_class=type(p))
    verbs.required = True
    s = verbs.add_parser("show", help="print a configuration", epilog=EXAMPLES,
                         formatter_class=argparse.RawDescriptionHelpFormatter)
    s.add_argument("config", metavar="PRESET|FILE", help=f"a preset ({', '.join(PRESET_NAMES)}) or a YAML file")
    s.add_argument("--full", action="store_true", help="add every resolved value (what outputs record) and the "
                   "default, range and help of each shared setting")
    s.add_argument("--json", action="store_true", help="print JSON instead of YAML")
    s.set_defaults(func=show)


def show(args) -> int:
    cfg = load_config(args.config)
    d = cfg.to_dict(full=args.full)
    if args.full:  # the defaults, ranges and help of the settings several inputs share (one definition each)
        d["settings"] = describe()
    if args.json:
        print(json.dumps(to_jsonable(d), indent=2))
    else:
        print(yaml.safe_dump(d, sort_keys=False), end="")
    return 0
