"""Benchmark: DAA bands + one agent step for N encounters x 1 intruder in one batched call,
versus the same code called one encounter at a time and versus a baseline commit (ratios measured
in the same run).

    python benchmarks/bench_daa.py [--n 10000] [--loop 200] [--repeat 5] [--preset do365|paper|daidalus]
                                   [--baseline DIR] [--startup]

Encounters: ownship 55 m/s at the origin, one intruder 3-8 km away, converging at random angles
(mostly alerting), with a random pilot command arriving in half of them. The preset is pinned
(``do365`` unless ``--preset``) and printed; no simulation reading is involved (bands and the agent
step are called directly, which no reading changes). The target (>= 100,000 encounter-steps/s of
CPU time on one core, stretch 150,000) is for ``do365``; ``--preset daidalus`` (1 deg / 5 kt / 100 fpm grids, about 2.7x the
candidates, cylinder recovery, hysteresis) is reported, not held to it.

``--baseline DIR`` (default ``/work/baseline`` when it is there; ``none``: no baseline): a checkout of the
baseline commit with its own ``DIR/.venv``; its
own ``benchmarks/bench_daa.py`` runs in a subprocess with the same arguments right after this
one, and the ratio of the two figures is printed. ``--startup``: also measure the start of a fresh
process (import + first ``compute_bands``) with an empty compiled-kernel cache (cold) and with the
cache this run filled (warm). Every figure is printed with the machine's load average.
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from daa_sil.agent.memory import AgentMemory, PilotInput
from daa_sil.agent.wait_function import WaitValue
from daa_sil.agent.step import agent_step
from daa_sil.config.groups import policy_for_group
from daa_sil.daa import DaaConfig, compute_bands
from daa_sil.geometry.kinematics import AircraftState, Command

sys.path.insert(0, str(Path(__file__).resolve().parent))
from baseline_paths import BASELINE_DIR  # noqa: E402


def make_batch(n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    own = AircraftState(np.zeros(n), np.zeros(n), np.full(n, 1000.0), np.full(n, 55.0), np.zeros(n),
                        np.zeros(n))
    rng_m = rng.uniform(3000, 8000, n)
    bearing = rng.uniform(-0.6, 0.6, n)
    ix, iy = rng_m * np.sin(bearing), rng_m * np.cos(bearing)
    trk = np.pi + bearing + rng.normal(0, 0.2, n)
    intr = AircraftState(ix[:, None], iy[:, None], 1000.0 + rng.uniform(-150, 150, (n, 1)),
                         rng.uniform(50, 150, (n, 1)), trk[:, None], rng.uniform(-5, 5, (n, 1)))
    cmd = Command(rng.uniform(-0.8, 0.8, n) % (2 * np.pi), np.where(rng.random(n) < 0.3, rng.uniform(-10, 10, n), 0.0),
                  np.full(n, 55.0))
    pilot = PilotInput(rng.random(n) < 0.5, cmd, np.full(n, 5.0), np.full(n, 10.0), np.full(n, 10.0))
    return own, intr, pilot


def step(own, intr, pilot, cfg, policy, lookup):
    n = own.shape[0]
    bands = compute_bands(own, intr, cfg)
    mem = AgentMemory.initial(n, own)
    return agent_step(10.0, own, intr, pilot, mem, policy, cfg, lookup, bands=bands)


def sub_pilot(p: PilotInput, i: slice) -> PilotInput:
    return PilotInput(p.received[i], p.cmd[i], p.t_sent[i], p.t_recv[i], p.link_alive_t[i])


def load() -> str:
    """The machine's 1-minute load average, for the record next to each figure."""
    return f"load {os.getloadavg()[0]:.1f}"


def run_baseline(root: Path, args) -> "tuple[float, float] | None":
    """(wall, CPU) encounter-steps/s of the baseline checkout's own bench_daa.py, or None."""
    py = root / ".venv" / "bin" / "python"
    script = root / "benchmarks" / "bench_daa.py"
    if not py.exists() or not script.exists():
        print(f"baseline: {py} or {script} missing; no ratio")
        return None
    cmd = [str(py), str(script), "--n", str(args.n), "--loop", str(args.loop), "--repeat", str(args.repeat),
           "--preset", args.preset]
    # without PYTHONPATH: a checkout's code on it (as a worktree is run) would otherwise be imported by the
    # baseline's python too, and the "baseline" would measure this code (bench_campaign.py does the same)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    res = subprocess.run(cmd, capture_output=True, text=True, cwd=root, env=env)
    wall = re.search(r"= ([\d,]+) encounter-steps/s", res.stdout)
    cpu = re.search(r"CPU time: batched ([\d,]+) encounter-steps/s", res.stdout)
    if res.returncode != 0 or not wall or not cpu:
        print(f"baseline run failed (exit {res.returncode}): {(res.stdout + res.stderr)[-500:]}")
        return None
    print(f"baseline {root}: {res.stdout.splitlines()[0]}  [{load()}]")
    return float(wall.group(1).replace(",", "")), float(cpu.group(1).replace(",", ""))


STARTUP = """
import time, numpy as np
t0 = time.perf_counter()
from daa_sil.daa import DaaConfig, compute_bands
from daa_sil.geometry.kinematics import AircraftState
t1 = time.perf_counter()
own = AircraftState(*(np.array([v]) for v in (0.0, 0.0, 1000.0, 55.0, 0.0, 0.0)))
intr = AircraftState(*(np.array([[v]]) for v in (0.0, 6000.0, 1000.0, 55.0, np.pi, 0.0)))
compute_bands(own, intr, DaaConfig.for_preset("{preset}"))
t2 = time.perf_counter()
print(f"{{t1 - t0:.3f}} {{t2 - t1:.3f}}")
"""


def startup(preset: str, baseline: "Path | None") -> None:
    """Start of a fresh process: import + first compute_bands, cold (empty kernel cache) and warm (and the
    baseline checkout's, which compiles nothing)."""
    code = STARTUP.format(preset=preset)

    def once(env, python=sys.executable, cwd=None):
        t = time.perf_counter()
        out = subprocess.run([python, "-c", code], env=env, capture_output=True, text=True, check=True,
                             cwd=cwd).stdout
        imp, first = (float(x) for x in out.split())
        return time.perf_counter() - t, imp, first

    def show(label, total, imp, first):
        print(f"start-up {label}: process {total:.2f} s = import {imp:.2f} s + first compute_bands "
              f"{first:.2f} s + interpreter  [{load()}]")

    with tempfile.TemporaryDirectory() as d:
        env = dict(os.environ, NUMBA_CACHE_DIR=d)
        for label in ("cold (empty kernel cache)", "warm (cache filled by the cold run)"):
            show(label, *once(env))
    if baseline is not None and (baseline / ".venv" / "bin" / "python").exists():
        show("baseline", *once(dict(os.environ), str(baseline / ".venv" / "bin" / "python"), baseline))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=10000, help="encounters in the batched call")
    ap.add_argument("--loop", type=int, default=200, help="encounters timed one at a time")
    ap.add_argument("--repeat", type=int, default=5, help="timed batched calls (median reported)")
    ap.add_argument("--preset", default="do365", help="DAA preset (default do365)")
    ap.add_argument("--baseline", default=None,
                    help="checkout of the baseline commit with its own .venv (its bench_daa.py is run for the ratio; "
                         f"default {BASELINE_DIR} when it is there, 'none': no baseline)")
    ap.add_argument("--startup", action="store_true", help="also measure a fresh process's start, cold and warm")
    args = ap.parse_args()
    cfg = DaaConfig.for_preset(args.preset)
    policy = policy_for_group("ID-2")
    lookup = lambda o, i, rate: WaitValue.constant(o.shape[0], 6.0)  # noqa: E731  (a 6 s wait everywhere)
    own, intr, pilot = make_batch(args.n)
    # warm-up at full size: the first call pays the first-touch page faults of its working arrays;
    # the fast-time loop calls this every step, so the steady state is the relevant figure
    _, dec, _ = step(own, intr, pilot, cfg, policy, lookup)
    walls, cpus = [], []
    for _ in range(args.repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        step(own, intr, pilot, cfg, policy, lookup)
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    t_batch, c_batch = statistics.median(walls), statistics.median(cpus)
    rate_batch = args.n / t_batch
    t0, c0 = time.perf_counter(), time.process_time()
    for i in range(args.loop):
        s = slice(i, i + 1)
        step(own[s], intr[s], sub_pilot(pilot, s), cfg, policy, lookup)
    t_loop, c_loop = time.perf_counter() - t0, time.process_time() - c0
    rate_loop = args.loop / t_loop
    active = dec["active"].mean()
    print(f"preset {args.preset}; batched: {args.n} encounters x 1 intruder, median of {args.repeat} calls {t_batch:.3f} s "
          f"(min {min(walls):.3f}, max {max(walls):.3f}) = {rate_batch:,.0f} encounter-steps/s ({active:.0%} active)"
          f"  [{load()}]")
    print(f"one at a time: {args.loop} encounters in {t_loop:.3f} s = {rate_loop:,.0f} encounter-steps/s")
    print(f"speed-up batched / one-at-a-time: {rate_batch / rate_loop:.1f}x (wall clock)")
    print(f"CPU time: batched {args.n / c_batch:,.0f} encounter-steps/s, one at a time {args.loop / c_loop:,.0f}/s, "
          f"ratio {(args.n / c_batch) / (args.loop / c_loop):.1f}x  (target for do365: >= 100,000/s)")
    if args.baseline is None:  # (the default: the baseline installed apart, when it is there)
        args.baseline = BASELINE_DIR if (BASELINE_DIR / ".venv").is_dir() else "none"
        if args.baseline == "none":
            print(f"no baseline at {BASELINE_DIR}: this code alone (--baseline DIR to compare)")
    args.baseline = None if str(args.baseline) == "none" else Path(args.baseline)
    if args.baseline is not None:
        base = run_baseline(args.baseline, args)
        if base is not None:
            print(f"this / baseline: {rate_batch / base[0]:.2f}x wall ({rate_batch:,.0f} vs {base[0]:,.0f}/s), "
                  f"{(args.n / c_batch) / base[1]:.2f}x CPU ({args.n / c_batch:,.0f} vs {base[1]:,.0f}/s)  [{load()}]")
    if args.startup:
        startup(args.preset, args.baseline)


if __name__ == "__main__":
    main()
