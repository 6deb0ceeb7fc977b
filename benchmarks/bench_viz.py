"""Benchmark the Rerun logging overhead against the run it visualises.

Usage::

    python benchmarks/bench_viz.py                              # scenarios/head_on.yaml, 5 runs each
    python benchmarks/bench_viz.py --scenario scenarios/crossing_left.yaml --repeat 3

Prints, all measured in this run:

1. **Lockstep SIL**: wall time of ``daa-sil run SCENARIO`` without and with ``--rrd`` (interleaved,
   median of ``--repeat``), the ratio and the .rrd size. Target: overhead <= 10 %. ``daa-sil run``
   logs the step log after the run, so the fixed part of its overhead is importing rerun and its
   interpreter shutdown, measured separately in fresh interpreters.
2. **Live logging cost** on the same step log: the time the control loop spends inside
   ``EncounterLogger.log_step`` (per step, it only queues the row) and the background thread's total
   (until ``close()``), each as a fraction of the SIL run's wall time.
3. **Fast-time**: one encounter simulated by ``daa_sil.fasttime.simulate(record_steps=True)``
   against ``log_steplog`` of its step log (the batch path, ``send_columns``).
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _sil_run(scenario: Path, out: Path, rrd: "Path | None") -> float:
    cmd = [sys.executable, "-m", "daa_sil.cli", "run", str(scenario), "--out", str(out), "--json"]
    if rrd is not None:
        cmd += ["--rrd", str(rrd)]
    t0 = time.perf_counter()
    res = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if res.returncode not in (0, 1) or not (out / "steplog.parquet").exists():
        raise SystemExit(f"bench_viz: daa-sil run failed ({res.returncode}): {res.stderr.strip()[-300:]}")
    return wall


def bench_sil(scenario: Path, repeat: int, tmp: Path) -> tuple[float, Path]:
    plain, with_rrd = [], []
    rrd = None
    for k in range(repeat):
        plain.append(_sil_run(scenario, tmp / f"plain{k}", None))
        rrd = tmp / f"rrd{k}" / "enc.rrd"
        rrd.parent.mkdir()
        with_rrd.append(_sil_run(scenario, tmp / f"rrd{k}", rrd))
    a, b = statistics.median(plain), statistics.median(with_rrd)
    imp = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-c", "import numpy, pyarrow"], check=True)
        t1 = time.perf_counter()
        subprocess.run([sys.executable, "-c", "import numpy, pyarrow, rerun.blueprint"], check=True)
        imp.append((time.perf_counter() - t1) - (t1 - t0))
    c = statistics.median(imp)

    def runs(xs):
        return ", ".join(f"{x:.2f}" for x in xs)

    print(f"[1] lockstep SIL {scenario.name}, median wall of {repeat} runs (interleaved):\n"
          f"    without --rrd        {a:.2f} s  ({runs(plain)})\n"
          f"    with --rrd           {b:.2f} s  ({runs(with_rrd)})  ratio {b / a:.3f} ({100 * (b / a - 1):+.1f} %)\n"
          f"    of which importing rerun + its interpreter shutdown (fresh process): {c:.2f} s "
          f"({100 * c / a:.1f} % of the plain run)\n"
          f"    .rrd {rrd.stat().st_size / 1000:.0f} kB")
    return a, tmp / "plain0" / "steplog.parquet"


def bench_live(steplog_path: Path, sil_wall: float, tmp: Path) -> None:
    from daa_sil import steplog, viz

    table = steplog.read_steplog(steplog_path)
    rows = table.to_pylist()
    logger = viz.EncounterLogger(viz.SinkOptions(rrd=tmp / "live.rrd"), encounter_id=0)
    in_call = 0.0
    t0 = time.perf_counter()
    for r in rows:
        t1 = time.perf_counter()
        logger.log_step(r)
        in_call += time.perf_counter() - t1
    t_close = time.perf_counter()
    logger.close()
    total = time.perf_counter() - t0
    print(f"[2] live EncounterLogger on {len(rows)} steps: {1e6 * in_call / len(rows):.1f} us per log_step call "
          f"({100 * in_call / sil_wall:.2f} % of the SIL wall time), background thread + close {total:.3f} s "
          f"({100 * total / sil_wall:.1f} %; close alone {time.perf_counter() - t_close:.3f} s)")


def bench_fasttime(tmp: Path) -> None:
    from daa_sil import campaign, viz
    from daa_sil.encounters import sample_encounters
    from daa_sil.fasttime import simulate

    es = sample_encounters(1, seed=3)
    spec = campaign.paper_groups()["B-1"]
    model = spec.delay_model()
    simulate(es, spec.policy(), model, model, preset="paper", record_steps=True)  # warm-up (imports, caches)
    t0 = time.perf_counter()
    _, _, steps = simulate(es, spec.policy(), model, model, preset="paper", record_steps=True)
    t_sim = time.perf_counter() - t0
    viz.log_steplog(steps, viz.SinkOptions(rrd=tmp / "warm.rrd"))  # warm-up
    t0 = time.perf_counter()
    path, _ = viz.log_steplog(steps, viz.SinkOptions(rrd=tmp / "ft.rrd"))
    t_log = time.perf_counter() - t0
    print(f"[3] fast-time, one 240 s encounter: simulate {t_sim:.3f} s, log_steplog {t_log:.3f} s "
          f"(ratio {t_log / t_sim:.2f}); .rrd {path.stat().st_size / 1000:.0f} kB")


def main(argv: "list[str] | None" = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", type=Path, default=ROOT / "scenarios" / "head_on.yaml")
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--skip-sil", action="store_true", help="only the fast-time comparison")
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        if not a.skip_sil:
            wall, log = bench_sil(a.scenario, a.repeat, tmp)
            bench_live(log, wall, tmp)
        bench_fasttime(tmp)
    return 0


if __name__ == "__main__":
    sys.exit(main())
