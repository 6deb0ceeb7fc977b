"""``daa-gcs``: the SIL ground station: shows the delayed telemetry and flies the pilot model or a script.

Prints ``READY listen=udp:HOST:PORT vehicle=...`` once bound. Runs until Ctrl-C / SIGTERM (exit 130 /
143, as ``daa-vehicle``) or ``--duration`` wall seconds (exit 0), then writes its command log (JSONL,
atomic). Errors are one line (``daa-gcs: error: ...``, exit 2 for bad input).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import signal
from pathlib import Path

from daa_sil.cli import run_guarded
from daa_sil.commands.common_args import OneLineParser as _Parser, check_speed, load_key_option
from daa_sil.config.config_option import add_config_argument, config_of
from daa_sil.errors import UsageError
from daa_sil.runtime.process_gc import freeze_after_startup
import math
import re

EXAMPLES = """examples:
  # pilot model of the scenario, vehicle directly on 14550 (realtime)
  daa-gcs --listen udp:127.0.0.1:14550 --vehicle udp:127.0.0.1:14600 --scenario scenarios/head_on.yaml

  # behind the delay shim's GCS side, lockstep, scripted pilot, command log
  daa-gcs --vehicle udp:127.0.0.1:14602 --scenario scenarios/pilot_unsafe_blend.yaml --pilot scripted \\
      --clock lockstep --log gcs.jsonl

  # the pilot raises W_T to 6 s at t = 30 s and switches the onboard agent off at t = 90 s (through the link)
  daa-gcs --vehicle udp:127.0.0.1:14602 --scenario scenarios/head_on.yaml --set 30:DAA_WT=6 --set 90:DAA_ENABLE=0

  # ask for GUIDED at t = 60 s: accepted whoever flies (the agent still judges every pilot command and
  # the heartbeat shows who flies); a mode never switches the agent off (DAA_ENABLE does)
  daa-gcs --vehicle udp:127.0.0.1:14602 --scenario scenarios/head_on.yaml --set 60:MODE=GUIDED

connection strings (as MAVProxy): udpin:HOST:PORT listens, udpout:HOST:PORT sends; a bare udp:HOST:PORT
listens for --listen and sends for --vehicle.
"""


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="daa-gcs", description=__doc__.splitlines()[0], epilog=EXAMPLES,
                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--listen", default=None, metavar="udp:HOST:PORT",
                   help="local socket (default udp:127.0.0.1:14550; port 0 = OS-chosen; not with --vehicle udpin:)")
    p.add_argument("--vehicle", default="udp:127.0.0.1:14602", metavar="udp:HOST:PORT",
                   help="vehicle, or the delay shim's GCS side, to send to (default udp:127.0.0.1:14602); "
                        "udpin:HOST:PORT listens there instead and answers whoever sends first")
    p.add_argument("--set", action="append", default=[], metavar="T:NAME=VALUE", dest="settings",
                   help="at sim time T (s) send PARAM_SET NAME VALUE (e.g. 30:DAA_WT=6), or with NAME MODE a "
                        "DO_SET_MODE (30:MODE=GUIDED, AVOID_ADSB or a mode number); repeatable")
    p.add_argument("--scenario", type=Path, metavar="FILE",
                   help="scenario file: origin, intruder order, pilot model settings / scripted commands")
    p.add_argument("--pilot", choices=("model", "scripted"), help="override the scenario's pilot mode")
    p.add_argument("--clock", choices=("realtime", "lockstep"), default="realtime")
    p.add_argument("--speed", type=float, default=1.0, metavar="X", help="realtime speed factor (default 1)")
    p.add_argument("--key", type=Path, metavar="FILE", help="MAVLink 2 signing key file")
    p.add_argument("--log", type=Path, metavar="FILE", help="write the commands sent as JSONL here")
    p.add_argument("--no-display", action="store_true", help="no per-second console line")
    p.add_argument("--duration", type=float, metavar="S", help="stop after S wall seconds")
    add_config_argument(p)
    return p


def parse_setting(text: str) -> "ScheduledSetting":
    """``"30:DAA_WT=6"`` -> ``(30.0, "DAA_WT", 6.0)``; ``"90:MODE=GUIDED"`` -> ``(90.0, "MODE", 15.0)``."""

    from daa_sil.link.plane import PLANE_MODES  # lazy: start-up time
    from gcs.pilot import ScheduledSetting  # lazy: start-up time

    m = re.fullmatch(r"\s*([^:]+):([A-Za-z0-9_]{1,16})=(\S+)\s*", str(text))
    if m is None:
        raise UsageError(f"--set must look like T:NAME=VALUE (e.g. 30:DAA_WT=6), got {text!r}")
    try:
        t = float(m.group(1))
    except ValueError:
        t = math.nan
    if not (math.isfinite(t) and t >= 0):
        raise UsageError(f"--set {text!r}: T must be a sim time >= 0 s, got {m.group(1)!r}")
    name, raw = m.group(2).upper(), m.group(3)
    if name == "MODE":
        by_name = {v: k for k, v in PLANE_MODES.items()}
        if raw.upper() in by_name:
            return ScheduledSetting(t, name, float(by_name[raw.upper()]))
        if raw.isdigit():
            return ScheduledSetting(t, name, float(int(raw)))
        raise UsageError(f"--set {text!r}: unknown mode {raw!r}; the vehicle takes GUIDED or AVOID_ADSB")
    try:
        value = float(raw)
    except ValueError:
        raise UsageError(f"--set {text!r}: VALUE must be a number, got {raw!r}") from None
    return ScheduledSetting(t, name, value)


async def _amain(args) -> int:
    from daa_sil.sil.scenario import load_scenario  # lazy: start-up time
    from gcs.node import GcsNode, GcsOptions  # lazy: start-up time

    check_speed(args.speed)
    sc = load_scenario(args.scenario) if args.scenario else None
    if sc is None and args.pilot != "scripted":
        raise UsageError("give --scenario FILE (pilot model settings, origin); without it only --pilot scripted "
                         "with no commands is possible")
    key = load_key_option(args.key, "daa-gcs")
    from daa_sil.sil.connstr import LISTEN, SEND, parse_connection  # lazy: start-up time

    vconn = parse_connection(args.vehicle, "--vehicle", SEND)
    if args.listen is not None:
        parse_connection(args.listen, "--listen", LISTEN, allow=(LISTEN,))
        if vconn.listens:
            raise UsageError(f"--vehicle {args.vehicle} already listens; drop --listen {args.listen}")
    settings = tuple(parse_setting(x) for x in args.settings)
    node = GcsNode(sc, GcsOptions(vehicle=args.vehicle, listen=args.listen or "udp:127.0.0.1:14550", clock=args.clock,
                                  speed=args.speed, key=key, pilot=args.pilot, log=args.log,
                                  display=not args.no_display, settings=settings,
                                  config=config_of(args.config)))
    await node.start()
    loop = asyncio.get_running_loop()
    got: dict = {}

    def on_signal(signum: int) -> None:
        got.setdefault("sig", signum)
        node.request_stop()

    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, on_signal, sig)
    if args.duration:
        loop.call_later(args.duration, node.request_stop)
    freeze_after_startup()  # the start-up's objects stay out of the steps' collections
    print(f"READY listen={node.local_address} vehicle={args.vehicle} pilot={node.mode} clock={args.clock}", flush=True)
    try:
        await node.run()
    finally:
        path = node.write_log()
        st = node.ep.stats()
        node.close()
    print(f"daa-gcs: done, {node.steps} steps, {len(node.sent)} commands sent, packets dropped {st['dropped']}, "
          f"telemetry rejected {node.view.rejected}, ticks {node.ticks.heard['vehicle']} (ticks skipped {node.ticks.skipped})"
          + (f"; log {path}" if path else ""), flush=True)
    print("daa-gcs: link stats " + json.dumps(st, sort_keys=True), flush=True)
    for line in (node.ep.drops.summary(), node.ep.guard.summary()):
        if line:
            print(f"daa-gcs: {line}", flush=True)
    if "sig" in got:  # Ctrl-C / SIGTERM: as daa-vehicle, 128 + the signal (130 / 143)
        print(f"daa-gcs: stopped by signal {got['sig']}", flush=True)
        return 128 + int(got["sig"])
    return 0


def main(argv: "list[str] | None" = None) -> int:
    args = build_parser().parse_args(argv)
    return run_guarded("daa-gcs", lambda: asyncio.run(_amain(args)))
