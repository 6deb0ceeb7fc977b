"""SIL benchmarks: lockstep speed, and realtime timing and parity under load.

**Lockstep** (``--part lockstep``): a 240 s head-on encounter through three processes (vehicle,
shim, GCS), ``daa-sil run`` started as a fresh process and timed from its start to its exit.
Measured in the same run, interleaved, for this checkout and a baseline checkout (``--baseline``,
default bba2fd8 installed apart in /work/baseline with its own venv and ``DAA_SIL_CACHE``), each
**with and without .pyc** (copies of the packages, compiled or not: see ``sil_probe.py``).
Prints per configuration the best and median wall time, the ratio to the baseline, start-up to
READY of each process (wall s after the run started, and its CPU s by then), CPU per step of the
vehicle, the GCS and the shim, the wall time per lockstep step, and the load average around each
run; with two repeats or more, the median of the paired differences (this checkout minus the baseline
run just before or after it) and in how many pairs this checkout was lower, which resolves a change
of a tenth of a second that the machine's drift hides in best and median figures (20 alternated
pairs did).
Every run's step log must be identical to the baseline's (``daa_sil.steplog.cells_equal``).
Then the in-process figure: the vehicle's core alone (``VehicleCore`` built and flown for every
step, no link, no processes) and its telemetry cost per step, for both checkouts.
Targets (issue 21): <= 2.0 s wall with .pyc; in-process <= 1.0 s; at N = 1 the vehicle's step
<= 1.5 ms and the GCS's <= 1 ms of CPU.

**Realtime** (``--part realtime``): ``N`` (default 20) concurrent ``daa-sil run --clock realtime``
encounters of the head-on scenario at each ``--speeds`` factor (default 1 and 4), after one run
alone at that speed (the baseline). Per run it reads ``result.json`` and the step log and prints
how late the vehicle's steps went out after their deadlines (mean / p99 / max ms; target: every
step within 50 ms), the shim's release lateness against the tick schedule (p99 ms: the "delay
error"; <= 2 ms is the target for a single run on a quiet machine), whether the run says it kept
lockstep semantics, and whether its step log is **identical** to the lockstep run's (decisions,
their times, minimum range). It prints the machine's load average while the runs played, and the
ratio of the loaded figures to the alone run.

    python benchmarks/bench_sil.py [--part lockstep|realtime|all] [--repeat 3] [--pyc both|present|absent]
    python benchmarks/bench_sil.py --baseline none          # this checkout only
    git worktree add /tmp/start HEAD~3                      # an A/B against an earlier commit, paired:
    python benchmarks/bench_sil.py --pyc present --repeat 20 --baseline /tmp/start \\
        --baseline-python .venv/bin/python --baseline-cache ~/.cache/daa-sil
    python benchmarks/bench_sil.py --part realtime --runs 20 --speeds 1,4 [--duration 180]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))

from baseline_paths import BASELINE_CACHE, BASELINE_DIR  # noqa: E402

TARGET_S, TARGET_INPROC_S, TARGET_VEHICLE_MS, TARGET_GCS_MS = 2.0, 1.0, 1.5, 1.0
DEFAULT_BASELINE = str(BASELINE_DIR)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0], epilog=__doc__.split("\n\n", 1)[1],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeat", type=int, default=3, help="lockstep: interleaved repeats of each configuration (default 3)")
    ap.add_argument("--scenario", type=Path, default=ROOT / "scenarios" / "head_on.yaml",
                    help="scenario YAML (default scenarios/head_on.yaml; lockstep stretches it to 240 s)")
    ap.add_argument("--part", choices=("lockstep", "realtime", "all"), default="lockstep",
                    help="what to measure (default lockstep)")
    ap.add_argument("--pyc", choices=("both", "present", "absent"), default="both",
                    help="lockstep: measure with the project's .pyc present, absent or both (default)")
    ap.add_argument("--baseline", default=DEFAULT_BASELINE,
                    help=f"lockstep: checkout of the baseline with its .venv (default {DEFAULT_BASELINE}, bba2fd8 "
                         f"installed apart, if it exists); none = this checkout only")
    ap.add_argument("--baseline-cache", default=str(BASELINE_CACHE),
                    help=f"lockstep: DAA_SIL_CACHE of the baseline (default {BASELINE_CACHE})")
    ap.add_argument("--baseline-python", default=None,
                    help="lockstep: the baseline's interpreter (default DIR/.venv/bin/python); e.g. this checkout's "
                         "own .venv/bin/python to compare with an earlier commit's sources (a git worktree)")
    ap.add_argument("--runs", type=int, default=20, help="realtime: concurrent runs (default 20)")
    ap.add_argument("--speeds", default="1,4", help="realtime: speed factors, comma-separated (default 1,4)")
    ap.add_argument("--duration", type=float, default=None, help="realtime: sim s per run (default: the scenario's)")
    ap.add_argument("--stagger", type=float, default=0.5, help="realtime: wall s between launches (default 0.5)")
    ap.add_argument("--keep", type=Path, default=None, help="keep the run directories here")
    ap.add_argument("--ab-slice", action="store_true",
                    help="realtime: every other concurrent run's vehicle without the short EEVDF slice "
                         "(DAA_SIL_VEHICLE_SLICE_US=0), and compare the two halves")
    args = ap.parse_args()
    from sil_realtime import bench_realtime  # (benchmarks/ is on sys.path, above)

    if args.part == "realtime":
        return bench_realtime(args)
    bench_lockstep(args)
    if args.part == "all":
        bench_realtime(args)


# ------------------------------------------------------------------------------------------------
# lockstep: this checkout against the baseline, with and without .pyc

#: the figures compared run by run (new - baseline of the same repeat: the two ran back to back)
PAIRED = (("wall", "wall s"), ("ready_vehicle", "vehicle READY s"), ("ready_cpu_vehicle", "vehicle CPU to READY s"),
          ("ready_cpu_gcs", "GCS CPU to READY s"), ("step_ms_vehicle", "vehicle CPU ms a step"),
          ("step_ms_gcs", "GCS CPU ms a step"), ("step_ms_shim", "shim CPU ms a step"))


def _paired(new: list, base: list, pyc: bool) -> None:
    """Print the median of the paired differences (new - baseline, repeat by repeat) of :data:`PAIRED`, and in how
    many pairs the new code was lower: on a machine whose speed drifts, the pairs resolve what best and median
    figures do not."""
    import sil_probe as P

    parts = []
    for key, label in PAIRED:
        d = [a[key] - b[key] for a, b in zip(new, base) if a.get(key) is not None and b.get(key) is not None]
        if d:
            parts.append(f"{label} {P.median(d):+.3f} (lower in {sum(x < 0 for x in d)}/{len(d)})")
    print(f"  => paired, new - base, median over {len(new)} back-to-back repeats ({'with' if pyc else 'no'} .pyc): "
          + "; ".join(parts))


def _f(x, fmt=".2f") -> str:
    return "-" if x is None else format(x, fmt)


def _label(k) -> str:
    return f"{k[0]} {'with' if k[1] else 'no'} .pyc"


def _ratio(a, b) -> str:
    return "-" if a is None or not b else f"{a / b:.2f}x"


def bench_lockstep(args) -> None:
    import yaml

    import sil_probe as P
    from daa_sil.sil.scenario import load_scenario, scenario_from_dict
    from daa_sil.steplog import cells_equal, read_steplog

    sc = load_scenario(args.scenario)
    d = sc.to_dict()
    d["duration_s"] = 240.0
    n_steps = scenario_from_dict(d).n_steps
    tmp = tempfile.TemporaryDirectory(prefix="bench_sil_")
    base = args.keep or Path(tmp.name)
    base.mkdir(parents=True, exist_ok=True)
    path = base / "bench.yaml"
    path.write_text(yaml.safe_dump(d, sort_keys=False))
    probe = P.write_probe(base / "probe")
    checkouts = {"new": (ROOT, sys.executable, os.environ.get("DAA_SIL_CACHE"))}
    bpy = Path(args.baseline_python).absolute() if args.baseline_python else Path(args.baseline) / ".venv" / "bin" / "python"
    if args.baseline == DEFAULT_BASELINE and not bpy.is_file():
        print(f"bench_sil: no baseline at {DEFAULT_BASELINE}: this checkout only (--baseline DIR to compare)")
        args.baseline = "none"
    if args.baseline != "none":
        if not bpy.is_file():
            sys.exit(f"bench_sil: no baseline interpreter {bpy} (give --baseline DIR or --baseline none)")
        checkouts["base"] = (Path(args.baseline), str(bpy), args.baseline_cache)
    pycs = {"both": (True, False), "present": (True,), "absent": (False,)}[args.pyc]
    configs = [(c, pyc) for pyc in pycs for c in checkouts]
    trees = {}
    for c, pyc in configs:
        root, py, _ = checkouts[c]
        trees[c, pyc] = P.prepare_tree(root, base / f"{c}-{'pyc' if pyc else 'nopyc'}", py, compiled=pyc)
    print(f"lockstep SIL, 240 s encounter ({sc.name}), 3 processes, `daa-sil run` as a fresh process; "
          f"{os.cpu_count()} CPUs; load average before: {', '.join(f'{x:.2f}' for x in os.getloadavg())}")
    print(f"  new = {ROOT}; base = {checkouts['base'][0] if 'base' in checkouts else '(none)'}; "
          f"{args.repeat} interleaved repeats of {len(configs)} configurations")
    # one warm-up run per tree (page cache, wait-map cache present, and the copy's compiled kernels: numba
    # files them under each copy's path, so every copy compiles once)
    for c, pyc in configs:
        root, py, cache = checkouts[c]
        P.run_probed(py, trees[c, pyc], probe, path, base / f"warm-{c}-{'pyc' if pyc else 'nopyc'}", cache)
    res = {k: [] for k in configs}
    for i in range(args.repeat):
        for c, pyc in configs:
            root, py, cache = checkouts[c]
            out = base / f"{c}-{'pyc' if pyc else 'nopyc'}-run{i}"
            l0 = P.load()
            run = P.run_probed(py, trees[c, pyc], probe, path, out, cache)
            if run["rc"] not in (0, 1):
                sys.exit(f"bench_sil: {c} run failed (exit {run['rc']}): {run['stderr']}")
            fig = P.figures(run, n_steps)
            fig["load"] = max(l0, P.load())
            bad = [m for m in fig["modules"].values() if m and not str(m).startswith(str(trees[c, pyc]))]
            if bad:
                sys.exit(f"bench_sil: a {c} process imported daa_sil from {bad[0]}, not the copy under test")
            fig["rows"] = read_steplog(out / "steplog.parquet").to_pylist()
            res[c, pyc].append(fig)
    # identity: every run's step log against the baseline's first one (or the first run without a baseline)
    ref = (res.get(("base", pycs[0])) or res[configs[0]])[0]["rows"]
    diff = {k: sum(1 for f in v for ra, rb in zip(ref, f["rows"]) for col in ra if not cells_equal(ra[col], rb[col]))
            + sum(abs(len(f["rows"]) - len(ref)) for f in v) for k, v in res.items()}
    print("\n  configuration      wall best / median (s)  vs base   load    READY (s after start; CPU s): "
          "vehicle / gcs / shim      CPU per step (ms): vehicle / gcs / shim   wall per step (ms)")
    best = {k: min(f["wall"] for f in v) for k, v in res.items()}
    for k in configs:
        v = res[k]
        med = {key: P.median([f[key] for f in v]) for key in v[0] if key not in ("modules", "rows")}
        b = ("base", k[1])
        vs = _ratio(best[k], best.get(b)) if k[0] != "base" and b in res else ""
        print(f"  {k[0]:4s} {'with' if k[1] else 'no':4s} .pyc    {best[k]:6.2f} / {med['wall']:6.2f}         "
              f"{vs:7s}  {_f(med['load'], '.1f'):>4s}    "
              f"{_f(med['ready_vehicle'])} ({_f(med['ready_cpu_vehicle'])}) / {_f(med['ready_gcs'])} "
              f"({_f(med['ready_cpu_gcs'])}) / {_f(med['ready_shim'])} ({_f(med['ready_cpu_shim'])})      "
              f"{_f(med['step_ms_vehicle'])} / {_f(med['step_ms_gcs'])} / {_f(med['step_ms_shim'])}"
              f"              {_f(med['play_ms_per_step'])}")
    for pyc in pycs:
        vs = (f" vs baseline {best['base', pyc]:.2f} s in the same run: ratio {best['new', pyc] / best['base', pyc]:.2f}"
              if ("base", pyc) in best else " (no baseline)")
        print(f"  => {'with' if pyc else 'without'} .pyc: {best['new', pyc]:.2f} s{vs}"
              + (f" (target <= {TARGET_S:g} s: {'met' if best['new', pyc] <= TARGET_S else 'NOT met'})" if pyc else ""))
    for pyc in pycs:
        if ("base", pyc) in res and args.repeat >= 2:
            _paired(res["new", pyc], res["base", pyc], pyc)
    print(f"  => step logs identical to the baseline's: {'yes' if not any(diff.values()) else 'NO'} "
          f"({', '.join(f'{_label(k)}: {n} cells differ' for k, n in diff.items())})")
    # in-process: the vehicle's core alone
    print("\n  in-process (VehicleCore built + every step, no link, no processes; best of "
          f"{args.repeat}):")
    inp = {}
    for c in checkouts:
        root, py, cache = checkouts[c]
        runs = []
        for _ in range(args.repeat):
            l0 = P.load()
            r = P.in_process(py, trees[c, pycs[0]], probe, path, cache)
            r["load"] = max(l0, P.load())
            runs.append(r)
        inp[c] = min(runs, key=lambda r: r["wall"])
        r = inp[c]
        print(f"  {c:4s}: {r['wall']:.2f} s (build {r['build_wall']:.2f} s, steps {r['step_ms']:.2f} ms CPU each; "
              f"telemetry {r['telemetry_ms']:.2f} ms a step; load {r['load']:.1f})")
    if "base" in inp:
        print(f"  => in-process {inp['new']['wall']:.2f} s vs baseline {inp['base']['wall']:.2f} s: ratio "
              f"{inp['new']['wall'] / inp['base']['wall']:.2f} (target <= {TARGET_INPROC_S:g} s: "
              f"{'met' if inp['new']['wall'] <= TARGET_INPROC_S else 'NOT met'})")
    k = ("new", pycs[0])
    vm = P.median([f["step_ms_vehicle"] for f in res[k]])
    gm = P.median([f["step_ms_gcs"] for f in res[k]])
    print(f"  => per-step CPU in the SIL (median, {'with' if k[1] else 'no'} .pyc): vehicle {_f(vm)} ms (target <= "
          f"{TARGET_VEHICLE_MS:g}), GCS {_f(gm)} ms (target <= {TARGET_GCS_MS:g}); load average after: "
          f"{', '.join(f'{x:.2f}' for x in os.getloadavg())}")
    tmp.cleanup()


if __name__ == "__main__":
    main()
