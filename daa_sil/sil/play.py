"""Playing a scenario through three processes (vehicle, delay shim, GCS).

Starts them on OS-chosen loopback ports, watches them (:mod:`daa_sil.sil.supervise`), carries out
the scenario's faults, stops them and writes ``DIR/result.json`` from the vehicle's step log. The
command ``daa-sil run`` (:mod:`daa_sil.commands.run`) is a thin shell around :func:`run_sil`.

Readiness: every child prints one ``READY key=value ...`` line on stdout once its sockets are
bound; the orchestrator reads the addresses from it (no guessed ports, no races). All child
output goes to ``DIR/logs/<name>.log``; the GCS's holds the pilot's display, one line per sim second
(:mod:`gcs.display`). The children die with the orchestrator, even on SIGKILL, and are called
``daa-vehicle``, ``daa-shim``, ``daa-gcs`` (:mod:`daa_sil.sil.children`).
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from daa_sil.errors import DaaSilError, UsageError
from daa_sil.sil.children import Interrupted, interrupt_signum, signal_name
from daa_sil.sil.prepare import prepare_kernels, prepare_waitmap  # noqa: F401 -- prepare_waitmap: run's API
from daa_sil.sil.run_files import rescued_steplog
from daa_sil.sil.summary import ProgressLine, gcs_ticks_skipped, realtime_report, summarize_steplog
from daa_sil.sil.supervise import (
    READY_TIMEOUT_S,
    ProcessGroup,
    RunMonitor,
    free_udp_ports,
    parse_shim_ready,
    python_module_argv,
)
import importlib
import threading

#: wall s the vehicle waits for the answer to tick 0 under ``daa-sil run`` (start-up on a busy machine)
START_TIMEOUT_S = 120.0


def shim_argv(sc, clock_args: list, key_args: list, stats_json: Path, vehicle_port: int = 0,
              gcs_port: int = 0) -> list[str]:
    """``daa-sil shim`` command line for scenario ``sc`` (link delays, loss, outages, seed), run as
    ``python -m daa_sil.commands.shim``: the shim's own entry point imports only what it needs."""
    from daa_sil.sil.scenario import delay_spec_string  # lazy: start-up time

    link = sc.link
    delays = (["--delay-round-trip", delay_spec_string(link.round_trip)] if link.round_trip is not None else
              ["--delay-up", delay_spec_string(link.up),
               "--delay-down", delay_spec_string(link.down if link.down is not None else link.up)])
    argv = python_module_argv("daa_sil.commands.shim") + [
        "--listen-vehicle", f"udp:127.0.0.1:{vehicle_port}", "--listen-gcs", f"udp:127.0.0.1:{gcs_port}",
        *delays, "--epoch", f"{link.epoch_s:g}", "--loss", f"{link.loss:g}", "--seed", str(sc.seed),
        "--dup", f"{link.dup:g}", "--reorder", f"{link.reorder:g}",
        "--stats-json", str(stats_json)]
    for o in link.outages:
        argv += ["--outage", f"{o.start_s:g}:{o.end_s:g}"]
    return argv + clock_args + key_args


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
    #: further ``daa-vehicle --out`` (observers, ``CONN[,rw]``: :mod:`daa_sil.sil.outputs`), after the shim's
    vehicle_outs: tuple = ()
    #: ``--waitmap`` of the vehicle: a map preset, grid spec or family directory (None = the default)
    waitmap: "str | None" = None
    #: ``--config`` of the vehicle and the GCS: a preset name or a YAML file (None = the scenario alone)
    config: "str | None" = None
    #: gets the run's progress lines for people (None = quiet): start, the vehicle's progress at a
    #: bounded rate (:class:`daa_sil.sil.summary.ProgressLine`), a failure
    progress: "Callable[[str], None] | None" = None


def _say(opts: RunOptions, msg: str) -> None:
    if opts.progress is not None:
        opts.progress(msg)


def run_sil(opts: RunOptions, scenario=None) -> dict:
    """Play ``opts.scenario_path`` through vehicle, shim and GCS processes; return the result dict.
    ``scenario``: that file's :class:`~daa_sil.sil.scenario.Scenario` if the caller loaded it already.

    Writes ``out_dir/result.json``, ``out_dir/steplog.parquet``, ``out_dir/gcs_commands.jsonl``
    and ``out_dir/logs/``. Raises DaaSilError if a process fails. Ctrl-C (and SIGTERM/SIGHUP under
    :func:`daa_sil.sil.children.signals_interrupt`) stops every child, summarises whatever step log
    exists without checking the expectation, and raises :class:`~daa_sil.sil.children.Interrupted`
    saying so.
    """
    from daa_sil.files import ensure_dir  # lazy: start-up time
    from daa_sil.sil.scenario import load_scenario  # lazy: start-up time

    sc = scenario if scenario is not None else load_scenario(opts.scenario_path)
    check_faults_allowed(sc, opts.clock, opts.scenario_path)
    if opts.vehicle_outs:  # a taken udpin: / tcpin: port: one line now, not after the vehicle started
        from daa_sil.sil.outputs import check_listening, output_specs  # lazy: start-up time

        check_listening(output_specs(["udp:127.0.0.1:1", *opts.vehicle_outs], option_of_extra="--vehicle-out")[1:],
                        "--vehicle-out")
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
    from daa_sil.viz.recorder import BackgroundRecorder  # lazy: start-up time

    from daa_sil.viz import SinkOptions  # lazy: start-up time

    try:
        return BackgroundRecorder(SinkOptions(rrd=opts.rrd, spawn=opts.spawn_viewer, connect=opts.connect,
                                              overwrite=True),
                                  preset=sc.thresholds, encounter_id=0,  # the vehicle logs encounter 0
                                  live=live_viz(opts), names=[i.callsign for i in sc.intruders])
    except OSError as exc:  # the helper process cannot start: the run goes on without a recording
        print(f"daa-sil: warning: cannot start the Rerun recorder ({exc.strerror or exc}); no recording",
              file=sys.stderr, flush=True)
        return None


def _finish_recorder(recorder, steplog: Path) -> "Path | None":
    """Hand the step log to the recorder; its warnings become ``daa-sil: warning: ...`` lines."""
    from daa_sil.viz.warning import one_line_warnings  # lazy: start-up time

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
        "--log", str(out / log_name)] + clock_args + key_args + (
        ["--config", str(opts.config)] if opts.config is not None else [])


def _preload(*modules: str) -> None:
    """Import ``modules`` (in order) in a daemon thread: while the vehicle is the only process still
    starting up, a core is free, and the end of the run then does not wait for the imports."""

    def load():
        for m in modules:
            importlib.import_module(m)

    threading.Thread(target=load, daemon=True, name=f"preload {', '.join(modules)}").start()


def _play(opts: RunOptions, sc, out: Path, steplog: Path, key_args: list, clock_args: list, recorder) -> dict:
    from daa_sil.files import atomic_write_json  # lazy: start-up time
    from daa_sil.out_dir import rescue_path, write_or_rescue  # lazy: start-up time

    prepare_kernels(lambda m: _say(opts, m))
    t0 = time.monotonic()
    t0_wall = time.time()
    interrupted: "KeyboardInterrupt | None" = None
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
                     *(a for o in opts.vehicle_outs for a in ("--out", o)),
                     "--steplog", str(steplog), "--tap", opts.tap or "none",
                     "--tick-timeout", f"{opts.tick_timeout_s:g}",
                     # tick 0: the GCS may still be starting (the monitor below notices a dead one at once)
                     "--start-timeout", f"{max(opts.tick_timeout_s, START_TIMEOUT_S):g}"] + clock_args + key_args
            vargs.append("--exit-at-end")  # the run is the scenario (a standalone vehicle flies on)
            if opts.clock == "realtime":
                vargs += ["--tick-sync", "wait"]  # start once tick 0 is acked: the GCS plays from step 0
            if opts.waitmap is not None:
                vargs += ["--waitmap", str(opts.waitmap)]
            if opts.config is not None:
                vargs += ["--config", str(opts.config)]
            if recorder is not None and recorder.live_address:
                vargs += ["--live", recorder.live_address]  # each step's row, fire-and-forget
            # GCS and vehicle start in parallel; the vehicle re-sends tick 0 until the GCS answers
            vehicle = pg.start("vehicle", python_module_argv("vehicle") + vargs)
            pg.wait_ready(shim)
            pg.wait_ready(gcs)
            # pyarrow, for the step log at the end (pyarrow.compute: its legacy-name check, ~50 ms), while
            # only the vehicle starts
            _preload("daa_sil.steplog", "pyarrow.compute")
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
                                                log_name=log), process_name=f"daa-{fault.process}")

            progress = ProgressLine(opts.progress, sc.duration_s) if opts.progress is not None else None
            monitor = RunMonitor(vehicle, {"shim": shim, "gcs": gcs}, faults=sc.faults, restart=restart,
                                 progress=progress)
            failure = monitor.wait()
            exited = time.monotonic()
            if failure is not None:
                _say(opts, f"stopping the run: {failure}")
            rc = vehicle.proc.poll()
            if recorder is not None and rc == 0 and steplog.exists():
                # logs (deferred) or completes (live) while the shim and GCS are stopped and the result is made
                recorder.submit(steplog, vehicle_exit=exited)
        except KeyboardInterrupt as exc:
            interrupted = exc
    wall = time.monotonic() - t0
    rescued = rescued_steplog(steplog, t0_wall)
    if rescued is not None:  # the vehicle could not write into --out any more: it saved the log elsewhere
        steplog = rescued
    if not steplog.exists():
        if interrupted is not None:
            raise Interrupted(interrupt_signum(interrupted), "before the vehicle wrote a step log")
        raise DaaSilError(failure or f"the vehicle wrote no step log (logs: {out / 'logs'})")
    from daa_sil.steplog import read_steplog  # lazy: start-up time; pyarrow: imported while the vehicle started (_preload)

    table = read_steplog(steplog)
    result = summarize_steplog(table, sc)
    if interrupted is not None or failure is not None:
        # a run cut short says nothing about the scenario's expected outcome
        why = (f"interrupted by {signal_name(interrupt_signum(interrupted))}" if interrupted is not None
               else "the run failed")
        result["expectation"] = {"checked": False, "ok": None, "violations": [],
                                 "reason": f"{why} at t = {result['duration_s']:g} s of {sc.duration_s:g} s"}
    result.update({"scenario": sc.name, "scenario_file": str(opts.scenario_path), "seed": sc.seed,
                   "preset": sc.thresholds, "clock": opts.clock, "wall_s": round(wall, 3),
                   "waitmap": _waitmap_record(sc, opts.waitmap, steplog),
                   "realtime_ratio": round(result["duration_s"] / wall, 2) if wall > 0 else None,
                   "interrupted": interrupted is not None,
                   "interrupted_by": signal_name(interrupt_signum(interrupted)) if interrupted is not None else None,
                   "failure": failure,
                   "process_died": monitor.death if monitor is not None else None,
                   "files": {"steplog": str(steplog), "gcs_log": str(out / "gcs_commands.jsonl"),
                             "gcs_logs": [str(x) for x in gcs_logs if x.is_file()], "logs": str(out / "logs")}})
    from daa_sil.steplog import steplog_metadata  # lazy: start-up time

    try:  # the full configuration the vehicle flew (its step-log metadata)
        result["config"] = json.loads(steplog_metadata(steplog).get("config") or "null")
    except ValueError:
        result["config"] = None
    if sc.faults:
        result["faults"] = monitor.fault_report() if monitor is not None else []
    if opts.clock == "realtime":
        from daa_sil.steplog import steplog_metadata  # lazy: start-up time

        shim_stats = None
        try:
            shim_stats = json.loads((out / "shim_stats.json").read_text())
        except (OSError, ValueError):
            pass
        result["realtime"] = realtime_report(steplog_metadata(steplog), shim_stats,
                                             gcs_ticks_skipped(out / "logs" / "gcs.log"))
    if recorder is not None:
        # also after Ctrl-C: the partial step log becomes a complete, readable recording (a second
        # Ctrl-C aborts it and no .rrd is written)
        try:
            rrd = _finish_recorder(recorder, steplog)
        except KeyboardInterrupt as exc:
            rrd, interrupted = None, exc
            result["interrupted"] = True
            result["interrupted_by"] = signal_name(interrupt_signum(exc))
        result["files"]["rrd"] = str(rrd) if rrd else None
        result["rrd_timing"] = {k: (round(v, 3) if isinstance(v, float) else v) for k, v in (
            ("helper", recorder.mode), ("prepared_before_end", recorder.prepared_in_time),
            ("finish_s", recorder.finish_s), ("wait_s", recorder.wait_s))}
        result["rrd_timing"]["live"] = (recorder.result or {}).get("live")
    if rescued is not None:
        result["rescued"] = {"steplog": str(steplog), "result": str(rescue_path(out / "result.json")),
                             "reason": f"{out} could not be written when the run ended"}
    summary_path = write_or_rescue(out / "result.json", lambda p: atomic_write_json(p, result), "summary",
                                   say=False)  # the run's last line says where
    if summary_path != out / "result.json" and "rescued" not in result:
        result["rescued"] = {"steplog": None, "result": str(summary_path),
                             "reason": f"{out} could not be written when the run ended"}
    if interrupted is not None:
        when = (f"at t = {result['duration_s']:g} s of {sc.duration_s:g} s; the expected outcome was not checked"
                if not result["expectation"]["checked"]
                else "while the Rerun recording was written (the run itself was complete)")
        raise Interrupted(interrupt_signum(interrupted),
                          f"{when}; {result['steps']} steps in {steplog}, summary in {summary_path}")
    if failure:
        raise DaaSilError(failure)
    return result


def _waitmap_record(sc, source: "str | None", steplog: Path) -> "dict | None":
    """What result.json records about the vehicle's wait maps (None when its policy reads no map):
    the description the vehicle wrote into its step log's metadata from the family it loaded and
    verified (``waitmap.describe``), so the maps are not loaded again here. A step log without it
    (not written by this vehicle) falls back to loading the family."""
    if sc.allocation.wait != "map":
        return None
    from daa_sil import waitmap  # lazy: start-up time
    from daa_sil.steplog import steplog_metadata  # lazy: start-up time

    try:
        described = json.loads(steplog_metadata(steplog).get("waitmap") or "null")
    except ValueError:
        described = None
    from daa_sil.config.run_config import default_wait_maps  # lazy: start-up time

    source, horizon = (source, None) if source else default_wait_maps()  # the vehicle's, when none is named
    if not isinstance(described, dict):  # cached: loaded, not built
        described = waitmap.describe(waitmap.family_for(source, preset="paper", horizon=horizon))
    return {"source": source, **described}

