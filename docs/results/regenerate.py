"""Regenerate every results page of the study in one command (resumable: an interrupted call picks up
where it stopped; every campaign is checked against its settings on --resume).

    python docs/results/regenerate.py --runs runs/results --seed SEED          # the study (SEED: the report seed)
    python docs/results/regenerate.py --smoke --runs /tmp/smoke                # the same chain, small, on a dev seed

Runs, on the campaign seed ``--seed`` (a fresh one: never a development seed, refused):

1. the ``paper`` reading, the seven groups (the paper's five and the wait-map ablations), at
   ``--encounters`` (default 10,000);
2. every other reading of ``daa_sil/config/readings.py`` at ``--alt-encounters`` (default 2,000), and
   ``paper`` again at that size (the like-for-like column for them: its encounters are the first of
   the large run's), and ``paper`` on the development seed (the seeds' agreement);
3. the experiments (``docs/results/experiments.py``: the unmitigated encounter set and ``paper-feet``
   at ``--encounters``, the others at ``--alt-encounters``) into ``experiments.json`` / ``experiments.md``;
4. the report: the main page ``paper-study.md`` (``paper`` against the paper: tally, the basis of every
   setting, every finding, the attribution of every miss, signatures, figures) and its appendices;
5. the sensitivity sweeps under ``paper`` (``--sweep-encounters`` per point) into ``sensitivity.md``;
6. the wait-map figures of the maps the study reads: the paper grid at the ``paper`` reading's horizon
   (40 s) and the alerting grid.

Pages go to ``--docs`` (default ``docs/results``; ``--smoke``: ``RUNS/docs``, never over the
committed ones). ``--skip-sweeps`` / ``--skip-readings`` / ``--skip-experiments`` leave parts out.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from daa_sil.study.campaign.experiments import READING_GROUPS  # noqa: E402 -- after the checkout is on the path

GROUPS = ",".join(READING_GROUPS)
SWEEP_GROUPS = "B-2,ID-2,ID-2-projl"
SWEEPS = (("latency", "latency=const:0.2;const:1;const:2;const:5;const:10;gauss:5,3"),
          ("wt", "wt=2,4,8,16"), ("gamma", "gamma=0.9,0.95,0.99"), ("grid", "grid=paper,fine,alerting"),
          ("intruders", "intruders=1,2"), ("pilot", "pilot=guendel,nasa_rayleigh5"))
#: the development seed of this study's experiments and of the paper reading's second column
DEV_SEED = 424242
#: the seed of the --smoke run
SMOKE_SEED = 424243
#: seeds used while developing the models and the analysis (2718: the batch-invariance reference): never a
#: report seed
DEV_SEEDS = (0, 3, 5, 7, 8, 11, 13, 31, 99, 101, 123, 2024, 2718, 99991, 99992, 20261201, DEV_SEED, SMOKE_SEED)
#: the file in the runs directory that records the code the campaigns were simulated with
CODE_FILE = "code.json"


def _run(argv: list, what: str) -> None:
    t = time.monotonic()
    print(f"== {what}: {' '.join(argv)}", flush=True)
    subprocess.run([sys.executable, *argv], check=True, cwd=ROOT)
    print(f"   ({time.monotonic() - t:.0f} s)", flush=True)


def _campaign(out: Path, extra: list, args, encounters: int) -> Path:
    argv = ["-m", "daa_sil.cli", "campaign", "run", "--groups", GROUPS, "--encounters", str(encounters), "--out",
            str(out), "--workers", str(args.workers), "--no-progress"] + extra
    if out.is_dir() and any(out.iterdir()):
        argv.append("--resume")
    _run(argv, out.name)
    return out


def readings() -> list:
    """Every reading, ``paper`` first."""
    from daa_sil.config.readings import READINGS

    return list(READINGS)


def _git(*argv: str) -> str:
    try:
        out = subprocess.run(["git", *argv], cwd=ROOT, capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.SubprocessError):
        return ""
    return out.stdout.strip() if out.returncode == 0 else ""


def code_record(runs: Path) -> dict:
    """The code the campaigns in ``runs`` were simulated with: read from ``runs/code.json``, written there
    (the current commit, and whether the simulation code had uncommitted changes) when the first
    campaign starts; a re-render on later code keeps the record of the code that simulated."""
    f = runs / CODE_FILE
    if f.is_file():
        try:
            return json.loads(f.read_text())
        except (OSError, ValueError):
            pass
    rec = {"commit": _git("rev-parse", "HEAD") or "unknown",
           "dirty": bool(_git("status", "--porcelain", "--", "daa_sil", "vehicle", "gcs"))}
    runs.mkdir(parents=True, exist_ok=True)
    f.write_text(json.dumps(rec) + "\n")
    return rec


def _again(args) -> str:
    """The command that runs the study again (the runs directory as the reader's own)."""
    sizes = "" if (args.encounters, args.alt_encounters, args.sweep_encounters) == (10000, 2000, 1000) else (
        f" --encounters {args.encounters} --alt-encounters {args.alt_encounters} --sweep-encounters "
        f"{args.sweep_encounters}")
    return (f"python docs/results/regenerate.py --runs RUNS --seed {args.seed}{sizes}" + (" --smoke" if args.smoke
                                                                                       else ""))


def _report(args, dirs: list, experiments: "dict | None") -> None:
    from daa_sil.study.report.pages import write_report

    code = code_record(args.runs)
    commit = str(code.get("commit", "unknown"))
    sim = f"commit {commit[:10]}" + (" with uncommitted changes" if code.get("dirty") else "")
    word = "smoke seed" if args.smoke else "report seed"
    note = [f"What ran (simulated on {sim}): `paper` at {args.encounters:,} encounters per group on the {word} "
            f"{args.seed}; every other reading, and `paper` again, at {args.alt_encounters:,} (the first encounters of "
            f"the same seed); `paper` on the development seed {DEV_SEED} at {args.alt_encounters:,} (the seeds' "
            f"agreement); the experiments ([experiments.md](experiments.md)); the sweeps "
            f"([sensitivity.md](sensitivity.md)) at {args.sweep_encounters:,} per point; {args.replicates:,} bootstrap "
            f"replicates; the figures of the wait maps `paper` reads (paper grid, H = 40 s: "
            f"[histogram](waitmap/paper/histogram.png), [slices](waitmap/paper/slices_geometries.png), "
            f"[the ±5 °/s pair](waitmap/paper/mirror_pair.png), [3-D](waitmap/paper/map_3d.png); the alerting grid's "
            f"in `waitmap/alerting/`; the wait-map section's own claims are compared in "
            f"[docs/waitmap.md](../waitmap.md), not counted here). Run it again: `{_again(args)}` (RUNS: any "
            f"directory; resumable; 20 to 40 minutes on two cores). "
            + ("" if args.smoke else f"The report seed {args.seed} was chosen before any run and never used while "
               "developing; ")
            + ("T" if args.smoke else "t") + "he seeds used while developing, which regenerate.py refuses as a report "
            f"seed: {', '.join(map(str, DEV_SEEDS))}."]
    if args.smoke:
        note.insert(0, f"SMOKE RUN ({args.encounters} encounters per group): checks the chain, not the paper.")
    t = time.monotonic()
    print("== report", flush=True)
    write_report(dirs, args.docs, replicates=args.replicates, notes=note, experiments=experiments,
                 main_name="paper-study.md", all_figures=False, runs_root=args.runs)
    print(f"   ({time.monotonic() - t:.0f} s)", flush=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__.split("\n\n", 1)[1])
    ap.add_argument("--runs", type=Path, default=Path("runs/results"), help="where the campaigns go")
    ap.add_argument("--seed", type=int, default=None, help="the report seed (required; --smoke: a development seed)")
    ap.add_argument("--encounters", type=int, default=None, help="encounters per group of paper (default 10000)")
    ap.add_argument("--alt-encounters", type=int, default=None,
                    help="encounters per group of every other reading and experiment (default 2000)")
    ap.add_argument("--sweep-encounters", type=int, default=None, help="encounters per sweep point (default 1000)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--replicates", type=int, default=2000, help="bootstrap replicates of the report (default 2000)")
    ap.add_argument("--skip-sweeps", action="store_true")
    ap.add_argument("--skip-readings", action="store_true", help="no readings and no report")
    ap.add_argument("--skip-experiments", action="store_true")
    ap.add_argument("--smoke", action="store_true", help="every step at a few encounters on a development seed; "
                                                         "pages under RUNS/docs")
    ap.add_argument("--docs", type=Path, default=None, help="where the pages go (default docs/results)")
    ap.add_argument("--render-only", action="store_true",
                    help="only the report pages, from the finished campaigns in --runs and the experiments.json in "
                         "--docs (no campaign, experiment, sweep or figure run)")
    args = ap.parse_args(argv)
    if args.smoke:
        args.encounters = args.encounters or 40
        args.alt_encounters = args.alt_encounters or args.encounters
        args.sweep_encounters = args.sweep_encounters or 20
        args.seed = SMOKE_SEED if args.seed is None else args.seed
        args.docs = args.docs or args.runs / "docs"
        args.replicates = min(args.replicates, 200)
    elif args.seed is None:
        ap.error("--seed is required: the report seed, chosen before any run and never used while developing")
    elif args.seed in DEV_SEEDS:
        ap.error(f"--seed {args.seed} was used while developing; the report needs a fresh seed")
    args.encounters = args.encounters or 10000
    args.alt_encounters = args.alt_encounters or 2000
    args.sweep_encounters = args.sweep_encounters or 1000
    args.docs = args.docs or ROOT / "docs" / "results"
    for name in ("encounters", "alt_encounters", "sweep_encounters", "workers", "replicates"):
        if getattr(args, name) < 1:
            ap.error(f"--{name.replace('_', '-')} must be at least 1")
    runs = args.runs
    if args.render_only:
        return render_only(args)
    code_record(runs)  # before the first campaign: the code that simulates
    seed = ["--seed", str(args.seed)]
    experiments = None
    if not args.skip_readings:
        dirs = [_campaign(runs / "paper", ["--reading", "paper"] + seed, args, args.encounters)]
        if args.alt_encounters != args.encounters:
            dirs.append(_campaign(runs / f"paper-{args.alt_encounters}", ["--reading", "paper"] + seed, args,
                                  args.alt_encounters))
        dev = runs / f"paper-seed{DEV_SEED}"
        dirs.append(_campaign(dev, ["--reading", "paper", "--seed", str(DEV_SEED if args.seed != DEV_SEED
                                                                         else SMOKE_SEED)], args, args.alt_encounters))
        for r in readings()[1:]:
            dirs.append(_campaign(runs / r, ["--reading", r] + seed, args, args.alt_encounters))
        if not args.skip_experiments:
            _run([str(ROOT / "docs" / "results" / "experiments.py"), "--runs", str(runs), "--seed", str(args.seed),
                  "--small", str(args.alt_encounters), "--large", str(args.encounters), "--workers", str(args.workers),
                  "--out", str(args.docs)], "experiments")
            experiments = json.loads((args.docs / "experiments.json").read_text())
        _report(args, dirs, experiments)
    if not args.skip_sweeps:
        sweep_dirs = []
        for name, vary in SWEEPS:
            d = runs / f"sweep-{name}-{args.sweep_encounters}"  # one directory per size: --resume checks it
            argv = ["-m", "daa_sil.cli", "campaign", "sweep", "--vary", vary, "--groups", SWEEP_GROUPS, "--encounters",
                    str(args.sweep_encounters), "--reading", "paper", "--out", str(d), "--workers", str(args.workers),
                    "--no-progress"] + seed
            if d.is_dir() and any(d.iterdir()):
                argv.append("--resume")
            _run(argv, f"sweep {name}")
            sweep_dirs.append(d)
        _run(["-m", "daa_sil.cli", "campaign", "sweep", "--collate", *map(str, sweep_dirs), "--out", str(args.docs)],
             "sensitivity page")
    waitmap_figures(args.docs / "waitmap")
    return 0


def campaign_dirs(args) -> list:
    """The campaign directories of the report, in its column order (``paper`` first)."""
    dirs = [args.runs / "paper"]
    if args.alt_encounters != args.encounters:
        dirs.append(args.runs / f"paper-{args.alt_encounters}")
    return dirs + [args.runs / f"paper-seed{DEV_SEED}"] + [args.runs / r for r in readings()[1:]]


def render_only(args) -> int:
    """The report pages again from finished runs (``--render-only``): exit 2 naming what is missing."""
    dirs = campaign_dirs(args)
    missing = [str(d) for d in dirs if not (d / "campaign.json").is_file()]
    exp = args.docs / "experiments.json"
    if missing or not (args.runs / CODE_FILE).is_file():
        what = f"{len(missing)} campaign(s), the first {missing[0]}" if missing else str(args.runs / CODE_FILE)
        print(f"regenerate.py: --render-only needs the finished runs of a regeneration; missing: {what}",
              file=sys.stderr)
        return 2
    experiments = json.loads(exp.read_text()) if exp.is_file() else None
    _report(args, dirs, experiments)
    return 0


def waitmap_figures(out: Path) -> None:
    """The figures of the wait maps the study reads: the paper grid at the ``paper`` reading's horizon
    (its maps, from the cache its campaigns filled) and the alerting grid of ``paper-alerting``."""
    from daa_sil.config.readings import READINGS
    from daa_sil.waitmap import family_for
    from daa_sil.waitmap.plots import write_plots

    for grid, horizon in (("paper", READINGS["paper"].wait_horizon_s), ("alerting", None)):
        t = time.monotonic()
        print(f"== wait-map figures ({grid}, H = {f'{horizon:g} s' if horizon else 'the preset default'})",
              flush=True)
        for f in write_plots(family_for(grid, horizon=horizon), out / grid, overwrite=True):
            print(f"   {f}", flush=True)
        print(f"   ({time.monotonic() - t:.0f} s)", flush=True)


if __name__ == "__main__":
    sys.exit(main())
