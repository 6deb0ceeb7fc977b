"""``daa-sil inject FILE``: new intruders for a vehicle that is flying, from a scenario file.

Attaches to a running ``daa-vehicle`` as one more ground station, reads where the ownship is, places the
file's intruders around it as the scenario places them around its start (:mod:`daa_sil.sil.traffic`) and
sends each as an ADSB_VEHICLE. The vehicle flies them from its next step and answers each with a
STATUSTEXT (``traffic HEAD1 (1000) injected``, or why not), which this command prints. The vehicle takes
traffic only on a writable link: its pilot's link or an output marked ``,rw``.
"""

from __future__ import annotations

import argparse
import socket
import time
from pathlib import Path

from ..errors import DaaSilError, UsageError
from daa_sil.config.settings import GCS_PORT, udp
from .common_args import load_key_option
from dataclasses import replace

EXAMPLES = """examples:
  # a vehicle listening like SITL: inject the crossing scenario's intruder around it, now
  # (the scenarios' first intruders are all ICAO 1000, which flies already: --id-offset renumbers them)
  daa-vehicle scenarios/head_on.yaml --out udpin:127.0.0.1:14550 &
  daa-sil inject scenarios/crossing_left.yaml --vehicle udpout:127.0.0.1:14550 --id-offset 100

  # through its TCP server (as SITL's 5760)
  daa-sil inject scenarios/two_intruders.yaml --vehicle tcp:127.0.0.1:5760 --id-offset 200

  # a vehicle streaming to a writable observer port (daa-vehicle ... --out udp:127.0.0.1:14560,rw)
  daa-sil inject scenarios/overtaking.yaml --vehicle udpin:127.0.0.1:14560 --id-offset 300
"""
#: wall seconds between two hellos while waiting for the vehicle's position
HELLO_EVERY_S = 0.5


def register(sub) -> None:
    p = sub.add_parser("inject", help="inject a scenario file's intruders into a flying vehicle",
                       description=__doc__, epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("file", type=Path, help="scenario YAML file whose intruders to inject")
    p.add_argument("--vehicle", default=udp(GCS_PORT, "udpout"), metavar="CONN",
                   help=f"the vehicle: udpout:HOST:PORT (its udpin: output; default {udp(GCS_PORT, 'udpout')}), "
                        "udpin:HOST:PORT (its ,rw output streams here) or tcp:HOST:PORT (its tcpin: output)")
    p.add_argument("--id-offset", type=int, default=0, metavar="N",
                   help="add N to each intruder's ICAO address (the vehicle refuses one that flies already)")
    p.add_argument("--key", type=Path, metavar="FILE", help="MAVLink 2 signing key file (as the vehicle's)")
    p.add_argument("--timeout", type=float, default=30.0, metavar="S",
                   help="wall seconds to wait for the vehicle's position, then for its answers (default 30)")
    p.set_defaults(func=inject)


class _Link:
    """One ground-station socket to the vehicle: UDP (send to it, or listen where it streams) or TCP."""

    def __init__(self, text: str):
        from daa_sil.link.framing import StreamFramer  # lazy: start-up time
        from daa_sil.sil.endpoint import norm_host, parse_udp_address  # lazy: start-up time

        scheme, _, rest = text.strip().partition(":")
        self.tcp = scheme.lower() in ("tcp", "tcpout")
        self.framer = StreamFramer() if self.tcp else None
        addr = parse_udp_address(rest if self.tcp else text, "--vehicle", allow_port_zero=False)
        addr = (norm_host(addr[0]), addr[1])
        self.dest: "tuple | None" = None
        if self.tcp:
            self.sock = socket.create_connection(addr, timeout=10.0)
        else:
            self.sock = socket.socket(socket.AF_INET6 if ":" in addr[0] else socket.AF_INET, socket.SOCK_DGRAM)
            if scheme.lower() == "udpin":
                self.sock.bind(addr)  # the vehicle streams here: answer whoever it is
            else:
                self.sock.bind(("127.0.0.1", 0) if addr[0].startswith("127.") else ("", 0))
                self.dest = addr
        self.sock.settimeout(0.1)

    def send(self, data: bytes) -> None:
        if self.tcp:
            self.sock.sendall(data)
        elif self.dest is not None:
            self.sock.sendto(data, self.dest)

    def recv(self) -> bytes:
        try:
            if self.tcp:
                return self.framer.feed(self.sock.recv(65536))
            data, src = self.sock.recvfrom(65536)
            if self.dest is None:
                self.dest = src  # (udpin:) the vehicle's socket
            return data
        except (socket.timeout, BlockingIOError):
            return b""

    def close(self) -> None:
        self.sock.close()


def inject(args) -> int:
    from daa_sil.link.codec import MavCodec  # lazy: start-up time
    from daa_sil.link.codec import mavlink as M  # lazy: start-up time
    from daa_sil.sil.scenario import load_scenario  # lazy: start-up time
    from daa_sil.sil.traffic import own_from_telemetry, traffic_reports  # lazy: start-up time

    if not (0.5 <= args.timeout <= 3600):
        raise UsageError(f"--timeout must be within [0.5, 3600] s, got {args.timeout:g}")
    sc = load_scenario(args.file)
    if args.id_offset:
        ids = [i.id + args.id_offset for i in sc.intruders]
        if not all(1 <= i <= 0xFFFFFF for i in ids):
            raise UsageError(f"--id-offset {args.id_offset}: ICAO addresses must stay within [1, 16777215]")
        sc = replace(sc, intruders=[replace(i, id=n) for i, n in zip(sc.intruders, ids)])
    codec = MavCodec(255, 191, key=load_key_option(args.key, "daa-sil") if args.key else None)
    try:
        link = _Link(args.vehicle)
    except OSError as exc:
        raise DaaSilError(f"--vehicle {args.vehicle}: cannot connect ({exc.strerror or exc})") from None
    hello = M.MAVLink_heartbeat_message(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, M.MAV_STATE_ACTIVE, 3)
    try:
        gpi, end, next_hello = None, time.monotonic() + args.timeout, 0.0
        while gpi is None:
            if time.monotonic() > end:
                raise DaaSilError(f"no position from a vehicle at {args.vehicle} within {args.timeout:g} s: is "
                                  f"daa-vehicle flying, with an output there?")
            if time.monotonic() >= next_hello:
                link.send(codec.encode(hello))  # a udpin: / tcpin: vehicle answers who speaks
                next_hello = time.monotonic() + HELLO_EVERY_S
            gpi = next((m for m in codec.decode(link.recv()) if m.get_type() == "GLOBAL_POSITION_INT"
                        and m.get_srcSystem() == 1), None)
        reports = traffic_reports(sc, own_from_telemetry(gpi))
        link.send(codec.encode_many(reports))
        waiting = {str(r.ICAO_address) for r in reports}
        failed, end = 0, time.monotonic() + args.timeout
        while waiting and time.monotonic() < end:
            for m in codec.decode(link.recv()):
                text = m.text if m.get_type() == "STATUSTEXT" else ""
                icao = next((i for i in waiting if text.startswith("traffic ") and f"{i}" in text.split(":")[0]), None)
                if icao is None:
                    continue
                waiting.discard(icao)
                ok = text.endswith("injected")
                failed += not ok
                print(f"daa-sil: {'injected' if ok else 'refused'}: {text}", flush=True)
        if waiting:
            raise DaaSilError(f"no answer from the vehicle for {', '.join(sorted(waiting))} within {args.timeout:g} s "
                              f"(is that output read-only? traffic is taken on writable links only)")
    finally:
        link.close()
    return 1 if failed else 0
