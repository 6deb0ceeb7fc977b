"""Check that this checkout's results are identical to a baseline commit's (issue 21: "0 differences").

Runs, for this checkout and for a baseline checkout installed apart (its own ``.venv`` and its own
``DAA_SIL_CACHE``, e.g. bba2fd8), and compares with :func:`daa_sil.study.campaign.compare.compare_dirs`
(floats bit for bit, NaN equal to NaN):

* **campaigns**: every reading of ``--readings`` x the groups of ``--groups`` x ``--encounters``
  (seed ``--seed``), ``daa-sil campaign run`` on both sides, reading by its name at the baseline;
* **SIL** (``--sil``): every scenario of ``--scenarios`` through ``daa-sil run`` (lockstep, three
  processes) on both sides, step logs compared;
* **conformance** (``--conformance``): ``daa-sil conformance --json`` of the DAIDALUS reference set
  under each preset of ``--presets``, the JSON text compared byte for byte.

Prints one line per comparison and a final ``identical: yes|no``; exit 0 when everything is
identical, 1 when something differs or a run failed, 2 (one line) on bad arguments. Each side's
output goes under ``--work`` (empty or new; default: a temporary directory, removed at the end unless
``--keep``).

One baseline, installed apart (the benchmarks find it at ``/work/baseline`` by default)::

    git worktree add /work/baseline bba2fd8
    (cd /work/baseline && python3 -m venv .venv && .venv/bin/pip install -e ".[dev]")
    DAA_SIL_CACHE=/work/cache-baseline /work/baseline/.venv/bin/daa-sil demo   # builds its wait maps

examples::

    python benchmarks/check_identity.py                               # every bba2fd8 reading x 7 groups x 2,000
    python benchmarks/check_identity.py --readings literal --encounters 200 --sil --conformance
    python benchmarks/check_identity.py --readings paper=paper-contradicted,extended --allow-added-columns
    python benchmarks/check_identity.py --baseline /tmp/start --baseline-cache ~/.cache/daa-sil \\
        --baseline-python .venv/bin/python                            # an earlier commit's sources (a worktree)
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))

from baseline_paths import BASELINE_CACHE, BASELINE_DIR  # noqa: E402
#: the readings that exist at bba2fd8, by their names there (``literal`` is called ``extended`` now)
BBA2FD8_READINGS = ("literal", "paper-counts", "preventive", "feet", "detection", "no-hold", "paper-grid")
GROUPS = "B-1,B-2,IC-1,ID-1,ID-2,ID-2-projl,ID-2-map"
SCENARIOS = ("head_on", "crossing_left", "crossing_right", "overtaking", "climbing", "two_intruders",
             "link_loss", "long_delay", "pilot_unsafe_blend")
PRESETS = ("daidalus", "do365", "paper")
CONFORMANCE_SET = ROOT / "tests" / "data" / "daidalus_do365b.jsonl.xz"


class Side:
    """One checkout: how to run its ``daa-sil`` (its own interpreter, cache, and source tree)."""

    def __init__(self, name: str, python: Path, tree: Path, cache: "Path | None"):
        self.name, self.python, self.tree = name, python, tree
        self.env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
        self.env["PYTHONDONTWRITEBYTECODE"] = "1"
        if cache is not None:
            self.env["DAA_SIL_CACHE"] = str(cache)

    def run(self, args: list, out: Path) -> bool:
        """``python -m daa_sil.cli ARGS`` from the checkout, its stdout to ``out`` and its stderr to ``out``
        + ``.err`` (a notice on stderr must not make two outputs differ); True on success."""
        err = out.with_name(out.name + ".err")
        with open(out, "wb") as f, open(err, "wb") as e:
            rc = subprocess.run([str(self.python), "-m", "daa_sil.cli", *args], cwd=self.tree, env=self.env,
                                stdout=f, stderr=e).returncode
        if rc != 0:
            print(f"  {self.name}: 'daa-sil {' '.join(args)}' failed (exit {rc}); see {out} and {err}")
        return rc == 0


def compare(a: Path, b: Path, allow_added: bool = False) -> bool:
    """True when the result tables (or step logs) under ``a`` and ``b`` are identical (with
    ``allow_added``, on the columns both have; the new side's added columns are listed)."""
    from daa_sil.study.campaign.compare import compare_dirs

    res = compare_dirs(a, b, allow_added=allow_added)
    if res.added:
        names = sorted({x.split(": ", 1)[1] for x in res.added})
        print(f"    columns only in the new side (not compared): {', '.join(names)}")
    for line in res.differences[:8]:
        print(f"    {line}")
    if len(res.differences) > 8:
        print(f"    ... {len(res.differences) - 8} more")
    return res.identical and res.columns > 0


def check_campaigns(sides: list, args, work: Path) -> list:
    out = []
    for spec in args.readings:
        dirs = []
        t0 = time.perf_counter()
        base_name, _, new_name = spec.partition("=")  # BASE=NEW: the reading's name on each side
        r = spec.replace("=", "-as-")
        for s, name in zip(sides, (base_name, new_name or base_name)):
            d = work / f"{s.name}-campaign-{r}"
            ok = s.run(["campaign", "run", "--groups", args.groups, "--encounters", str(args.encounters), "--seed",
                        str(args.seed), "--reading", name, "--workers", str(args.workers), "--out", str(d),
                        "--no-progress"], work / f"{s.name}-campaign-{r}.log")
            dirs.append(d if ok else None)
        same = all(d is not None for d in dirs) and compare(*dirs, allow_added=args.allow_added_columns)
        print(f"campaign {r:13s} {args.groups} x {args.encounters}: {'identical' if same else 'DIFFERENT'} "
              f"({time.perf_counter() - t0:.0f} s)", flush=True)
        out.append(same)
    return out


def check_sil(sides: list, args, work: Path) -> list:
    out = []
    for sc in args.scenarios:
        path = ROOT / "scenarios" / f"{sc}.yaml"
        dirs = []
        for s in sides:
            d = work / f"{s.name}-sil-{sc}"
            dirs.append(d if s.run(["run", str(path), "--out", str(d)], work / f"{s.name}-sil-{sc}.log")
                        else None)
        same = all(d is not None for d in dirs) and compare(dirs[0] / "steplog.parquet", dirs[1] / "steplog.parquet",
                                                            allow_added=args.allow_added_columns)
        print(f"SIL {sc:18s} step log: {'identical' if same else 'DIFFERENT'}", flush=True)
        out.append(same)
    return out


def check_conformance(sides: list, args, work: Path) -> list:
    out = []
    for p in args.presets:
        texts = []
        for s in sides:
            log = work / f"{s.name}-conformance-{p}.json"
            ok = s.run(["conformance", str(CONFORMANCE_SET), "--preset", p, "--json"], log)
            texts.append(log.read_bytes() if ok else None)
        same = texts[0] is not None and texts[0] == texts[1]
        print(f"conformance --preset {p:9s}: {'identical' if same else 'DIFFERENT'}", flush=True)
        out.append(same)
    return out


def main(argv: "list[str] | None" = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0], epilog=__doc__.split("\n\n", 1)[1],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--baseline", type=Path, default=BASELINE_DIR,
                    help=f"the baseline checkout (default {BASELINE_DIR})")
    ap.add_argument("--baseline-python", type=Path, default=None,
                    help="the baseline's interpreter (default BASELINE/.venv/bin/python)")
    ap.add_argument("--baseline-cache", default=str(BASELINE_CACHE),
                    help=f"DAA_SIL_CACHE of the baseline (default {BASELINE_CACHE}; none: this environment's)")
    ap.add_argument("--readings", type=lambda s: [r for r in s.split(",") if r], default=list(BBA2FD8_READINGS),
                    help=f"comma-separated readings, by their names at the baseline, or BASE=NEW where the reading is "
                         f"named otherwise here (default: {','.join(BBA2FD8_READINGS)})")
    ap.add_argument("--allow-added-columns", action="store_true",
                    help="columns only this checkout writes are listed, not counted as differences (the shared "
                         "columns are still compared bit for bit)")
    ap.add_argument("--groups", default=GROUPS, help=f"groups (default {GROUPS})")
    ap.add_argument("--encounters", type=int, default=2000, help="encounters per group (default 2000)")
    ap.add_argument("--seed", type=int, default=7, help="campaign seed (default 7)")
    ap.add_argument("--workers", type=int, default=2, help="campaign workers (default 2)")
    ap.add_argument("--sil", action="store_true", help="also compare the SIL step logs of --scenarios")
    ap.add_argument("--scenarios", type=lambda s: [x for x in s.split(",") if x], default=list(SCENARIOS),
                    help="scenario names under scenarios/ (default: all nine)")
    ap.add_argument("--conformance", action="store_true", help="also compare 'daa-sil conformance --json'")
    ap.add_argument("--presets", type=lambda s: [x for x in s.split(",") if x], default=list(PRESETS),
                    help=f"conformance presets (default {','.join(PRESETS)})")
    ap.add_argument("--work", type=Path, default=None, help="where both sides write (default: a temporary directory)")
    ap.add_argument("--keep", action="store_true", help="keep the temporary directory (a given --work is always kept)")
    args = ap.parse_args(argv)
    base_py = args.baseline_python or args.baseline / ".venv" / "bin" / "python"
    if not base_py.is_file() or not (args.baseline / "daa_sil").is_dir():
        print(f"check_identity: no baseline at {args.baseline} (python {base_py}); install one apart as --help says",
              file=sys.stderr)
        return 2
    if args.encounters < 1:
        print("check_identity: --encounters must be at least 1", file=sys.stderr)
        return 2
    made = args.work is None
    if not made and args.work.exists() and any(args.work.iterdir()):
        print(f"check_identity: --work {args.work} is not empty (each run writes a new directory there)", file=sys.stderr)
        return 2
    work = Path(tempfile.mkdtemp(prefix="identity-")) if made else args.work
    work.mkdir(parents=True, exist_ok=True)
    cache = None if args.baseline_cache == "none" else Path(args.baseline_cache)
    sides = [Side("base", base_py.absolute(), args.baseline.absolute(), cache),
             Side("new", Path(sys.executable), ROOT, None)]
    print(f"baseline {args.baseline} ({base_py}) vs this checkout {ROOT}; work in {work}", flush=True)
    try:
        results = check_campaigns(sides, args, work)
        if args.sil:
            results += check_sil(sides, args, work)
        if args.conformance:
            results += check_conformance(sides, args, work)
    finally:
        if made and not args.keep:
            shutil.rmtree(work, ignore_errors=True)
    same = all(results)
    print(f"identical: {'yes' if same else 'no'} ({sum(results)} of {len(results)} comparisons)")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
