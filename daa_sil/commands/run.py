"""``daa-sil run SCENARIO`` and ``daa-sil demo``: the three-process SIL (vehicle, shim, GCS).

The orchestrator starts ``daa-vehicle``, the delay shim and ``daa-gcs`` as **separate processes**
(each in its own process group, named ``daa-vehicle``, ``daa-shim``, ``daa-gcs``, each dying with
the orchestrator even on SIGKILL) on OS-chosen loopback ports, plays the encounter, stops them
(SIGINT, then SIGTERM, then SIGKILL, each with a timeout; also on Ctrl-C, SIGTERM and SIGHUP, so no
orphans), and summarises the vehicle's step log into ``DIR/result.json``.

The orchestration lives in :mod:`daa_sil.sil.play` (processes) and :mod:`daa_sil.sil.summary`
(result); this module is the command line.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

from daa_sil.config.config_option import add_config_argument, config_of
from daa_sil.errors import OutputError, UsageError
from .common_args import add_allow_large, check_speed, load_key_option, stdout_may_close
from daa_sil.sil.children import interruptible
from daa_sil.sil.summary import PROGRESS_EVERY_S, demo_legend, human_summary, pilot_story
from daa_sil.sil.play import RunOptions, check_faults_allowed, prepare_waitmap, run_sil
from daa_sil.sil.run_files import remove_run_outputs
from daa_sil.files import check_output_path
from daa_sil.out_dir import check_not_busy, claim_out_dir
import importlib.util
from daa_sil.files import to_jsonable


EXAMPLES = """examples:
  # the main job: a head-on encounter, 4 s link delay, through the real link (lockstep)
  daa-sil demo --out demo-out

  # any scenario file, deterministic and fast (lockstep), result as JSON
  daa-sil run scenarios/head_on.yaml --out runs/head_on --json

  # the same in real time at 10x speed
  daa-sil run scenarios/crossing_left.yaml --clock realtime --speed 10

  # two ground stations watching the vehicle undelayed: QGC on 14550 (read-only) and a MAVProxy on
  # 14560 that may also set parameters (,rw); pilot commands still come only through the delayed link
  daa-sil run scenarios/head_on.yaml --clock realtime --vehicle-out udp:127.0.0.1:14550 --vehicle-out udp:127.0.0.1:14560,rw

  # watch it in Rerun step by step as it plays (a viewer it spawns, or one already running)
  daa-sil run scenarios/head_on.yaml --clock realtime --speed 4 --spawn-viewer --rrd head_on.rrd
  daa-sil run scenarios/head_on.yaml --clock realtime --connect rerun+http://127.0.0.1:9876/proxy

  # no display: serve the finished run in the web viewer (http://127.0.0.1:9090) until Ctrl-C
  daa-sil run scenarios/head_on.yaml --serve-web

Rerun: realtime runs with --spawn-viewer/--connect show every step in the viewer as it happens;
lockstep runs are logged from the step log when the vehicle exits, so nothing runs next to the SIL
(--viz-live). An --rrd file is always written from the step log at the end.

While it plays, a progress line (sim time, authority, decision, nearest intruder) comes at most
every {every:g} s of wall time (--quiet: none). The processes are called daa-vehicle, daa-shim and daa-gcs
(`pgrep daa-gcs`) and die with the run, also when it is killed.

Exit status: 0 = the run matched the scenario's `expect:` block, 1 = an expectation was violated
or a process failed, 2 = bad input, 130 = interrupted by Ctrl-C, 143 = by SIGTERM, 129 = by SIGHUP
(the step log so far is still written; the expectation is not checked).
""".format(every=PROGRESS_EVERY_S)


# --------------------------------------------------------------------------------------------
# result summary (pure: step log table -> result dict)


# --------------------------------------------------------------------------------------------
# the run


# --------------------------------------------------------------------------------------------
# CLI

def _viz_available() -> bool:
    return importlib.util.find_spec("daa_sil.viz") is not None


def _add_common(p: argparse.ArgumentParser, default_out: str) -> None:
    p.add_argument("--out", default=default_out, metavar="DIR",
                   help=f"output directory (default {default_out}); held by this run while it writes, refused when "
                        "another run holds it or it is not empty (see --force). MAVLink outputs (udp:..., tcpin:...) "
                        "go to --vehicle-out")
    p.add_argument("--force", action="store_true",
                   help="replace a previous run's outputs in a non-empty --out (result.json, the step log, the logs)")
    add_allow_large(p, "building the --waitmap grid on first use")
    p.add_argument("--clock", choices=("lockstep", "realtime"), default="lockstep",
                   help="lockstep: as fast as the processes go, deterministic (default); realtime: wall clock x --speed")
    p.add_argument("--speed", type=float, default=1.0, metavar="X", help="realtime speed factor (default 1)")
    p.add_argument("--key", type=Path, metavar="FILE", help="MAVLink 2 signing key file (all three processes)")
    p.add_argument("--tap", metavar="udp:HOST:PORT",
                   help="also stream undelayed telemetry to an observer (QGC/MAVProxy), e.g. udp:127.0.0.1:14550")
    p.add_argument("--vehicle-out", action="append", default=[], metavar="CONN[,rw]", dest="vehicle_outs",
                   help="repeatable: a further output of daa-vehicle (its --out after the shim's), e.g. a ground "
                        "station: undelayed telemetry with its own rates, read-only unless ,rw (then it may set "
                        "parameters and modes); udpin:HOST:PORT listens there (see daa-vehicle --help)")
    p.add_argument("--waitmap", default=None, metavar="PRESET|GRID|DIR",
                   help="the vehicle's wait maps, as in 'campaign run': alerting (default), paper, fine, a grid "
                        "spec or a 'waitmap build' directory")
    p.add_argument("--json", action="store_true", help="print result.json instead of the summary (implies --quiet)")
    p.add_argument("--quiet", action="store_true", help="no progress lines on stderr while it plays")
    add_config_argument(p)
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
        from daa_sil.sil.web_ports import add_web_viewer_arguments  # lazy: start-up time

        add_web_viewer_arguments(p, "when the run ends, serve its recording in the Rerun web viewer until "
                                    "Ctrl-C (as 'viz steplog --serve-web'; no display needed)")


def register(sub) -> None:
    p = sub.add_parser("run", help="play a scenario through vehicle, delay shim and GCS processes",
                       description="Start daa-vehicle, the delay shim and daa-gcs as separate processes on "
                                   "free loopback ports, play SCENARIO, stop them and write DIR/result.json "
                                   "and DIR/steplog.parquet.",
                       epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scenario", type=Path, help="scenario YAML file (see docs/sil.md)")
    _add_common(p, "sil-out")
    p.set_defaults(func=interruptible(run))  # SIGTERM / SIGHUP stop it as Ctrl-C does
    d = sub.add_parser("demo", help="head-on encounter with a 4 s link delay through the real link",
                       description="The main job: a head-on encounter, 4 s link delay each way, remote-pilot "
                                   "model on the GCS, allocation agent with the MDP wait map on the vehicle, "
                                   "everything over MAVLink through the delay shim (lockstep).",
                       epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    _add_common(d, "demo-out")
    d.set_defaults(func=interruptible(demo), scenario=None)


#: connection strings of MAVLink tools (pymavlink / MAVProxy / SITL): an ``--out`` starting so is one
MAVLINK_SCHEMES = ("udp", "udpin", "udpout", "udpbcast", "tcp", "tcpin", "serial", "mcast", "ws", "wss", "wsserver")
_MAVLINK = re.compile(rf"^(?:{'|'.join(MAVLINK_SCHEMES)}):", re.IGNORECASE)


def check_out_option(out: str) -> Path:
    """``--out`` of ``run``/``demo`` before anything runs: a MAVLink connection string is refused in
    one line pointing at ``--vehicle-out`` (exit 2); otherwise the directory is checked as every output
    is (:func:`daa_sil.files.check_output_path`). Creates nothing."""
    text = str(out)
    if _MAVLINK.match(text):
        raise UsageError(f"--out {text!r} looks like a MAVLink connection, but --out of 'daa-sil run' is the output "
                         f"directory; send the vehicle's MAVLink to a ground station with --vehicle-out {text} "
                         f"(for a directory of that name, write ./{text})")
    return check_output_path(text, "--out", directory=True)


def _check_args(args):
    """Every check that can fail before a process starts (one line, exit 2); returns the scenario of
    ``args.scenario`` loaded (None without one: the demo's)."""
    check_out_option(args.out)
    check_not_busy(args.out)
    check_speed(args.speed)
    if args.config:
        config_of(args.config)  # a bad file fails here, one line, before any process starts
    if args.key is not None:
        if not args.key.is_file():
            raise UsageError(f"--key: key file {args.key} does not exist")
        load_key_option(args.key)  # a bad key file fails here (one line), its warnings show once
    if args.tap:
        from daa_sil.sil.endpoint import parse_udp_address  # lazy: start-up time

        parse_udp_address(args.tap, "--tap")
    if args.vehicle_outs:
        from daa_sil.sil.outputs import check_listening, output_specs  # lazy: start-up time

        # the shim's side is the vehicle's first --out; these follow it (a malformed one: one line, exit 2)
        specs = output_specs(["udp:127.0.0.1:1", *args.vehicle_outs], args.tap, option_of_extra="--vehicle-out")
        check_listening(specs[1:], "--vehicle-out")  # a taken udpin: / tcpin: port: now, not after the vehicle started
    if getattr(args, "connect", None):
        from ..viz import url_host_port  # lazy: start-up time

        url_host_port(args.connect)  # a malformed URL is a usage error; a missing viewer only a warning
    if hasattr(args, "serve_web"):
        from daa_sil.sil.web_ports import check_web_viewer_arguments  # lazy: start-up time

        check_web_viewer_arguments(args)  # a taken port fails before the run
    rrd = getattr(args, "rrd", None)
    if rrd is not None:
        if rrd.suffix != ".rrd":
            raise UsageError(f"--rrd {str(rrd)!r} should end in .rrd")
        from ..viz import check_rrd_path  # lazy: start-up time

        check_output_path(rrd, "--rrd")  # name, length, UTF-8; a directory: one line
        if rrd.resolve().parent != Path(args.out).resolve():  # --out is created by the run
            check_rrd_path(rrd, overwrite=True)  # a missing/unwritable directory fails before any process starts
    if args.scenario is None:
        return None
    from daa_sil.sil.scenario import load_scenario  # lazy: start-up time

    sc = load_scenario(args.scenario)  # fail fast, one line, before any process starts
    check_faults_allowed(sc, args.clock, args.scenario)
    return sc


def _waitmap_source(args) -> "str | None":
    """``--waitmap``, else the wait maps of the ``--config``'s reading, else None (the vehicle's
    default: the study's default reading's maps)."""
    if args.waitmap is not None:
        return args.waitmap
    return config_of(args.config).map_source if args.config else None


def _options(args, scenario: Path) -> RunOptions:
    return RunOptions(scenario_path=scenario, out_dir=Path(args.out), clock=args.clock, speed=args.speed,
                      key=args.key, tap=args.tap, vehicle_outs=tuple(args.vehicle_outs), rrd=getattr(args, "rrd", None),
                      spawn_viewer=getattr(args, "spawn_viewer", False), connect=getattr(args, "connect", None),
                      viz_live=getattr(args, "viz_live", "auto"), waitmap=_waitmap_source(args),
                      config=args.config,
                      progress=_say("daa-sil", args))


def _finish(args, result: dict, sc, legend: "str | None" = None) -> int:
    if args.json:
        print(json.dumps(to_jsonable(result), indent=2, sort_keys=True))
    else:
        print(human_summary(result, sc, Path(args.out)))
        print(f"  wall {result['wall_s']:.1f} s for {result['duration_s']:.0f} s of sim time "
              f"({result['realtime_ratio']}x real time, clock {result['clock']})")
        if result["files"].get("rrd"):
            print(f"  Rerun recording: {result['files']['rrd']}  (open it with: rerun {result['files']['rrd']})")
        if legend:
            print(legend)
    exp = result.get("expectation") or {}
    rc = 0 if exp.get("ok", True) is True else 1
    saved = result.get("rescued")
    if saved:  # the run is complete, but not where it was asked to be
        where = " and ".join(f"{what} in {path}" for what, path in (("the step log", saved["steplog"]),
                                                                   ("result.json", saved["result"])) if path)
        raise OutputError(f"{saved['reason']}; {where}")
    if getattr(args, "serve_web", False):
        _serve_web(args, result)
    return rc


def _serve_web(args, result: dict) -> None:
    """``--serve-web``: the run's step log in the Rerun web viewer until Ctrl-C (as ``viz steplog``)."""
    from daa_sil.steplog import read_steplog  # lazy: start-up time
    from daa_sil.viz import SinkOptions, log_steplog  # lazy: start-up time
    from daa_sil.viz.warning import one_line_warnings  # lazy: start-up time

    sinks = SinkOptions(serve_web=True, bind=args.bind, web_port=args.web_port, grpc_port=args.grpc_port)
    with one_line_warnings():
        _, logger = log_steplog(read_steplog(result["files"]["steplog"]), sinks, preset=result["preset"],
                                keep_serving=True)
    if logger.web is None or not logger.web.alive():
        raise OutputError(f"--serve-web: the Rerun web viewer did not start on {args.bind} "
                          f"(ports {args.web_port}, {args.grpc_port})")
    logger.wait_serving(announce=lambda: print(f"web viewer: {logger.web.url}  (Ctrl-C to stop)",
                                               file=sys.stderr if args.json else sys.stdout, flush=True))


def _say(prefix: str, args):
    """Progress lines on stderr (None with --json / --quiet)."""
    if args.json or args.quiet:
        return None
    return lambda m: print(f"{prefix}: {m}", file=sys.stderr, flush=True)


def _claim(args):
    """Hold ``--out`` for this run (:func:`daa_sil.out_dir.claim_out_dir`; ``--force`` replaces a
    previous run's outputs there)."""
    return claim_out_dir(args.out, replace=remove_run_outputs if args.force else None,
                         hint="pass --force to replace the run in it, or choose a new directory")


def run(args) -> int:
    sc = _check_args(args)  # (loaded once here, and handed on)
    with _claim(args), stdout_may_close("daa-sil", args.out):  # an unusable --out fails here, before anything starts
        prepare_waitmap(sc, _waitmap_source(args), _say("daa-sil", args), allow_large=args.allow_large)
        result = run_sil(_options(args, args.scenario), scenario=sc)
        return _finish(args, result, sc)


def demo_scenario_path() -> Path:
    """The bundled demo scenario (``scenarios/head_on.yaml``)."""
    here = Path(__file__).resolve().parents[2] / "scenarios" / "head_on.yaml"
    if not here.is_file():
        raise UsageError(f"demo scenario {here} is missing (run from a source checkout)")
    return here


def demo(args) -> int:
    from daa_sil.sil.scenario import load_scenario  # lazy: start-up time

    _check_args(args)
    path = demo_scenario_path()
    sc = load_scenario(path)
    with _claim(args), stdout_may_close("daa-sil demo", args.out):
        if not args.json:
            print(f"daa-sil demo: {sc.description.strip().splitlines()[0]}", flush=True)
        say = _say("daa-sil demo", args)
        prepare_waitmap(sc, _waitmap_source(args), say and (lambda m: print(f"daa-sil demo: {m}", flush=True)),
                        allow_large=args.allow_large)
        result = run_sil(_options(args, path), scenario=sc)
        if not args.json:
            print(pilot_story(Path(args.out)))
        return _finish(args, result, sc, legend=demo_legend(result, sc, Path(args.out)))


