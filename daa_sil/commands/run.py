"""``daa-sil run SCENARIO`` and ``daa-sil demo``: the three-process SIL (vehicle, shim, GCS).

The orchestrator starts ``daa-vehicle``, the delay shim and ``daa-gcs`` as **separate processes**
(each in its own process group) on OS-chosen loopback ports, plays the encounter, stops them
(SIGINT, then SIGTERM, then SIGKILL, each with a timeout; also on Ctrl-C, so no orphans), and
summarises the vehicle's step log into ``DIR/result.json``.

Readiness: every child prints one ``READY key=value ...`` line on stdout once its sockets are
bound; the orchestrator reads the addresses from it (no guessed ports, no races). All child
output goes to ``DIR/logs/<name>.log``.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from ..errors import DaaSilError, OutputError, UsageError
from ._args import check_speed
from daa_sil.sil.supervise import (READY_TIMEOUT_S, STOP_GRACE_S, STOP_TERM_S, Child, ProcessGroup,
    RunMonitor, free_udp_ports, last_error_line, parse_ready_line, parse_shim_ready, python_module_argv)

#: wall s the vehicle waits for the answer to tick 0 under ``daa-sil run`` (start-up on a busy machine)
START_TIMEOUT_S = 120.0

EXAMPLES = """examples:
  # the main job: a head-on encounter, 4 s link delay, through the real link (lockstep)
  daa-sil demo --out demo-out

  # any scenario file, deterministic and fast (lockstep), result as JSON
  daa-sil run scenarios/head_on.yaml --out runs/head_on --json

  # the same in real time at 10x speed
  daa-sil run scenarios/crossing_left.yaml --clock realtime --speed 10

  # watch it in Rerun step by step as it plays (a viewer it spawns, or one already running)
  daa-sil run scenarios/head_on.yaml --clock realtime --speed 4 --spawn-viewer --rrd head_on.rrd
  daa-sil run scenarios/head_on.yaml --clock realtime --connect rerun+http://127.0.0.1:9876/proxy

Rerun: realtime runs with --spawn-viewer/--connect show every step in the viewer as it happens;
lockstep runs are logged from the step log when the vehicle exits, so nothing runs next to the SIL
(--viz-live). An --rrd file is always written from the step log at the end.

Exit status: 0 = the run matched the scenario's `expect:` block, 1 = an expectation was violated
or a process failed, 2 = bad input, 130 = interrupted (the step log is still written).
"""

def shim_argv(sc, clock_args: list, key_args: list, stats_json: Path, vehicle_port: int = 0,
              gcs_port: int = 0) -> list[str]:
    """``daa-sil shim`` arguments for scenario ``sc`` (link delays, loss, outages, seed)."""
    from daa_sil.sil.scenario import delay_spec_string

    link = sc.link
    argv = python_module_argv("daa_sil.cli") + [
        "shim", "--listen-vehicle", f"udp:127.0.0.1:{vehicle_port}", "--listen-gcs", f"udp:127.0.0.1:{gcs_port}",
        "--delay-up", delay_spec_string(link.up),
        "--delay-down", delay_spec_string(link.down if link.down is not None else link.up),
        "--epoch", f"{link.epoch_s:g}", "--loss", f"{link.loss:g}", "--seed", str(sc.seed),
        "--dup", f"{link.dup:g}", "--reorder", f"{link.reorder:g}",
        "--stats-json", str(stats_json)]
    for o in link.outages:
        argv += ["--outage", f"{o.start_s:g}:{o.end_s:g}"]
    return argv + clock_args + key_args


# --------------------------------------------------------------------------------------------
# result summary (pure: step log table -> result dict)

def summarize_steplog(table, scenario=None) -> dict:
    """LoWC, NMAC, minimum separation and the decision counts/sequence of one SIL run.

    ``decision_sequence`` lists every active step's decision as ``{t, decision, rule, authority}``
    (decision != ``none``), in step order. Distances in m, times in s.
    """
    import numpy as np

    from daa_sil.sil.scenario import DECISIONS, check_expectation

    n = table.num_rows
    col = {name: table.column(name).to_pylist() for name in
           ("t", "decision", "rule", "authority", "lowc", "nmac", "range_m", "dh_m", "wait_s")}
    counts = {d: 0 for d in DECISIONS}
    seq = []
    for i in range(n):
        d = col["decision"][i]
        counts[d] = counts.get(d, 0) + 1
        if d != "none":
            w = col["wait_s"][i]
            seq.append({"t": col["t"][i], "decision": d, "rule": col["rule"][i],
                        "authority": col["authority"][i],
                        "wait_s": None if w is None or not np.isfinite(w) else round(float(w), 3)})
    counts.pop("none", None)
    rng = np.array([min(r) if r else np.inf for r in col["range_m"]], dtype=float) if n else np.array([np.inf])
    k = int(np.argmin(rng)) if n else 0
    dh_at = None
    if n and col["dh_m"][k]:
        j = int(np.argmin(col["range_m"][k]))
        dh_at = float(col["dh_m"][k][j])
    lowc_t = [col["t"][i] for i in range(n) if col["lowc"][i]]
    link_lost_t = [e["t"] for e in seq if e["decision"] == "link_lost"]
    handed = [e["t"] for e in seq if e["authority"] == "daa"]
    result = {
        "steps": n,
        "duration_s": (col["t"][-1] + 1.0) if n else 0.0,
        "lowc": bool(any(col["lowc"])),
        "nmac": bool(any(col["nmac"])),
        "lowc_steps": len(lowc_t),
        "first_lowc_s": lowc_t[0] if lowc_t else None,
        "min_range_m": float(rng[k]) if n and np.isfinite(rng[k]) else None,
        "min_range_t_s": col["t"][k] if n else None,
        "vsep_at_min_range_m": abs(dh_at) if dh_at is not None else None,
        "n_active_steps": len(seq),
        "decision_counts": counts,
        "decision_sequence": seq,
        "first_link_lost_s": link_lost_t[0] if link_lost_t else None,
        "first_daa_authority_s": handed[0] if handed else None,
    }
    if scenario is not None:
        violations = check_expectation(scenario.expect, result)
        result["expectation"] = {"checked": True, "ok": not violations, "violations": violations}
    return result


def human_summary(result: dict, scenario=None, out_dir: "Path | None" = None) -> str:
    """A few lines for people: what happened, when control moved, separation, outcome."""
    lines = []
    if scenario is not None:
        lines.append(f"scenario {scenario.name}: {scenario.description.strip().splitlines()[0] if scenario.description.strip() else ''}".rstrip(": "))
    c = result["decision_counts"]
    active = ", ".join(f"{k} {v}" for k, v in c.items() if v) or "none"
    lines.append(f"  active steps: {result['n_active_steps']}  decisions: {active}")
    seq = result["decision_sequence"]
    if seq:
        runs = []
        for e in seq:
            if runs and runs[-1][0] == e["decision"] and e["t"] - runs[-1][2] <= 1.0 + 1e-9:
                runs[-1][2] = e["t"]
            else:
                runs.append([e["decision"], e["t"], e["t"]])
        parts = [f"{d} {a:.0f}s" if a == b else f"{d} {a:.0f}-{b:.0f}s" for d, a, b in runs[:12]]
        more = f" ... (+{len(runs) - 12} more)" if len(runs) > 12 else ""
        lines.append("  timeline: " + ", ".join(parts) + more)
    if result.get("first_daa_authority_s") is not None:
        lines.append(f"  onboard DAA first took control at t = {result['first_daa_authority_s']:.0f} s")
    mr = result["min_range_m"]
    vs = result["vsep_at_min_range_m"]
    lines.append(f"  min horizontal range {mr:.0f} m at t = {result['min_range_t_s']:.0f} s"
                 + (f" (vertical separation {vs:.0f} m)" if vs is not None else "") if mr is not None
                 else "  min horizontal range: n/a")
    lines.append(f"  LoWC: {'YES' if result['lowc'] else 'no'}   NMAC: {'YES' if result['nmac'] else 'no'}")
    exp = result.get("expectation")
    if exp:
        lines.append("  expected outcome: " + ("OK" if exp["ok"] else "VIOLATED: " + "; ".join(exp["violations"])))
    if out_dir is not None:
        lines.append(f"  results: {out_dir / 'result.json'}  step log: {out_dir / 'steplog.parquet'}")
    return "\n".join(lines)


# --------------------------------------------------------------------------------------------
# the run

@dataclass
class RunOptions:
    scenario_path: Path
    out_dir: Path
    clock: str = "lockstep"
    speed: float = 1.0
    key: "Path | None" = None
    tick_timeout_s: float = 10.0
    rrd: "Path | None" = None
    spawn_viewer: bool = False
    connect: "str | None" = None
    #: stream the steps to the Rerun sinks as they happen: "auto" (realtime runs with a viewer sink,
    #: --spawn-viewer / --connect), "on" or "off" (log the step log when the vehicle exits)
    viz_live: str = "auto"
    tap: "str | None" = None
    #: ``--waitmap`` of the vehicle: a map preset, grid spec or family directory (None = the default)
    waitmap: "str | None" = None
    progress: "Callable[[str], None] | None" = None


def _say(opts: RunOptions, msg: str) -> None:
    if opts.progress is not None:
        opts.progress(msg)


def run_sil(opts: RunOptions) -> dict:
    """Play ``opts.scenario_path`` through vehicle, shim and GCS processes; return the result dict.

    Writes ``out_dir/result.json``, ``out_dir/steplog.parquet``, ``out_dir/gcs_commands.jsonl``
    and ``out_dir/logs/``. Raises DaaSilError if a process fails; KeyboardInterrupt propagates
    after every child is stopped and whatever step log exists is summarised.
    """
    from daa_sil.files import ensure_dir
    from daa_sil.sil.scenario import load_scenario

    sc = load_scenario(opts.scenario_path)
    check_faults_allowed(sc, opts.clock, opts.scenario_path)
    out = ensure_dir(opts.out_dir)
    steplog = out / "steplog.parquet"
    for stale in (steplog, out / "result.json"):
        stale.unlink(missing_ok=True)
    key_args = ["--key", str(opts.key)] if opts.key else []
    clock_args = ["--clock", opts.clock] + (["--speed", f"{opts.speed:g}"] if opts.clock == "realtime" else [])
    recorder = _start_recorder(opts, sc)  # forked now, before any thread; prepares once the SIL is ready
    try:
        return _play(opts, sc, out, steplog, key_args, clock_args, recorder)
    finally:
        if recorder is not None:
            recorder.abort()  # no-op after finish; otherwise kills the helper and removes its temp file


def live_viz(opts: RunOptions) -> bool:
    """True if the run streams its steps to a Rerun viewer as they happen (``--viz-live``, see
    RunOptions; only with a viewer: the .rrd is always made from the step log)."""
    if not (opts.spawn_viewer or opts.connect) or opts.viz_live == "off":
        return False
    return opts.viz_live == "on" or opts.clock == "realtime"


def _start_recorder(opts: RunOptions, sc):
    """A :class:`daa_sil.viz.recorder.BackgroundRecorder` for ``--rrd`` / ``--spawn-viewer`` /
    ``--connect`` (None without them): an idle helper process now; :func:`_play` lets it prepare once
    the SIL processes are ready and hands it the step log when the vehicle exits. In live mode
    (:func:`live_viz`) it also logs the rows the vehicle sends to ``recorder.live_address`` during the
    run. The ``--rrd`` path was checked by :func:`_check_args` before anything started.
    """
    if not (opts.rrd or opts.spawn_viewer or opts.connect):
        return None
    from ..viz import SinkOptions
    from daa_sil.viz.recorder import BackgroundRecorder

    try:
        return BackgroundRecorder(SinkOptions(rrd=opts.rrd, spawn=opts.spawn_viewer, connect=opts.connect,
                                              overwrite=True),
                                  preset=sc.thresholds, encounter_id=0,  # the vehicle logs encounter 0
                                  live=live_viz(opts))
    except OSError as exc:  # the helper process cannot start: the run goes on without a recording
        print(f"daa-sil: warning: cannot start the Rerun recorder ({exc.strerror or exc}); no recording",
              file=sys.stderr, flush=True)
        return None


def _finish_recorder(recorder, steplog: Path) -> "Path | None":
    """Hand the step log to the recorder; its warnings become ``daa-sil: warning: ...`` lines."""
    from .viz import one_line_warnings

    with one_line_warnings():
        return recorder.finish(steplog)


def check_faults_allowed(sc, clock: str, path=None) -> None:
    """A scenario with process faults needs ``--clock realtime``: one-line UsageError otherwise."""
    if sc.faults and clock != "realtime":
        what = "; ".join(f.describe() for f in sc.faults)
        raise UsageError(f"{path or sc.source}: faults ({what}) need --clock realtime: in lockstep the GCS is part of "
                         f"the clock (the vehicle waits for each tick's ack), so killing it would stop the simulation, "
                         f"not just the link; run it with --clock realtime (e.g. --speed 10)")


def _gcs_argv(opts: RunOptions, out: Path, listen: str, gcs_side: str, clock_args: list, key_args: list,
              log_name: str = "gcs_commands.jsonl") -> list:
    return python_module_argv("gcs") + [
        "--scenario", str(opts.scenario_path), "--listen", listen, "--vehicle", gcs_side,
        "--log", str(out / log_name), "--no-display"] + clock_args + key_args


def realtime_report(steplog_meta: dict, shim_stats: "dict | None", gcs_skipped: "int | None") -> dict:
    """Whether a realtime run kept lockstep semantics, from the vehicle's and the shim's counters.

    ``lockstep_equivalent`` is true when every tick was answered by the shim before its step ran
    (``steps_unconfirmed`` 0), no GCS datagram missed the tick that lockstep releases it at
    (``released_late`` 0), the GCS never fell ``MAX_GCS_LAG_TICKS`` behind (``gcs_unresponsive``
    0) and it stepped on every tick (``gcs_ticks_skipped`` 0): then each step of the vehicle and of
    the GCS had the same input as in lockstep.
    """
    try:
        veh = json.loads(steplog_meta.get("vehicle") or "{}")
    except ValueError:
        veh = {}
    c = (shim_stats or {}).get("counters", {})
    rep = {"sync_partner": veh.get("sync_partner"), "steps_unconfirmed": veh.get("steps_unconfirmed"),
           "gcs_acks_late": veh.get("acks_late"), "late_mean_ms": veh.get("late_mean_ms"),
           "late_max_ms": veh.get("late_max_ms"), "late_p99_ms": veh.get("late_p99_ms"), "shim_release": (shim_stats or {}).get("release"),
           "released_late": c.get("released_late"), "gcs_lagged": c.get("gcs_lagged"),
           "gcs_unresponsive": c.get("gcs_unresponsive"), "gcs_ticks_skipped": gcs_skipped,
           "shim_release_lateness_ms": (shim_stats or {}).get("release_lateness_ms"),
           "tick_schedule": (shim_stats or {}).get("tick_schedule")}
    rep["lockstep_equivalent"] = bool(
        rep["sync_partner"] == "shim" and rep["shim_release"] == "ticks" and rep["steps_unconfirmed"] == 0
        and rep["released_late"] == 0 and rep["gcs_unresponsive"] == 0 and gcs_skipped == 0)
    return rep


_SKIPPED = re.compile(r"ticks skipped (\d+)")


def _gcs_ticks_skipped(log_path: Path) -> "int | None":
    try:
        m = _SKIPPED.findall(log_path.read_text(errors="replace"))
    except OSError:
        return None
    return int(m[-1]) if m else None


def _play(opts: RunOptions, sc, out: Path, steplog: Path, key_args: list, clock_args: list, recorder) -> dict:
    from daa_sil.files import atomic_write_json
    from ..steplog import read_steplog

    t0 = time.monotonic()
    interrupted = False
    failure: "str | None" = None
    monitor: "RunMonitor | None" = None
    gcs_logs = [out / "gcs_commands.jsonl"]
    with ProcessGroup(out / "logs") as pg:
        try:
            # all three start at once: the shim's ports are picked here (the shim binds them; if one was
            # taken in between, its READY never comes and the run fails with a clear message). A GCS that
            # a fault restarts must come back on the same port, so it gets a fixed one too.
            v_side, g_side, g_port = free_udp_ports(3)
            sready = {"vehicle_side": f"udp:127.0.0.1:{v_side}", "gcs_side": f"udp:127.0.0.1:{g_side}"}
            gcs_listen = f"udp:127.0.0.1:{g_port}" if sc.faults else "udp:127.0.0.1:0"
            shim = pg.start("shim", shim_argv(sc, clock_args, key_args, out / "shim_stats.json", v_side, g_side),
                            ready_parser=parse_shim_ready)
            gcs = pg.start("gcs", _gcs_argv(opts, out, gcs_listen, sready["gcs_side"], clock_args, key_args))
            vargs = [str(opts.scenario_path), "--listen", "udp:127.0.0.1:0", "--out", sready["vehicle_side"],
                     "--steplog", str(steplog), "--tap", opts.tap or "none",
                     "--tick-timeout", f"{opts.tick_timeout_s:g}",
                     # tick 0: the GCS may still be starting (the monitor below notices a dead one at once)
                     "--start-timeout", f"{max(opts.tick_timeout_s, START_TIMEOUT_S):g}"] + clock_args + key_args
            if opts.clock == "realtime":
                vargs += ["--tick-sync", "wait"]  # start once tick 0 is acked: the GCS plays from step 0
            if opts.waitmap is not None:
                vargs += ["--waitmap", str(opts.waitmap)]
            if recorder is not None and recorder.live_address:
                vargs += ["--live", recorder.live_address]  # each step's row, fire-and-forget
            # GCS and vehicle start in parallel; the vehicle re-sends tick 0 until the GCS answers
            vehicle = pg.start("vehicle", python_module_argv("vehicle") + vargs)
            pg.wait_ready(shim)
            pg.wait_ready(gcs)
            pg.wait_ready(vehicle, timeout=READY_TIMEOUT_S + 120.0)  # may build the wait map first
            if recorder is not None:
                # now, not at launch: the three processes' start-up is CPU-bound (a helper importing
                # Rerun then slowed it measurably), the lockstep play leaves a core idle
                recorder.prepare()
            _say(opts, f"playing {sc.duration_s:g} s of {sc.name} ({opts.clock})"
                 + (f"; faults: {'; '.join(f.describe() for f in sc.faults)}" if sc.faults else ""))

            def restart(fault, n):
                name = f"{fault.process}{n + 1}"
                log = f"gcs_commands_{name}.jsonl"
                gcs_logs.append(out / log)
                return pg.start(name, _gcs_argv(opts, out, gcs_listen, sready["gcs_side"], clock_args, key_args,
                                                log_name=log))

            monitor = RunMonitor(vehicle, {"shim": shim, "gcs": gcs}, faults=sc.faults, restart=restart)
            failure = monitor.wait()
            exited = time.monotonic()
            if failure is not None:
                _say(opts, f"stopping the run: {failure}")
            rc = vehicle.proc.poll()
            if recorder is not None and rc == 0 and steplog.exists():
                # logs (deferred) or completes (live) while the shim and GCS are stopped and the result is made
                recorder.submit(steplog, vehicle_exit=exited)
        except KeyboardInterrupt:
            interrupted = True
    wall = time.monotonic() - t0
    if not steplog.exists():
        if interrupted:
            raise KeyboardInterrupt
        raise DaaSilError(failure or f"the vehicle wrote no step log (logs: {out / 'logs'})")
    table = read_steplog(steplog)
    result = summarize_steplog(table, sc)
    result.update({"scenario": sc.name, "scenario_file": str(opts.scenario_path), "seed": sc.seed,
                   "preset": sc.thresholds, "clock": opts.clock, "wall_s": round(wall, 3),
                   "waitmap": _waitmap_record(sc, opts.waitmap),
                   "realtime_ratio": round(result["duration_s"] / wall, 2) if wall > 0 else None,
                   "interrupted": interrupted, "failure": failure,
                   "process_died": monitor.death if monitor is not None else None,
                   "files": {"steplog": str(steplog), "gcs_log": str(out / "gcs_commands.jsonl"),
                             "gcs_logs": [str(x) for x in gcs_logs if x.is_file()], "logs": str(out / "logs")}})
    if sc.faults:
        result["faults"] = monitor.fault_report() if monitor is not None else []
    if opts.clock == "realtime":
        from ..steplog import steplog_metadata

        shim_stats = None
        try:
            shim_stats = json.loads((out / "shim_stats.json").read_text())
        except (OSError, ValueError):
            pass
        result["realtime"] = realtime_report(steplog_metadata(steplog), shim_stats,
                                             _gcs_ticks_skipped(out / "logs" / "gcs.log"))
    if recorder is not None:
        # also after Ctrl-C: the partial step log becomes a complete, readable recording (a second
        # Ctrl-C aborts it and no .rrd is written)
        try:
            rrd = _finish_recorder(recorder, steplog)
        except KeyboardInterrupt:
            rrd, interrupted = None, True
            result["interrupted"] = True
        result["files"]["rrd"] = str(rrd) if rrd else None
        result["rrd_timing"] = {k: (round(v, 3) if isinstance(v, float) else v) for k, v in (
            ("helper", recorder.mode), ("prepared_before_end", recorder.prepared_in_time),
            ("finish_s", recorder.finish_s), ("wait_s", recorder.wait_s))}
        result["rrd_timing"]["live"] = (recorder.result or {}).get("live")
    atomic_write_json(out / "result.json", result)
    if interrupted:
        raise KeyboardInterrupt
    if failure:
        raise DaaSilError(failure)
    return result


# --------------------------------------------------------------------------------------------
# CLI

def _viz_available() -> bool:
    import importlib.util

    return importlib.util.find_spec("daa_sil.viz") is not None


def _add_common(p: argparse.ArgumentParser, default_out: str) -> None:
    p.add_argument("--out", default=default_out, metavar="DIR", help=f"output directory (default {default_out})")
    p.add_argument("--clock", choices=("lockstep", "realtime"), default="lockstep",
                   help="lockstep: as fast as the processes go, deterministic (default); realtime: wall clock x --speed")
    p.add_argument("--speed", type=float, default=1.0, metavar="X", help="realtime speed factor (default 1)")
    p.add_argument("--key", type=Path, metavar="FILE", help="MAVLink 2 signing key file (all three processes)")
    p.add_argument("--tap", metavar="udp:HOST:PORT",
                   help="also stream undelayed telemetry to an observer (QGC/MAVProxy), e.g. udp:127.0.0.1:14550")
    p.add_argument("--waitmap", default=None, metavar="PRESET|GRID|DIR",
                   help="the vehicle's wait maps, as in 'campaign run': alerting (default), paper, fine, a grid "
                        "spec or a 'waitmap build' directory")
    p.add_argument("--json", action="store_true", help="print result.json instead of the summary")
    if _viz_available():
        p.add_argument("--rrd", type=Path, metavar="FILE", help="write a Rerun recording")
        p.add_argument("--spawn-viewer", action="store_true", help="stream to a Rerun viewer it spawns")
        p.add_argument("--connect", metavar="URL",
                       help="stream to a running Rerun viewer, e.g. rerun+http://127.0.0.1:9876/proxy")
        p.add_argument("--viz-live", choices=("auto", "on", "off"), default="auto",
                       help="auto (default): with --clock realtime, every step appears in the viewer "
                            "(--spawn-viewer/--connect) as it happens (the vehicle sends each step's row to "
                            "the recorder over loopback, fire-and-forget); lockstep runs are shown when the "
                            "vehicle exits, so nothing runs next to the SIL. on: live in lockstep too; off: "
                            "never. The --rrd file is always made from the step log (the same either way)")


def register(sub) -> None:
    p = sub.add_parser("run", help="play a scenario through vehicle, delay shim and GCS processes",
                       description="Start daa-vehicle, the delay shim and daa-gcs as separate processes on "
                                   "free loopback ports, play SCENARIO, stop them and write DIR/result.json "
                                   "and DIR/steplog.parquet.",
                       epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scenario", type=Path, help="scenario YAML file (see docs/sil.md)")
    _add_common(p, "sil-out")
    p.set_defaults(func=run)
    d = sub.add_parser("demo", help="head-on encounter with a 4 s link delay through the real link",
                       description="The main job: a head-on encounter, 4 s link delay each way, remote-pilot "
                                   "model on the GCS, allocation agent with the MDP wait map on the vehicle, "
                                   "everything over MAVLink through the delay shim (lockstep).",
                       epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    _add_common(d, "demo-out")
    d.set_defaults(func=demo, scenario=None)


def _check_args(args) -> None:
    check_speed(args.speed)
    if args.key is not None and not args.key.is_file():
        raise UsageError(f"--key: key file {args.key} does not exist")
    if args.tap:
        from daa_sil.sil.endpoint import parse_udp_address

        parse_udp_address(args.tap, "--tap")
    if getattr(args, "connect", None):
        from ..viz import _url_host_port

        _url_host_port(args.connect)  # a malformed URL is a usage error; a missing viewer only a warning
    rrd = getattr(args, "rrd", None)
    if rrd is not None:
        if rrd.suffix != ".rrd":
            raise UsageError(f"--rrd {str(rrd)!r} should end in .rrd")
        from ..viz import check_rrd_path

        if rrd.is_dir():
            raise UsageError(f"--rrd {str(rrd)!r} is a directory, not an .rrd file path")
        if rrd.resolve().parent != Path(args.out).resolve():  # --out is created by the run
            check_rrd_path(rrd, overwrite=True)  # a missing/unwritable directory fails before any process starts
    if args.scenario is not None:
        from daa_sil.sil.scenario import load_scenario

        sc = load_scenario(args.scenario)  # fail fast, one line, before any process starts
        check_faults_allowed(sc, args.clock, args.scenario)


def _options(args, scenario: Path) -> RunOptions:
    quiet = args.json
    return RunOptions(scenario_path=scenario, out_dir=Path(args.out), clock=args.clock, speed=args.speed,
                      key=args.key, tap=args.tap, rrd=getattr(args, "rrd", None),
                      spawn_viewer=getattr(args, "spawn_viewer", False), connect=getattr(args, "connect", None),
                      viz_live=getattr(args, "viz_live", "auto"), waitmap=args.waitmap,
                      progress=None if quiet else (lambda m: print(f"daa-sil: {m}", file=sys.stderr, flush=True)))


def _finish(args, result: dict, sc) -> int:
    if args.json:
        from daa_sil.files import to_jsonable

        print(json.dumps(to_jsonable(result), indent=2, sort_keys=True))
    else:
        print(human_summary(result, sc, Path(args.out)))
        print(f"  wall {result['wall_s']:.1f} s for {result['duration_s']:.0f} s of sim time "
              f"({result['realtime_ratio']}x real time, clock {result['clock']})")
        if result["files"].get("rrd"):
            print(f"  Rerun recording: {result['files']['rrd']}  (open it with: rerun {result['files']['rrd']})")
    exp = result.get("expectation") or {}
    return 0 if exp.get("ok", True) else 1


def run(args) -> int:
    from daa_sil.files import ensure_dir
    from daa_sil.sil.scenario import load_scenario

    _check_args(args)
    ensure_dir(args.out)  # an unusable --out fails here, before the maps are built or anything starts
    prepare_waitmap(load_scenario(args.scenario), args.waitmap,
                    None if args.json else (lambda m: print(f"daa-sil: {m}", file=sys.stderr, flush=True)))
    result = run_sil(_options(args, args.scenario))
    return _finish(args, result, load_scenario(args.scenario))


def demo_scenario_path() -> Path:
    """The bundled demo scenario (``scenarios/head_on.yaml``)."""
    here = Path(__file__).resolve().parents[2] / "scenarios" / "head_on.yaml"
    if not here.is_file():
        raise UsageError(f"demo scenario {here} is missing (run from a source checkout)")
    return here


def demo(args) -> int:
    from daa_sil.files import ensure_dir
    from daa_sil.sil.scenario import load_scenario

    _check_args(args)
    path = demo_scenario_path()
    sc = load_scenario(path)
    if not args.json:
        print(f"daa-sil demo: {sc.description.strip().splitlines()[0]}", flush=True)
    ensure_dir(args.out)
    prepare_waitmap(sc, args.waitmap, None if args.json else (lambda m: print(f"daa-sil demo: {m}", flush=True)))
    result = run_sil(_options(args, path))
    if not args.json:
        print(_pilot_story(Path(args.out)))
    return _finish(args, result, sc)


def _waitmap_record(sc, source: "str | None") -> "dict | None":
    """What result.json records about the vehicle's wait maps (None when its policy reads no map)."""
    if sc.allocation.wait != "map":
        return None
    from .. import waitmap

    fam = waitmap.family_for(source, preset="paper")  # cached: loaded, not built
    return {"source": source or waitmap.DEFAULT_MAP, **waitmap.describe(fam)}


def prepare_waitmap(sc, source: "str | None", say: "Callable[[str], None] | None") -> None:
    """Build (or load) the vehicle's wait maps before any process starts, so the vehicle loads them
    from the cache; a bad ``--waitmap`` is a one-line usage error here. ``say`` gets progress lines."""
    if sc.allocation.wait != "map":
        return
    from .. import waitmap

    t = time.monotonic()
    if waitmap.is_cached(source, preset="paper"):
        say = None  # loaded in well under a second: nothing to report
    if say:
        say(f"loading the MDP wait maps ({source or waitmap.DEFAULT_MAP}; the first run builds and caches them) ...")
    progress = (lambda r: say(f"  built the {r:+g} deg/s map ({time.monotonic() - t:.0f} s)")) if say else None
    waitmap.family_for(source, preset="paper", progress=progress)
    if say:
        say(f"wait maps ready ({time.monotonic() - t:.1f} s)")


def _pilot_story(out_dir: Path) -> str:
    """One line on what the (model) pilot sent, from the GCS command log."""
    path = out_dir / "gcs_commands.jsonl"
    try:
        rows = [json.loads(x) for x in path.read_text().splitlines() if x.strip()]
    except (OSError, ValueError):
        return "  pilot: (no GCS command log)"
    if not rows:
        return "  pilot: sent no command"
    firsts, last = [], None
    for r in rows:
        key = (r.get("track_deg"), r.get("vs_mps"), r.get("gs_mps"))
        if key != last:
            firsts.append(r)
            last = key
    parts = []
    for r in firsts[:4]:
        what = ", ".join(f"{k} {r[k]:.0f}" for k in ("track_deg", "vs_mps", "gs_mps")
                         if isinstance(r.get(k), (int, float)))
        parts.append(f"t={r['t']:.0f}s {r.get('kind', 'cmd')} ({what})")
    return (f"  pilot: {len(rows)} command packets; " + "; ".join(parts)
            + (" ..." if len(firsts) > 4 else ""))
