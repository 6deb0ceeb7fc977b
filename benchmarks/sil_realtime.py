"""``bench_sil.py --part realtime``: N concurrent ``daa-sil run --clock realtime`` encounters, their step
lateness, the shim's release lateness and whether each run's step log is identical to the lockstep run's
(see bench_sil.py's docstring for what is printed and the targets)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

LATE_TARGET_MS = 50.0


def _launch(scenario: Path, out: Path, clock: list, env: "dict | None" = None) -> subprocess.Popen:
    out.parent.mkdir(parents=True, exist_ok=True)  # next to the run's --out, which must be empty when it starts
    return subprocess.Popen([sys.executable, "-m", "daa_sil.cli", "run", str(scenario), "--out", str(out), "--json"]
                            + clock, stdout=open(_console(out, "stdout.json"), "w"),
                            stderr=open(_console(out, "stderr.txt"), "w"), cwd=ROOT, env={**os.environ, **(env or {})})


def _console(out: Path, name: str) -> Path:
    """Where the console output of the run into ``out`` goes: ``OUT.stdout.json`` / ``OUT.stderr.txt``."""
    return out.parent / f"{out.name}.{name}"


def _evaluate(out: Path, rc: int, ref_rows: list, ref: dict) -> dict:
    from daa_sil.steplog import read_steplog

    ev = {"dir": str(out), "rc": rc}
    try:
        res = json.loads((out / "result.json").read_text())
    except (OSError, ValueError):
        ev["error"] = _console(out, "stderr.txt").read_text()[-300:]
        return ev
    from daa_sil.steplog import cells_equal, steplog_metadata

    rows = read_steplog(out / "steplog.parquet").to_pylist()
    timing = json.loads(steplog_metadata(out / "steplog.parquet").get("realtime_timing", "{}"))
    ev["t0"], ev["late_ms"] = timing.get("t0_monotonic"), timing.get("late_ms", [])
    ev["ready_ms"] = timing.get("ready_ms", [])
    ev["speed"], ev["short_slice"] = timing.get("speed"), timing.get("short_slice")
    cells = sum(1 for ra, rb in zip(ref_rows, rows) for k in ra if not cells_equal(ra[k], rb[k]))
    rt = res.get("realtime") or {}
    lat = rt.get("shim_release_lateness_ms") or {}
    ev.update(identical=len(rows) == len(ref_rows) and cells == 0, cells_differing=cells,
              same_decisions=res["decision_sequence"] == ref["decision_sequence"],
              min_range_m=res["min_range_m"], min_range_t_s=res["min_range_t_s"],
              d_min_range_m=abs(res["min_range_m"] - ref["min_range_m"]),
              equivalent=rt.get("lockstep_equivalent"), late_mean=rt.get("late_mean_ms"),
              late_p99=rt.get("late_p99_ms"), late_max=rt.get("late_max_ms"), shim_p99=lat.get("p99"),
              shim_max=lat.get("max"), unconfirmed=rt.get("steps_unconfirmed"), gcs_lagged=rt.get("gcs_lagged"),
              released_late=rt.get("released_late"), expectation_ok=(res.get("expectation") or {}).get("ok"))
    return ev


def _play_batch(scenario: Path, base: Path, n: int, clock: list, stagger: float, ref_rows, ref,
                ab_slice: bool = False) -> tuple:
    loads, stop = [], threading.Event()

    def sample():
        while not stop.is_set():
            loads.append(os.getloadavg()[0])
            stop.wait(2.0)

    th = threading.Thread(target=sample, daemon=True)
    th.start()
    procs = []
    t0 = time.monotonic()
    for i in range(n):
        # --ab-slice: every other run's vehicle keeps the default scheduler slice (interleaved A/B)
        env = {"DAA_SIL_VEHICLE_SLICE_US": "0"} if ab_slice and i % 2 else None
        procs.append((base / f"run{i:02d}", _launch(scenario, base / f"run{i:02d}", clock, env)))
        if stagger and i + 1 < n:
            time.sleep(stagger)
    evs = [_evaluate(out, p.wait(), ref_rows, ref) for out, p in procs]
    wall = time.monotonic() - t0
    stop.set()
    th.join()
    return evs, loads, wall


def _window(evs: list) -> "tuple[float, float] | None":
    """Wall interval (monotonic s) in which every run was playing (after the last start-up)."""
    ok = [e for e in evs if "error" not in e and e.get("t0") is not None and e.get("late_ms")]
    if len(ok) < len(evs) or not ok:
        return None
    lo = max(e["t0"] for e in ok)
    hi = min(e["t0"] + (len(e["late_ms"]) - 1) / e["speed"] for e in ok)
    return (lo, hi) if hi > lo else None


def _late_in(e: dict, win) -> list:
    return [x for k, x in enumerate(e.get("late_ms") or []) if win[0] <= e["t0"] + k / e["speed"] <= win[1]]


def _summary(evs: list) -> dict:
    ok = [e for e in evs if "error" not in e]

    def col(k):
        return [e[k] for e in ok if e.get(k) is not None]

    return {"runs": len(evs), "completed": len(ok), "identical": sum(bool(e["identical"]) for e in ok),
            "same_decisions": sum(bool(e["same_decisions"]) for e in ok),
            "equivalent": sum(bool(e["equivalent"]) for e in ok),
            "min_ranges": sorted({round(e["min_range_m"], 1) for e in ok}),
            "max_d_min_range_m": max(col("d_min_range_m"), default=None),
            "late_mean": max(col("late_mean"), default=None), "late_p99": max(col("late_p99"), default=None),
            "late_max": max(col("late_max"), default=None),
            "over_target": sum(1 for e in ok if (e.get("late_max") or 0) > LATE_TARGET_MS),
            "shim_p99_median": sorted(col("shim_p99"))[len(col("shim_p99")) // 2] if col("shim_p99") else None,
            "shim_p99_max": max(col("shim_p99"), default=None), "unconfirmed": sum(col("unconfirmed")),
            "released_late": sum(col("released_late"))}


def _fmt(x, nd=1):
    return "-" if x is None else f"{x:.{nd}f}"


def bench_realtime(args) -> None:
    import yaml

    from daa_sil.sil.play import RunOptions, run_sil
    from daa_sil.sil.scenario import load_scenario, scenario_from_dict
    from daa_sil.steplog import read_steplog

    speeds = [float(x) for x in args.speeds.split(",") if x.strip()]
    sc = load_scenario(args.scenario)
    d = sc.to_dict()
    if args.duration:
        d["duration_s"] = float(args.duration)
    scenario_from_dict(d)
    tmp = tempfile.TemporaryDirectory()
    base = args.keep or Path(tmp.name)
    base.mkdir(parents=True, exist_ok=True)
    path = base / "bench_realtime.yaml"
    path.write_text(yaml.safe_dump(d, sort_keys=False))
    print(f"realtime SIL: {sc.name}, {d['duration_s']:g} s per run, {args.runs} concurrent runs per speed, "
          f"{os.cpu_count()} CPUs; load average before: {', '.join(f'{x:.2f}' for x in os.getloadavg())}")
    ref = run_sil(RunOptions(path, base / "lockstep"))
    ref_rows = read_steplog(base / "lockstep" / "steplog.parquet").to_pylist()
    print(f"  lockstep reference: {len(ref['decision_sequence'])} decisions, min range {ref['min_range_m']:.1f} m "
          f"at t = {ref['min_range_t_s']:g} s")
    for speed in speeds:
        clock = ["--clock", "realtime", "--speed", f"{speed:g}"]
        alone, loads0, wall0 = _play_batch(path, base / f"x{speed:g}_alone", 1, clock, 0.0, ref_rows, ref)
        evs, loads, wall = _play_batch(path, base / f"x{speed:g}_load", args.runs, clock, args.stagger, ref_rows, ref,
                                       ab_slice=args.ab_slice)
        a, s_ = _summary(alone), _summary(evs)
        print(f"\n  speed {speed:g}x, 1 run alone (load avg {_fmt(max(loads0, default=None), 2)}): "
              f"identical to lockstep {a['identical']}/1; step lateness mean {_fmt(a['late_mean'])} p99 "
              f"{_fmt(a['late_p99'])} max {_fmt(a['late_max'])} ms; shim release p99 {_fmt(a['shim_p99_max'], 2)} ms")
        print(f"  speed {speed:g}x, {args.runs} runs at once ({wall:.0f} s wall; load average while playing: "
              f"mean {_fmt(sum(loads) / len(loads) if loads else None, 2)}, max {_fmt(max(loads, default=None), 2)}):")
        print("    run  identical  decisions  min range (m)  late mean/p99/max (ms)  shim p99/max (ms)  unconfirmed")
        for i, e in enumerate(evs):
            if "error" in e:
                print(f"    {i:3d}  FAILED rc={e['rc']}: {e['error'].strip().splitlines()[-1] if e['error'].strip() else ''}")
                continue
            print(f"    {i:3d}  {str(e['identical']):9s}  {str(e['same_decisions']):9s}  {e['min_range_m']:13.1f}  "
                  f"{_fmt(e['late_mean']):>6s}/{_fmt(e['late_p99']):>5s}/{_fmt(e['late_max']):>6s}        "
                  f"{_fmt(e['shim_p99'], 2):>6s}/{_fmt(e['shim_max'], 1):>6s}       {e['unconfirmed']}")
        print(f"    => {s_['completed']}/{s_['runs']} completed; step log identical to lockstep in "
              f"{s_['identical']}/{s_['completed']} (decision sequence in {s_['same_decisions']}), minimum ranges "
              f"{s_['min_ranges']} m (lockstep {ref['min_range_m']:.1f} m; largest difference "
              f"{_fmt(s_['max_d_min_range_m'], 3)} m)")
        print(f"    => vehicle step lateness: worst mean {_fmt(s_['late_mean'])} ms, worst p99 {_fmt(s_['late_p99'])} ms, "
              f"worst max {_fmt(s_['late_max'])} ms; runs with a step over {LATE_TARGET_MS:g} ms: {s_['over_target']}"
              f"/{s_['completed']}; steps run unconfirmed {s_['unconfirmed']}")
        win = _window(evs)
        if win is not None:
            import numpy as np

            inside = np.array([x for e in evs for x in _late_in(e, win)])
            over = sum(1 for e in evs if any(x > LATE_TARGET_MS for x in _late_in(e, win)))
            print(f"    => while all {args.runs} were playing ({win[1] - win[0]:.0f} s, after the last start-up): "
                  f"{inside.size} steps, lateness mean {inside.mean():.1f} p99 {np.percentile(inside, 99):.1f} max "
                  f"{inside.max():.1f} ms; runs with a step over {LATE_TARGET_MS:g} ms: {over}/{len(evs)}")
            late_steps = [(x, r) for e in evs for k, (x, r) in enumerate(zip(e["late_ms"], e.get("ready_ms") or []))
                          if win[0] <= e["t0"] + k / e["speed"] <= win[1] and x > LATE_TARGET_MS]
            if late_steps:
                computed_late = sum(1 for x, r in late_steps if r > 0)
                print(f"    => of the {len(late_steps)} steps over {LATE_TARGET_MS:g} ms in that window, {computed_late} "
                      f"were still being computed at their deadline (echo or computation late); the other "
                      f"{len(late_steps) - computed_late} were ready before it and woke up late")
            outside = np.array([x for e in evs for k, x in enumerate(e["late_ms"])
                                if not win[0] <= e["t0"] + k / e["speed"] <= win[1]])
            if outside.size:
                print(f"    => outside that window (other runs starting or finishing): {outside.size} steps, max "
                      f"{outside.max():.1f} ms, {int((outside > LATE_TARGET_MS).sum())} over {LATE_TARGET_MS:g} ms")
        if args.ab_slice and win is not None:
            import numpy as np

            for label, want in (("with the short slice", True), ("default slice", False)):
                grp = [e for e in evs if "error" not in e and bool(e.get("short_slice")) == want]
                x = np.array([v for e in grp for v in _late_in(e, win)])
                if x.size:
                    print(f"    => A/B {label} ({len(grp)} runs, same window): mean {x.mean():.1f} p99 "
                          f"{np.percentile(x, 99):.1f} max {x.max():.1f} ms, steps over {LATE_TARGET_MS:g} ms "
                          f"{int((x > LATE_TARGET_MS).sum())} of {x.size}")
        print(f"    => shim release lateness (delay error) p99: median over runs {_fmt(s_['shim_p99_median'], 2)} ms, "
              f"worst {_fmt(s_['shim_p99_max'], 2)} ms; short EEVDF slice granted to the vehicles: "
              f"{sum(bool(e.get('short_slice')) for e in evs)}/{len(evs)}")
        if a["late_max"] and s_["late_max"] is not None and a["shim_p99_max"]:
            print(f"    => loaded / alone: worst step lateness {s_['late_max'] / a['late_max']:.1f}x, shim p99 "
                  f"{s_['shim_p99_max'] / a['shim_p99_max']:.1f}x")
    tmp.cleanup()

