"""Benchmark the fast-time campaign: wall time and peak memory, against a baseline commit in the same run.

Usage::

    python benchmarks/bench_campaign.py                                  # the figure: 10,000 x 5 groups x 240 s, 2 workers
    python benchmarks/bench_campaign.py --scaling 1000,2000,5000,10000 --intruders 1,2   # the scaling table
    python benchmarks/bench_campaign.py --encounters 1000 --no-baseline  # a quick look at this code alone

Every campaign runs as ``daa-sil campaign run`` in a subprocess (``--reading literal``, pinned: a
benchmark must not change what it measures when a default moves), reading its wall time and the
peak RSS of its largest process (driver or worker; ``wait4``). The baseline is a commit (``/work/baseline``)
installed apart (``--baseline-python``, default ``/work/baseline/.venv/bin/python``, with its own
cache ``--baseline-cache``), run on the same configuration in the same run, alternating with this
code so both see the same machine load; the 1-minute load average is printed with every figure.
Target: 10,000 x 5 groups <= 15 s on 2 workers; peak memory <= 1 GiB per
worker. Results of both runs are compared (``identical: yes`` when the baseline ran).
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

from baseline_paths import BASELINE_CACHE, BASELINE_PYTHON  # noqa: E402
GROUPS = "B-1,B-2,IC-1,ID-1,ID-2"


def _load() -> float:
    return os.getloadavg()[0]


def run_campaign(python: str, out: Path, n: int, m: int, groups: str, workers: int, seed: int, env: dict,
                 extra: "list[str] | None" = None) -> tuple[float, float, tuple[float, float], float]:
    """One ``campaign run`` subprocess: (wall s, peak RSS MiB of its largest process, load before/after,
    CPU s of it and its workers (user + system, ``wait4``))."""
    cmd = [python, "-m", "daa_sil.cli", "campaign", "run", "--groups", groups, "--encounters", str(n),
           "--intruders", str(m), "--seed", str(seed), "--reading", "literal", "--workers", str(workers),
           "--out", str(out), "--no-progress", *(extra or [])]
    load0 = _load()
    t0 = time.perf_counter()
    # cwd outside any checkout: each python imports its own installed daa_sil
    proc = subprocess.Popen(cmd, cwd=tempfile.gettempdir(), env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    err = proc.stderr.read().decode(errors="replace")
    if proc.returncode != 0:
        raise SystemExit(f"bench_campaign: {' '.join(cmd)} failed ({proc.returncode}): {err.strip()[-2000:]}")
    return wall, usage.ru_maxrss / 1024.0, (load0, _load()), usage.ru_utime + usage.ru_stime


def _warm(python: str, env: dict, m: int) -> None:
    """Load (or build) the wait maps and import everything once, outside the clock."""
    with tempfile.TemporaryDirectory(prefix="bench-campaign-warm-") as tmp:
        run_campaign(python, Path(tmp) / "w", 1, m, "ID-2", 1, 1, env, ["--duration", "20"])


def _identical(a: Path, b: Path) -> str:
    from daa_sil.study.campaign.compare import compare_dirs

    res = compare_dirs(a, b)
    return "yes" if res.identical else f"NO ({len(res.differences)} differences: {res.differences[0]})"


def measure(n: int, m: int, args, env_new: dict, env_base: "dict | None") -> dict:
    """This code (and the baseline, alternating) on one configuration; returns the figures."""
    out = {}
    with tempfile.TemporaryDirectory(prefix="bench-campaign-") as tmp:
        tmp = Path(tmp)
        for rep in range(args.repeat):
            order = [("new", sys.executable, env_new)] + ([("base", args.baseline_python, env_base)] if env_base else [])
            if rep % 2:
                order.reverse()
            for name, py, env in order:
                d = tmp / f"{name}-{rep}"
                wall, rss, load, cpu = run_campaign(str(py), d, n, m, args.groups, args.workers, args.seed, env)
                best = out.get(name)
                if best is None or wall < best["wall"]:
                    out[name] = {"wall": wall, "rss": rss, "load": load, "cpu": cpu, "dir": d}
                elif d.exists():
                    shutil.rmtree(d)
        if "base" in out:
            out["identical"] = _identical(out["base"]["dir"], out["new"]["dir"])
    return out


def _fmt(r: dict) -> str:
    return (f"{r['wall']:.1f} s (CPU {r['cpu']:.1f} s), peak RSS {r['rss']:.0f} MiB "
            f"(load {r['load'][0]:.1f}->{r['load'][1]:.1f})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0], epilog=__doc__.split("Usage::")[1],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--encounters", type=int, default=10_000, help="encounters per group of the figure (default 10000)")
    ap.add_argument("--groups", default=GROUPS, help=f"groups (default {GROUPS}, the paper's five)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--intruders", default="1", help="intruders per encounter, comma-separated (default 1)")
    ap.add_argument("--scaling", default=None, metavar="N1,N2,...",
                    help="instead of the figure: a table of wall time and peak RSS at these encounter counts")
    ap.add_argument("--repeat", type=int, default=1, help="runs per configuration and code, best kept (default 1)")
    ap.add_argument("--baseline-python", type=Path, default=BASELINE_PYTHON,
                    help=f"python of the baseline commit installed apart (default {BASELINE_PYTHON})")
    ap.add_argument("--baseline-cache", type=Path, default=BASELINE_CACHE,
                    help=f"DAA_SIL_CACHE of the baseline (default {BASELINE_CACHE})")
    ap.add_argument("--no-baseline", action="store_true", help="measure this code only")
    ap.add_argument("--baseline-label", default="baseline", help="what the baseline python runs (printed)")
    args = ap.parse_args()
    intruders = [int(x) for x in args.intruders.split(",")]
    sizes = [int(x) for x in args.scaling.split(",")] if args.scaling else [args.encounters]

    env_new = dict(os.environ, PYTHONPATH=str(ROOT))
    env_base = None
    if not args.no_baseline and args.baseline_python == BASELINE_PYTHON and not BASELINE_PYTHON.is_file():
        print(f"bench_campaign: no baseline at {BASELINE_PYTHON}: this code only, no ratio "
              f"(--baseline-python PY to compare; CONTRIBUTING.md says how to install a baseline apart)")
        args.no_baseline = True
    if not args.no_baseline:
        if not args.baseline_python.is_file():
            raise SystemExit(f"bench_campaign: no baseline python at {args.baseline_python} "
                             f"(install a baseline apart, pass --baseline-python, or --no-baseline)")
        env_base = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
        env_base["DAA_SIL_CACHE"] = str(args.baseline_cache)
    print(f"[load] 1-minute load average {_load():.2f} on {os.cpu_count()} cores; reading literal; "
          f"groups {args.groups}; {args.workers} workers")
    for m in intruders:
        _warm(sys.executable, env_new, m)
        if env_base:
            _warm(str(args.baseline_python), env_base, m)
    n_groups = len(args.groups.split(","))
    for m in intruders:
        for n in sizes:
            r = measure(n, m, args, env_new, env_base)
            new = r["new"]
            steps = n * n_groups * 240
            line = (f"{n_groups} groups x {n} encounters x 240 s, {m} intruder{'s' if m > 1 else ''}: "
                    f"{_fmt(new)}, {steps / new['wall']:,.0f} encounter-steps/s")
            if "base" in r:
                line += (f"; {args.baseline_label} same run {_fmt(r['base'])}: ratio x{r['base']['wall'] / new['wall']:.2f} "
                         f"wall, x{r['base']['cpu'] / new['cpu']:.2f} CPU (identical: {r['identical']})")
            tag = "[campaign]" if not args.scaling else "[scaling]"
            target = "; target 15 s, <= 1 GiB per worker" if not args.scaling else ""
            print(f"{tag} {line}{target}", flush=True)


if __name__ == "__main__":
    main()
