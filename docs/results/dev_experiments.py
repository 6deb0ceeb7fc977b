"""The development experiments of issue 22 §2: which reading's simulator resembles the paper's, and
which model choice moves the remaining gap -- on a development seed, never the report seed.

    python docs/results/dev_experiments.py --runs /tmp/dev --seed 99991 --encounters 1000 [--workers 2]

Runs (resumable; one campaign directory each, groups B-2 and ID-2 unless noted):

* the readings ``paper`` and ``paper-corrective`` (the five groups and ID-2-projl), ``paper-hold-blend``, ``paper-no-hold``,
  ``paper-one-way``, ``paper-outside-far``, ``paper-countdown``, ``paper-preventive``, ``paper-feet``,
  ``detection`` and ``extended``;
* model-choice experiments on the ``paper`` reading (not readings: the text does not allow them):
  ``edge-margin`` -- the pilot never takes a band's edge (its gamma-distributed extra beyond the
  conflict-free value is never clamped to zero: offsets 0 instead of 30 deg / 1,500 ft); ``sm35`` and
  ``sm25`` -- SM(u)'s horizon 35 s or 25 s instead of 55 s;
* IC-1 with a constant wait of 5 s and of 50 s under the ``threshold`` and ``countdown`` rules;

then prints the signatures of every run (``daa_sil/study/signatures.py``) as a Markdown table.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from daa_sil.config.groups import group_spec  # noqa: E402
from daa_sil.study.campaign import run_campaign  # noqa: E402
from daa_sil.study.campaign_config import CampaignConfig  # noqa: E402

#: the report seed: never used here
REPORT_SEED = 20261201
PAIR = ("B-2", "ID-2")
ALL = ("B-1", "B-2", "IC-1", "ID-1", "ID-2", "ID-2-projl")
EDGE = {"turn_primary": (6.21, 9.67, 0.0), "turn_opposite": (5.47, 8.25, 0.0), "vertical": (9.73, 207.98, 0.0)}


def _ic1(wait: float, name: str):
    return group_spec("IC-1").with_(name=name, wait=float(wait))


def runs() -> dict:
    """name -> CampaignConfig keyword arguments (without seed / size)."""
    out = {"paper": dict(groups=ALL, reading="paper"), "paper-corrective": dict(groups=ALL, reading="paper-corrective")}
    for r in ("paper-hold-blend", "paper-no-hold", "paper-one-way", "paper-outside-far", "paper-countdown",
              "paper-preventive", "paper-feet", "detection", "extended"):
        out[r] = dict(groups=PAIR, reading=r)
    out["edge-margin"] = dict(groups=PAIR, reading="paper", pilot=EDGE)
    out["sm35"] = dict(groups=PAIR, reading="paper", daa={"sm_horizon_s": 35.0})
    out["sm25"] = dict(groups=PAIR, reading="paper", daa={"sm_horizon_s": 25.0})
    ic = (_ic1(5, "IC-1"), _ic1(50, "IC-1-w50"))
    out["ic1-threshold"] = dict(groups=ic, reading="paper")
    out["ic1-countdown"] = dict(groups=ic, reading="paper-countdown")
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=Path, required=True)
    ap.add_argument("--seed", type=int, default=99991)
    ap.add_argument("--encounters", type=int, default=1000)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--only", default=None, help="comma-separated run names")
    ap.add_argument("--summary-only", action="store_true")
    args = ap.parse_args()
    if args.seed == REPORT_SEED:
        ap.error("the report seed is reserved for the final regeneration")
    todo = runs()
    if args.only:
        todo = {k: v for k, v in todo.items() if k in args.only.split(",")}
    if not args.summary_only:
        for name, kw in todo.items():
            d = args.runs / name
            cfg = CampaignConfig(n_encounters=args.encounters, seed=args.seed, **kw)
            again = d.is_dir() and any(d.iterdir())
            print(f"== {name} ({'resuming' if again else 'running'})", flush=True)
            run_campaign(cfg, d, workers=args.workers, resume=again, progress=False)
    from daa_sil.study.signatures import signature_table

    dirs = {k: args.runs / k for k in todo if (args.runs / k / "campaign.json").is_file()}
    print(signature_table(dirs))
    return 0


if __name__ == "__main__":
    sys.exit(main())
