"""``daa-vehicle SCENARIO``: the SIL vehicle process (ownship, intruders, onboard DAA + allocation agent).

Like a SITL autopilot it streams telemetry to a GCS at ``--out`` and takes pilot commands from
that link. It binds its sockets first and, while it prepares (a cold first start compiles the DAA
kernels and builds the wait maps), sends HEARTBEAT in MAV_STATE_BOOT, answers parameters and reports
its progress in STATUSTEXT. Prints ``READY listen=udp:HOST:PORT out=...`` once ready (orchestrators
read it), one progress line per 10 sim seconds unless ``--quiet``, and a one-line summary at the end.
It flies on past the scenario's last step until stopped, unless ``--exit-at-end``. Errors are one
line (``daa-vehicle: error: ...``, exit 2 for bad input, 1 for a failed run); Ctrl-C / SIGTERM write
the step log so far and exit 130 / 143.
"""

from __future__ import annotations

import argparse
import asyncio
import signal
import sys
from pathlib import Path

from daa_sil.cli import run_guarded
from daa_sil.commands.common_args import OneLineParser as _Parser, check_speed, load_key_option
from daa_sil.config.config_option import add_config_argument
from daa_sil.config.overrides import Overrides, add_flags
from daa_sil.config.run_config import load_config
from daa_sil.config.settings import GCS_PORT, udp
from daa_sil.errors import UsageError
from daa_sil.runtime.process_gc import freeze_after_startup
from daa_sil.errors import OutputError
import math
import numpy as np

EXAMPLES = """examples:
  # stream to a GCS (or MAVProxy/QGC) on 14550, real time
  daa-vehicle scenarios/head_on.yaml

  # behind the delay shim, lockstep (what `daa-sil run` does), with a step log
  daa-vehicle scenarios/head_on.yaml --out udp:127.0.0.1:14601 --clock lockstep --steplog run.parquet

  # each step's row to a local Rerun recorder as it happens (daa-sil run does this for live viewers)
  daa-vehicle scenarios/head_on.yaml --live udp:127.0.0.1:9870

  # the paper's own 72,000-state wait map instead of the default alerting-region map
  daa-vehicle scenarios/head_on.yaml --waitmap paper

  # 10x real time, undelayed truth copy for QGroundControl on 14550
  daa-vehicle scenarios/crossing_left.yaml --out udp:127.0.0.1:14601 --speed 10 --tap udp:127.0.0.1:14550

  # like SITL: listen on 14550 and stream to every GCS that spoke there in the last 5 s
  # (MAVProxy --master udpout:127.0.0.1:14550; restart it at will)
  daa-vehicle scenarios/head_on.yaml --out udpin:127.0.0.1:14550

  # a TCP server as SITL's 5760 (MAVProxy --master tcp:127.0.0.1:5760, QGC's TCP link), several clients
  # at once, each with its own rates; start the clock only once a GCS has spoken
  daa-vehicle scenarios/head_on.yaml --out tcpin:127.0.0.1:5760 --wait-gcs

  # the scenario only: exit after its last step (what daa-sil run does)
  daa-vehicle scenarios/head_on.yaml --exit-at-end

  # more ground stations, as SITL's --out: the shim (the pilot's link), QGC read-only on 14550,
  # a MAVProxy on 14560 that may also set parameters and modes (,rw; undelayed!)
  daa-vehicle scenarios/head_on.yaml --out udp:127.0.0.1:14601 --out udp:127.0.0.1:14550 --out udp:127.0.0.1:14560,rw

connection strings (as MAVProxy): udpin:HOST:PORT listens, udpout:HOST:PORT sends, a bare udp:HOST:PORT
listens for --listen and sends for --out / --tap; tcpin:HOST:PORT (--out only) serves TCP clients.

after the scenario: the vehicle flies on (the ownship on its last command or its plan, the intruders
straight on) until Ctrl-C; ADSB_VEHICLE sent to it on a writable output adds an intruder (daa-sil inject).

outputs: the first --out is the pilot's link (GCS or delay shim): pilot commands and settings travel
on it. Every further --out (and --tap) is an observer with its own stream rates that may read
parameters and ask for messages; it is read-only unless marked ,rw (then it may also set parameters
and modes). Pilot commands are taken from the first --out only (they must cross the delayed link).
"""


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="daa-vehicle", description=__doc__.splitlines()[0], epilog=EXAMPLES,
                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scenario", type=Path, help="scenario YAML file")
    p.add_argument("--out", action="append", default=None, metavar="CONN[,rw]",
                   help="repeatable. The first: the GCS (or delay shim) to stream to and take commands from "
                        "(default udp:127.0.0.1:14550); udpin:HOST:PORT listens there and answers every GCS heard "
                        "in the last 5 s; tcpin:HOST:PORT serves TCP clients. Each further one: an observer with its "
                        "own rates, read-only unless ,rw (see 'outputs' below)")
    p.add_argument("--listen", default=None, metavar="udp:HOST:PORT",
                   help="local socket (default udp:127.0.0.1:0 = OS-chosen port; not with --out udpin:)")
    p.add_argument("--tap", default=None, metavar="udp:HOST:PORT|none",
                   help="undelayed observer copy of the telemetry (QGC/MAVProxy); it may read parameters and "
                        "set its own rates, its pilot commands are ignored")
    p.add_argument("--tap-writable", action="store_true",
                   help="also apply parameter and mode writes from the tap (undelayed!); default: refused")
    p.add_argument("--clock", choices=("realtime", "lockstep"), default="realtime",
                   help="realtime (wall clock x --speed, default) or lockstep (SIM_TICK / SIM_TICK_ACK)")
    p.add_argument("--speed", type=float, default=1.0, metavar="X", help="realtime speed factor (default 1)")
    p.add_argument("--key", type=Path, metavar="FILE", help="MAVLink 2 signing key file")
    p.add_argument("--steplog", type=Path, metavar="FILE", help="write the step log (Parquet) here")
    p.add_argument("--tick-timeout", type=float, default=10.0, metavar="S",
                   help="lockstep: wall seconds to wait for a SIM_TICK_ACK (default 10)")
    p.add_argument("--start-timeout", type=float, default=None, metavar="S",
                   help="wall seconds to wait for the answer to tick 0, while the shim and GCS may still be "
                        "starting (default: --tick-timeout)")
    p.add_argument("--live", default=None, metavar="udp:127.0.0.1:PORT",
                   help="also send each step's step-log row, as soon as the step is done, to this loopback "
                        "port (the Rerun recorder of `daa-sil run`); fire-and-forget, never slows the loop")
    p.add_argument("--waitmap", default=None, metavar="PRESET|GRID|DIR",
                   help="wait maps: alerting (default), paper, fine, a grid spec or a 'waitmap build' directory "
                        "(built and cached on first use; the same lookup as 'campaign run --waitmap')")
    p.add_argument("--tick-sync", choices=("auto", "wait"), default="auto",
                   help="realtime: auto (default) = start at once and pace SIM_TICKs by the wall clock, waiting "
                        "for the shim's (or a direct GCS's) answer only if it gives them (a stock GCS does not); "
                        "wait = start the clock only once tick 0 is acknowledged (daa-sil run), so the run makes "
                        "the same decisions as lockstep")
    p.add_argument("--exit-at-end", action="store_true",
                   help="exit after the scenario's last step (default: fly on until stopped)")
    p.add_argument("--wait-gcs", action="store_true",
                   help="once ready, wait (MAV_STATE_STANDBY) for a ground station on the first --out before the "
                        "clock starts")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    add_config_argument(p)
    add_flags(p, "of the scenario's group (over the scenario's and --config's)")  # --wt, --projl-horizon, ...
    return p


def check_steplog_path(path: Path) -> None:
    """``--steplog``: a one-line usage error now, not after the whole flight, if it cannot be written
    (its directory is created if missing and probed with a file, as ``daa-sil run --out`` is)."""
    from daa_sil.files import check_output_path, ensure_dir  # lazy: start-up time

    try:  # name (UTF-8, length), kind, writable: before the flight, not after it
        check_output_path(path, "--steplog")
        ensure_dir(path.parent)
    except OutputError as exc:
        raise UsageError(f"--steplog {path}: {exc}") from None


def _options(args):
    from vehicle.node import VehicleOptions  # lazy: start-up time

    check_speed(args.speed)
    if not (math.isfinite(args.tick_timeout) and 0.1 <= args.tick_timeout <= 3600):
        raise UsageError(f"--tick-timeout must be within [0.1, 3600] s, got {args.tick_timeout:g}")
    if args.start_timeout is not None and not (math.isfinite(args.start_timeout) and 0.1 <= args.start_timeout <= 3600):
        raise UsageError(f"--start-timeout must be within [0.1, 3600] s, got {args.start_timeout:g}")
    key = load_key_option(args.key, "daa-vehicle")
    from daa_sil.sil.connstr import LISTEN, parse_connection  # lazy: start-up time

    from daa_sil.sil.outputs import output_specs  # lazy: start-up time

    tap = None if args.tap in (None, "", "none") else args.tap
    outs = args.out or [udp(GCS_PORT)]
    if args.tap_writable and tap is None:
        raise UsageError("--tap-writable needs --tap udp:HOST:PORT")
    specs = output_specs(outs, tap, args.tap_writable)  # one line for a malformed --out / --tap
    if args.listen is not None:
        parse_connection(args.listen, "--listen", LISTEN, allow=(LISTEN,))
        if specs[0].listens:
            raise UsageError(f"--out {outs[0]} already listens; drop --listen {args.listen}")
    if args.steplog is not None:
        check_steplog_path(args.steplog)
    live = None if args.live in (None, "", "none") else args.live
    if live is not None:
        from daa_sil.sil.live import parse_live_address  # lazy: start-up time

        parse_live_address(live)
    def clock_start(wall0: float) -> None:  # orchestrators time scheduled faults from this line
        print(f"CLOCK t0_monotonic={wall0:.6f} speed={args.speed:g}", flush=True)

    return VehicleOptions(out=outs[0], also_out=tuple(outs[1:]), listen=args.listen or "udp:127.0.0.1:0", tap=tap,
                          clock=args.clock,
                          speed=args.speed, key=key, steplog=args.steplog, tick_timeout_s=args.tick_timeout, live=live,
                          waitmap=args.waitmap, config=load_config(args.config) if args.config else None,
                          settings=Overrides.from_args(args),
                          tap_writable=args.tap_writable, start_timeout_s=args.start_timeout,
                          tick_sync=args.tick_sync, on_clock_start=clock_start, exit_at_end=args.exit_at_end,
                          wait_gcs=args.wait_gcs)


async def _amain(args) -> int:
    from daa_sil.sil.endpoint import format_udp_address  # lazy: start-up time
    from daa_sil.sil.scenario import load_scenario  # lazy: start-up time
    from vehicle.node import VehicleNode  # lazy: start-up time

    sc = load_scenario(args.scenario)
    opts = _options(args)
    if sc.faults:
        print(f"daa-vehicle: note: the scenario's faults ({'; '.join(f.describe() for f in sc.faults)}) are "
              f"carried out by `daa-sil run --clock realtime`, not by daa-vehicle", file=sys.stderr, flush=True)
    node = VehicleNode(sc, opts)
    await node.start()  # every socket bound first: a taken port is one line, before any work
    loop = asyncio.get_running_loop()
    task = asyncio.current_task()
    got = {}

    def on_signal(signum):
        got["sig"] = signum
        node.request_stop()  # also if the cancellation below is lost in a wait_for race
        task.cancel()

    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, on_signal, sig)
    out_text = node.bound_address(node.outputs[0]) if node.out.listens else format_udp_address(node.out.addr)
    observers = " ".join(f"{o.name}={node.bound_address(o)}{',rw' if o.spec.writable else ''}" for o in node.outputs[1:])
    end = {"told": False}

    def progress(nd, out):
        if not args.quiet and nd.k % 10 == 0:
            rng = np.asarray(out.geometry["range_m"][0], float)  # every intruder's horizontal range, m
            near = f"{np.min(rng):.0f}m" if rng.size and np.isfinite(rng).any() else "n/a"
            print(f"t={nd.t:5.0f}s authority={nd.core.last_authority:5s} decision={nd.core.last_decision} "
                  f"range={near}", flush=True)
        if not opts.exit_at_end and not end["told"] and nd.k >= nd.core.n_steps - 1:
            end["told"] = True
            print(f"daa-vehicle: t = {nd.t:g} s, the scenario's last step: flying on until stopped (Ctrl-C); "
                  f"--exit-at-end stops here", file=sys.stderr, flush=True)

    try:
        print(f"daa-vehicle: booting: listening ({node.local_address}, out={node.bound_address(node.outputs[0])}), "
              f"preparing the simulation", file=sys.stderr, flush=True)
        await node.prepare()  # beside the link: boot heartbeats, parameters, progress in STATUSTEXT
        freeze_after_startup()  # the start-up's objects stay out of the steps' collections
        print(f"READY listen={node.local_address} out={out_text} clock={opts.clock} "
              f"scenario={sc.name} steps={node.core.n_steps}" + (f" {observers}" if observers else ""), flush=True)
        await node.run(on_step=progress)
    except asyncio.CancelledError:
        path = node.write_steplog()
        node.close()
        sig = got.get("sig", signal.SIGINT)
        print(f"daa-vehicle: stopped by signal {sig} " + ("while booting" if node.core is None else f"at t = {node.t:g} s")
              + (f"; step log ({node.stats.steps} steps) in {path}" if path else ""), flush=True)
        return 128 + int(sig)
    except BaseException:
        node.write_steplog()
        node.close()
        raise
    path = node.write_steplog()
    st = {"dropped": node.dropped()}
    node.close()
    g = node.gate.counters
    print(f"daa-vehicle: done, {node.stats.steps} steps; commands accepted {g.accepted}, dropped "
          f"{g.duplicate + g.older + g.future + g.invalid} (dup {g.duplicate}, older {g.older}, future {g.future}, "
          f"invalid {g.invalid}); packets dropped {st['dropped']}"
          + (f"; live rows sent {node.live.stats.sent}, failed {node.live.stats.errors + node.live.stats.too_big}"
             if node.live is not None else "")
          + (f"; step log {path}" if path else ""), flush=True)
    if opts.clock == "realtime":
        v = node.stats
        print(f"daa-vehicle: realtime: ticks answered by {v.sync_partner}, steps run before their tick was "
              f"confirmed {v.steps_unconfirmed}, GCS acks late {v.acks_late}; step lateness mean {v.late_mean_ms:.1f} "
              f"ms, max {v.late_max_ms:.1f} ms", flush=True)
    for line in [ep.drops.summary() for ep in node.endpoints] + [node.guard.summary(), node.protocol.queue_summary()]:
        if line:
            print(f"daa-vehicle: {line}", flush=True)
    return 0


def main(argv: "list[str] | None" = None) -> int:
    args = build_parser().parse_args(argv)
    return run_guarded("daa-vehicle", lambda: asyncio.run(_amain(args)))
