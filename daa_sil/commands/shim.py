"""``daa-sil shim``: the UDP delay shim between a vehicle and a GCS (realtime or lockstep clock).

Also runnable alone as ``python -m daa_sil.commands.shim ARGS`` (the same arguments and behaviour):
``daa-sil run`` starts its shim that way, importing only what the shim needs (not every command's
modules, as ``daa-sil``'s parser does)."""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import signal
import sys

from ..errors import UsageError
from daa_sil.config.settings import DELAY_EPOCH, SHIM_GCS_PORT, SHIM_VEHICLE_PORT, udp
from daa_sil.models.delay_spec import SPEC_HELP, parse_delay_spec
from daa_sil.models.link_rule import link_legs
from daa_sil.sil.endpoint import format_udp_address
from daa_sil.sil.shim import run_shim
from daa_sil.sil.shim_config import CLOCKS, ShimConfig
from .common_args import finite_float, load_key_option
from .common_args import OneLineParser
from daa_sil.files import check_output_path

EXAMPLES = """examples:
  # paper group B-2/ID-2 delays, vehicle sends to 14601, GCS to 14602, peers learned
  daa-sil shim --delay gauss:5,3 --seed 7

  # asymmetric constant delays, 1 % loss, a 20 s outage, stats to a file
  daa-sil shim --vehicle udp:127.0.0.1:14600 --gcs udp:127.0.0.1:14550 \\
      --delay-up const:4 --delay-down const:2 --loss 0.01 --outage 60:80 --stats-json shim.json

  # the paper reading's rule: a Gaussian round trip (5 s, 3 s), each direction half of one draw
  daa-sil shim --delay-round-trip gauss:5,3 --seed 7

  # lockstep with the vehicle's SIM_TICK clock (CI runs), OS-chosen ports printed on stderr
  daa-sil shim --delay const:4 --clock lockstep --listen-vehicle udp:127.0.0.1:0 --listen-gcs udp:127.0.0.1:0

Delay specs: """ + SPEC_HELP + """. The delay process is piecewise constant per --epoch
seconds of sim time (0 = a new draw per datagram; that reorders traffic, so FIFO then inflates
the delay). "up" = GCS -> vehicle (pilot commands), "down" = vehicle -> GCS (telemetry).

Realtime: if the vehicle's first datagram is a SIM_TICK (daa-vehicle sends them), releases follow
the ticks exactly as in lockstep (same steps as a lockstep run; docs/sil.md "Realtime and
lockstep"); otherwise packets are released on the wall clock (kernel arrival stamps + timerfd).
Datagrams from an address that is not the learned peer are dropped with a warning on stderr.
Stops on Ctrl-C / SIGTERM (or after --duration) and prints its stats as JSON on stdout.
"""


def _outage(text: str) -> tuple[float, float]:
    a, sep, b = str(text).partition(":")
    try:
        lo, hi = float(a), float(b)
    except ValueError:
        raise UsageError(f"--outage must be START:END in sim seconds, got {text!r}") from None
    if not sep or not (lo < hi) or lo < 0:
        raise UsageError(f"--outage needs 0 <= START < END (s), got {text!r}")
    return lo, hi


DESCRIPTION = ("Relay MAVLink datagrams between a vehicle and a GCS with seeded per-direction delay, loss, "
               "duplication, reordering and outages; bytes are never modified.")


def register(sub) -> None:
    p = sub.add_parser("shim", help="UDP delay shim between vehicle and GCS (delay, loss, dup, outages)",
                       description=DESCRIPTION, epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_arguments(p)
    p.set_defaults(func=run)


def build_parser() -> argparse.ArgumentParser:
    """The shim's own parser (``python -m daa_sil.commands.shim``): the arguments of ``daa-sil shim``."""

    p = OneLineParser(prog="daa-sil shim", description=DESCRIPTION, epilog=EXAMPLES,
                      formatter_class=argparse.RawDescriptionHelpFormatter)
    add_arguments(p)
    return p


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Every ``daa-sil shim`` option on ``p``."""
    p.add_argument("--vehicle", metavar="udp:HOST:PORT", help="vehicle address (default: learned from its first datagram)")
    p.add_argument("--gcs", metavar="udp:HOST:PORT", help="GCS address (default: learned from its first datagram)")
    p.add_argument("--listen-vehicle", default=udp(SHIM_VEHICLE_PORT), metavar="udp:HOST:PORT",
                   help=f"socket the vehicle sends to (default {udp(SHIM_VEHICLE_PORT)}; port 0 = OS-chosen)")
    p.add_argument("--listen-gcs", default=udp(SHIM_GCS_PORT), metavar="udp:HOST:PORT",
                   help=f"socket the GCS sends to (default {udp(SHIM_GCS_PORT)})")
    p.add_argument("--delay", metavar="SPEC", help="one-way delay model for both directions")
    p.add_argument("--delay-up", metavar="SPEC", help="GCS -> vehicle delay (overrides --delay)")
    p.add_argument("--delay-down", metavar="SPEC", help="vehicle -> GCS delay (overrides --delay)")
    p.add_argument("--delay-round-trip", metavar="SPEC",
                   help="instead of --delay*: the round trip, split evenly (each direction half of one draw per "
                        "epoch; the paper reading's rule)")
    p.add_argument("--epoch", type=finite_float("--epoch", *DELAY_EPOCH.range), default=DELAY_EPOCH.default,
                   metavar="S", help=DELAY_EPOCH.flag_help())
    p.add_argument("--loss", type=finite_float("--loss", 0.0, 1.0), default=0.0, metavar="P", help="loss probability")
    p.add_argument("--dup", type=finite_float("--dup", 0.0, 1.0), default=0.0, metavar="P", help="duplication probability")
    p.add_argument("--reorder", type=finite_float("--reorder", 0.0, 1.0), default=0.0, metavar="P",
                   help="probability a datagram jumps the queue (released after half its delay); not with signing")
    p.add_argument("--outage", type=_outage, action="append", default=[], metavar="START:END",
                   help="drop everything sent in [START, END) sim s (repeatable)")
    p.add_argument("--seed", type=int, default=0, help="seed for delays and impairments (default 0)")
    p.add_argument("--clock", choices=CLOCKS, default="realtime", help="realtime (default) or lockstep (SIM_TICK)")
    p.add_argument("--speed", type=finite_float("--speed", 0.01, 1000.0), default=1.0,
                   help="realtime: sim seconds per wall second (default 1)")
    p.add_argument("--rt-priority", type=int, default=0, metavar="N",
                   help="realtime: run under SCHED_FIFO priority N (1-99; needs CAP_SYS_NICE) so a busy "
                        "machine does not delay releases; 0 = normal scheduling (default)")
    p.add_argument("--timing", choices=("precise", "poll"), default="precise",
                   help="realtime release timing: precise = kernel arrival stamps + timerfd wake-ups (default); "
                        "poll = stamp on read, call_at 2 ms early then poll the loop")
    p.add_argument("--key", metavar="FILE", help="signing key file to verify lockstep control messages")
    p.add_argument("--duration", type=finite_float("--duration", 0.0, 1e7), metavar="S",
                   help="stop after S wall seconds (default: run until Ctrl-C / SIGTERM)")
    p.add_argument("--stats-json", metavar="FILE", help="write the final stats JSON here (atomic)")


def config_from_args(args) -> ShimConfig:
    """Build and validate a :class:`ShimConfig` from parsed arguments."""
    rt = getattr(args, "delay_round_trip", None)
    if rt and (args.delay or args.delay_up or args.delay_down):
        raise UsageError("--delay-round-trip replaces --delay / --delay-up / --delay-down; give one form")
    up_spec = args.delay_up or args.delay
    down_spec = args.delay_down or args.delay
    if not rt and (not up_spec or not down_spec):
        raise UsageError("give --delay SPEC (or both --delay-up and --delay-down, or --delay-round-trip SPEC); "
                         "e.g. --delay const:4")
    if args.seed < 0:
        raise UsageError(f"--seed must be >= 0, got {args.seed}")
    if args.stats_json:
        check_output_path(args.stats_json, "--stats-json")  # name, length, UTF-8, writable: before binding
    if rt:
        legs = link_legs(parse_delay_spec(rt), "round-trip")
        up_model, down_model = legs.up, legs.down
    else:
        up_model, down_model = parse_delay_spec(up_spec), parse_delay_spec(down_spec)
    cfg = ShimConfig(delay_down=down_model, delay_up=up_model, round_trip=bool(rt),
                     listen_vehicle=args.listen_vehicle, listen_gcs=args.listen_gcs, vehicle=args.vehicle,
                     gcs=args.gcs, epoch_s=args.epoch, loss=args.loss, dup=args.dup, reorder=args.reorder,
                     outages=args.outage, seed=args.seed, clock=args.clock, speed=args.speed,
                     key=load_key_option(args.key), stats_json=args.stats_json,
                     timing=args.timing)
    cfg.validate()
    return cfg


async def _main(cfg: ShimConfig, duration: "float | None") -> dict:
    loop = asyncio.get_running_loop()
    stop = asyncio.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        try:
            loop.add_signal_handler(sig, stop.set)
        except (NotImplementedError, RuntimeError):  # non-main thread / platform without signals
            pass

    def ready(shim) -> None:
        print(f"daa-sil shim: vehicle side {format_udp_address(shim.vehicle_side)}, "
              f"gcs side {format_udp_address(shim.gcs_side)}, clock {cfg.clock}, "
              f"delay down {cfg.delay_down.spec()} up {cfg.delay_up.spec()}", file=sys.stderr, flush=True)

    return await run_shim(cfg, stop=stop, on_ready=ready, duration=duration)


def set_rt_priority(prio: int) -> bool:
    """Switch this process to SCHED_FIFO priority ``prio``; warn on stderr and return False if not allowed."""
    if not 1 <= prio <= 99:
        raise UsageError(f"--rt-priority must be within [1, 99] (0 = off), got {prio}")
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(prio))
    except (AttributeError, OSError) as exc:
        print(f"daa-sil shim: warning: cannot use SCHED_FIFO priority {prio} ({exc}); normal scheduling",
              file=sys.stderr)
        return False
    return True


def run(args) -> int:
    cfg = config_from_args(args)
    if args.rt_priority:
        set_rt_priority(args.rt_priority)
    stats = asyncio.run(_main(cfg, args.duration))
    print(json.dumps(stats, indent=2, sort_keys=True))
    return 0


def main(argv: "list[str] | None" = None) -> int:
    """``python -m daa_sil.commands.shim ARGS``: ``daa-sil shim ARGS`` without the other commands' imports."""
    from daa_sil.cli import run_guarded  # lazy: start-up time

    args = build_parser().parse_args(argv)
    return run_guarded("daa-sil", lambda: run(args))


if __name__ == "__main__":  # pragma: no cover - exercised through daa-sil run (tests/test_sil_run.py)
    from daa_sil.sil.children import exit_without_teardown

    exit_without_teardown(main())
