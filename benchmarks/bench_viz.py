"""Benchmark the Rerun logging overhead against the run it visualises.

Usage::

    python benchmarks/bench_viz.py                              # scenarios/head_on.yaml, 10 pairs
    python benchmarks/bench_viz.py --scenario scenarios/crossing_left.yaml --repeat 4
    python benchmarks/bench_viz.py --skip-sil                    # only [0] and [3]

Prints, all measured in this run:

0. **Where the time goes** (fresh interpreter, no SIL running): starting Python with numpy/pyarrow,
   importing rerun, opening the file sink + static entities, then the part that is left for the end
   of a run (read the step log, blueprint, ``send_columns`` of all steps, flush/close/rename), and
   the interpreter exit. ``daa-sil run --rrd`` forks its helper at launch (so the helper inherits
   Python, numpy and pyarrow: no start-up, no exit), lets it import rerun and log the static parts
   at SCHED_IDLE once the SIL processes are ready, and hands it the step log the moment the vehicle
   exits, so the END part overlaps with stopping the shim and the GCS.
1. **Lockstep SIL**: wall time of ``daa-sil run SCENARIO`` without and with ``--rrd``, in interleaved
   pairs (the order inside a pair alternates), as seen by the caller (process start to exit). Prints
   each pair, the median of the per-pair ratios and their spread (min..max), the median of the wall
   times, the run's own wall time (does the helper slow the run?), the time after the run that the
   caller waits for the recorder, the CPU time of all processes, and the .rrd size.
   Target: ratio <= 1.10.
2. **Live logging cost** on the same step log: the time the control loop spends inside
   ``EncounterLogger.log_step`` (per step, it only queues the row) and the background thread's total
   (until ``close()``), each as a fraction of the SIL run's wall time.
3. **Fast-time**: one encounter simulated by ``daa_sil.study.simulation.fasttime.simulate(record_steps=True)``
   against ``log_steplog`` of its step log (the batch path, ``send_columns``).
4. **Realtime with live streaming** (``--clock realtime --speed 20 --connect URL --rrd FILE`` to a
   headless viewer, the rerun binary serving gRPC on 127.0.0.1): how late the vehicle finished its
   steps after their due wall time (mean and max, from the step log's metadata) without and with
   the live stream, in interleaved pairs, and how many steps were in the viewer before the vehicle
   exited.
"""

from __future__ import annotations

import argparse
import json
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TIMING: list[dict] = []  #: result.json "rrd_timing" of every --rrd run

PROFILE_CHILD = r"""
import json, os, sys, time
T = [("start", time.perf_counter())]
def mark(name): T.append((name, time.perf_counter()))
import numpy, pyarrow, pyarrow.parquet
from daa_sil import viz
from daa_sil.steplog import read_steplog
mark("numpy + pyarrow + daa_sil.viz")
import rerun, rerun.blueprint
mark("import rerun")
logger = viz.EncounterLogger(viz.SinkOptions(rrd=sys.argv[2], overwrite=True), encounter_id=0, defer_blueprint=True)
mark("open file sink + static entities")
table, _ = viz.select_encounter(read_steplog(sys.argv[1]))
center, extent = viz.focus(table)
mark("END: read step log + camera target")
logger.send_blueprint(center, extent)
mark("END: send blueprint")
logger.log_table(table)
mark("END: send_columns of all steps")
logger.close()
mark("END: flush + disconnect + fsync + rename")
print(json.dumps([(b, tb - ta) for (a, ta), (b, tb) in zip(T, T[1:])]))
"""


def _sil_run(scenario: Path, out: Path, rrd: "Path | None", extra: tuple = ()) -> tuple[float, float, float]:
    """(wall time seen by the caller, the run's own wall_s from result.json, CPU time of all its
    processes), s."""
    cmd = [sys.executable, "-m", "daa_sil.cli", "run", str(scenario), "--out", str(out), "--json", *extra]
    if rrd is not None:
        cmd += ["--rrd", str(rrd)]
    ru0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    res = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    ru1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (ru1.ru_utime + ru1.ru_stime) - (ru0.ru_utime + ru0.ru_stime)
    if res.returncode not in (0, 1) or not (out / "steplog.parquet").exists():
        raise SystemExit(f"bench_viz: daa-sil run failed ({res.returncode}): {res.stderr.strip()[-300:]}")
    if rrd is not None and not rrd.exists():
        raise SystemExit(f"bench_viz: daa-sil run --rrd wrote no recording: {res.stderr.strip()[-300:]}")
    result = json.loads(res.stdout)
    if rrd is not None:
        TIMING.append(result.get("rrd_timing") or {})
    return wall, float(result["wall_s"]), cpu


def bench_profile(steplog_path: Path, tmp: Path) -> None:
    t0 = time.perf_counter()
    res = subprocess.run([sys.executable, "-c", PROFILE_CHILD, str(steplog_path), str(tmp / "profile.rrd")],
                         capture_output=True, text=True, check=True)
    total = time.perf_counter() - t0
    parts = json.loads(res.stdout.strip().splitlines()[-1])
    inside = sum(dt for _, dt in parts)
    end = sum(dt for name, dt in parts if name.startswith("END"))
    print("[0] where the time of an .rrd goes (one fresh interpreter, idle SIL):")
    for name, dt in parts:
        print(f"    {name:42s} {1000 * dt:7.1f} ms")
    print(f"    {'interpreter start + exit (the rest)':42s} {1000 * (total - inside):7.1f} ms\n"
          f"    total {1000 * total:.0f} ms; left for the end of a run (END lines): {1000 * end:.0f} ms")


def bench_sil(scenario: Path, repeat: int, tmp: Path) -> tuple[float, Path]:
    plain, with_rrd, own_plain, own_rrd, cpu_plain, cpu_rrd = [], [], [], [], [], []
    rrd = None
    for k in range(repeat):
        rrd = tmp / f"rrd{k}" / "enc.rrd"
        rrd.parent.mkdir()
        order = (None, rrd) if k % 2 == 0 else (rrd, None)
        for r in order:
            w, own, cpu = _sil_run(scenario, tmp / (f"rrd{k}" if r else f"plain{k}"), r)
            (with_rrd if r else plain).append(w)
            (own_rrd if r else own_plain).append(own)
            (cpu_rrd if r else cpu_plain).append(cpu)
    ratios = [b / a for a, b in zip(plain, with_rrd)]
    a, b = statistics.median(plain), statistics.median(with_rrd)
    # the caller's wall minus the run's own wall: process start, the recorder's finish, exit
    tail = statistics.median(w - o for w, o in zip(with_rrd, own_rrd)) - statistics.median(
        w - o for w, o in zip(plain, own_plain))
    r_med = statistics.median(ratios)
    print(f"[1] lockstep SIL {scenario.name}: {repeat} interleaved pairs (wall seen by the caller, s)")
    for k, (x, y, r) in enumerate(zip(plain, with_rrd, ratios)):
        print(f"    pair {k}: without {x:.2f}  with --rrd {y:.2f}  ratio {r:.3f}")
    print(f"    median wall: without {a:.2f} s, with --rrd {b:.2f} s\n"
          f"    ratio with/without: median {r_med:.3f} ({100 * (r_med - 1):+.1f} %), spread {min(ratios):.3f}"
          f"..{max(ratios):.3f}; target <= 1.10: {'met' if r_med <= 1.10 else 'NOT met'}\n"
          f"    the run itself (result.json wall_s, while the helper prepares): median {statistics.median(own_plain):.2f}"
          f" s without, {statistics.median(own_rrd):.2f} s with --rrd, per-pair ratio median "
          f"{statistics.median(b / a for a, b in zip(own_plain, own_rrd)):.3f}\n"
          f"    the caller waits {1000 * tail:+.0f} ms longer after the run with --rrd (median)\n"
          f"    helper prepared before the vehicle exited in {sum(bool(t.get('prepared_before_end')) for t in TIMING)}"
          f"/{len(TIMING)} runs; step log -> .rrd in place: median "
          f"{1000 * statistics.median(t.get('finish_s') or 0.0 for t in TIMING):.0f} ms, of which the caller "
          f"still waited {1000 * statistics.median(t.get('wait_s') or 0.0 for t in TIMING):.0f} ms (median)\n"
          f"    CPU time of all processes: median {statistics.median(cpu_plain):.2f} s without, "
          f"{statistics.median(cpu_rrd):.2f} s with --rrd (the helper runs SCHED_IDLE during the run)\n"
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
    from daa_sil import viz
    from daa_sil.config.groups import group_spec
    from daa_sil.models.encounters import sample_encounters
    from daa_sil.study.simulation.fasttime import simulate

    es = sample_encounters(1, seed=3)
    spec = group_spec("B-1")
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


def bench_realtime_live(scenario: Path, repeat: int, tmp: Path, speed: float = 20.0) -> None:
    import os
    import signal
    import socket

    from daa_sil import viz

    with socket.socket() as sk:
        sk.bind(("127.0.0.1", 0))
        port = sk.getsockname()[1]
    srv = subprocess.Popen([viz.rerun_binary(), "--serve-grpc", "--bind", "127.0.0.1", "--port", str(port)],
                           stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                           start_new_session=True)
    try:
        for _ in range(500):
            if viz.port_open("127.0.0.1", port, 0.1):
                break
            time.sleep(0.02)
        _realtime_pairs(scenario, repeat, tmp, speed, f"rerun+http://127.0.0.1:{port}/proxy")
    finally:
        os.killpg(srv.pid, signal.SIGTERM)
        srv.wait(timeout=10)


def _realtime_pairs(scenario: Path, repeat: int, tmp: Path, speed: float, url: str) -> None:
    from daa_sil.steplog import steplog_metadata

    clock = ("--clock", "realtime", "--speed", f"{speed:g}")
    late: dict = {"plain": [], "live": []}
    before, steps = [], 0
    for k in range(repeat):
        for kind in (("plain", "live") if k % 2 == 0 else ("live", "plain")):
            out = tmp / f"rt-{kind}{k}"
            rrd = out / "enc.rrd" if kind == "live" else None
            if rrd is not None:
                rrd.parent.mkdir(parents=True)
            _sil_run(scenario, out, rrd, clock + (("--connect", url) if rrd else ()))
            v = json.loads(steplog_metadata(out / "steplog.parquet")["vehicle"])
            late[kind].append((v["late_mean_ms"], v["late_max_ms"]))
            if rrd is not None:
                info = TIMING[-1].get("live") or {}
                before.append(info.get("before_exit", 0))
                steps = v["steps"]
    med = {k: (statistics.median(m for m, _ in x), statistics.median(mx for _, mx in x)) for k, x in late.items()}
    print(f"[4] realtime SIL {scenario.name} at {speed:g}x, {repeat} interleaved pairs: step done after its due "
          f"wall time, median of the runs' mean / max: without {med['plain'][0]:.2f} / {med['plain'][1]:.2f} ms, "
          f"with live streaming to a viewer + --rrd {med['live'][0]:.2f} / {med['live'][1]:.2f} ms\n"
          f"    steps in the viewer before the vehicle exited: {before} of {steps} (per run)")


def _any_steplog(tmp: Path) -> Path:
    """A real step log for [0] without a SIL run: one fast-time encounter."""
    from daa_sil import steplog
    from daa_sil.config.groups import group_spec
    from daa_sil.models.encounters import sample_encounters
    from daa_sil.study.simulation.fasttime import simulate

    spec = group_spec("B-1")
    model = spec.delay_model()
    _, _, steps = simulate(sample_encounters(1, seed=3), spec.policy(), model, model, preset="paper",
                           record_steps=True)
    return steplog.write_steplog(steps, tmp / "ft_steplog.parquet")


def main(argv: "list[str] | None" = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", type=Path, default=ROOT / "scenarios" / "head_on.yaml")
    ap.add_argument("--repeat", type=int, default=10, help="interleaved pairs (default 10)")
    ap.add_argument("--skip-sil", action="store_true", help="only the profile [0] and fast-time [3]")
    ap.add_argument("--live-repeat", type=int, default=3, help="interleaved realtime pairs for [4] (default 3; "
                                                               "0 skips it)")
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        if a.skip_sil:
            bench_profile(_any_steplog(tmp), tmp)
        else:
            plain_out = tmp / "warm"
            _sil_run(a.scenario, plain_out, None)  # warm-up: wait-map cache, OS file cache
            bench_profile(plain_out / "steplog.parquet", tmp)
            wall, log = bench_sil(a.scenario, a.repeat, tmp)
            bench_live(log, wall, tmp)
        bench_fasttime(tmp)
        if not a.skip_sil and a.live_repeat > 0:
            bench_realtime_live(a.scenario, a.live_repeat, tmp)
    return 0


if __name__ == "__main__":
    sys.exit(main())
