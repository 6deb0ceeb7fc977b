"""Floods against the vehicle, the shim and a realtime run, bounded in time and size, on loopback only:
what comes back, how much memory, how late the steps are -- this checkout and a baseline, in one run.

    python benchmarks/bench_flood.py                            # every part, against /work/baseline
    python benchmarks/bench_flood.py --part amplification --datagrams 10
    python benchmarks/bench_flood.py --part realtime            # needs CAP_NET_RAW (spoofs the shim's address)
    python benchmarks/bench_flood.py --baseline none            # this checkout alone

Parts (each process a part starts runs under RLIMIT_AS ``--limit-gb``; each flood is a fixed number of
datagrams):

* ``amplification``: ``daa-vehicle`` (realtime, its pilot link this script's socket) gets ``--datagrams``
  datagrams of 4,679 PARAM_REQUEST_LIST each (65,506 B) at 5 a second, from the pilot link's address.
  Bytes back = the vehicle's own ``bytes_out`` (its step log's link counters) minus that of the same run
  without the flood; amplification = bytes back / bytes sent. Also its peak RSS and step lateness.
* ``shim``: ``daa-sil shim`` (lockstep: the delay line; realtime: the start-up hold) gets
  ``--shim-datagrams`` datagrams of 60 kB on its GCS side from the GCS it learned: RSS growth and
  ``dropped_queue``.
* ``addresses``: ``--addresses`` datagrams from as many spoofed source addresses into one endpoint
  (``MavEndpoint.datagram_received``, in a child process): RSS before and after.
* ``realtime``: ``daa-sil run`` (realtime, ``--speed``) of a 40 s head-on with the same flood sent from
  the shim's vehicle-side address to the vehicle (a raw socket: root or CAP_NET_RAW), against a
  lockstep run of the same scenario: ``lockstep_equivalent``, step lateness, GCS commands sent.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import resource
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
from baseline_paths import BASELINE_CACHE, BASELINE_DIR, BASELINE_PYTHON  # noqa: E402

from daa_sil.link.codec import MavCodec, mavlink as M  # noqa: E402

SCENARIO = """\
name: flood
seed: 11
duration_s: {duration}
ownship: {{alt_m: 1000, gs_mps: 55, track_deg: 0}}
intruders:
  - callsign: HEAD1
    initial: {{x_m: 150, y_m: 6900, alt_m: 1000, gs_mps: 60, track_deg: 180}}
link: {{up: "const:2", down: "const:2"}}
pilot: {{mode: model, model: {{response: deterministic}}}}
allocation: {{group: ID-1}}
"""
GCS = MavCodec(255, 190)
LIST_REQUEST = GCS.encode(M.MAVLink_param_request_list_message(1, 1))
LIST_FLOOD = LIST_REQUEST * (65507 // len(LIST_REQUEST))
ADDRESSES_CODE = """
import re, sys
from daa_sil.link.codec import MavCodec, mavlink as M
from daa_sil.sil.endpoint import MavEndpoint
def rss():
    return int(re.search(r"VmRSS:\\s+(\\d+)", open("/proc/self/status").read()).group(1)) / 1024
ep = MavEndpoint(MavCodec(1, 1), peer=("127.0.0.1", 14550), learn_peer=False, allow_peers=[("127.0.0.1", 14550)],
                 warn=lambda text: None)
junk = MavCodec(255, 190).encode(M.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3))
for i in range(2000):
    ep.datagram_received(junk, ("10.255.0.1", 1000 + i))
before = rss()
n = int(sys.argv[1])
for i in range(n):
    ep.datagram_received(junk, (f"10.{i // 62500 % 250}.{i // 250 % 250}.{i % 250}", 1024 + i % 60000))
print(f"RSS {before:.0f} -> {rss():.0f} MiB")
"""


class Side:
    """A checkout to measure: its interpreter, tree and wait-map cache."""

    def __init__(self, name: str, python: Path, tree: Path, cache: "Path | None", limit_gb: float):
        self.name, self.python, self.tree, self.limit = name, str(python), tree, int(limit_gb * 2**30)
        self.env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
        self.env.update(PYTHONDONTWRITEBYTECODE="1", PYTHONUNBUFFERED="1")
        if cache is not None:
            self.env["DAA_SIL_CACHE"] = str(cache)

    def start(self, args: list, **kw) -> subprocess.Popen:
        def limited():
            resource.setrlimit(resource.RLIMIT_AS, (self.limit, self.limit))
        return subprocess.Popen([self.python, *args], cwd=self.tree, env=self.env, preexec_fn=limited,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kw)


def rss_mib(pid: int, field: str = "VmRSS") -> float:
    try:
        with open(f"/proc/{pid}/status") as f:
            return int(re.search(field + r":\s+(\d+)", f.read()).group(1)) / 1024
    except (OSError, AttributeError):
        return float("nan")


def _read_line(stream, pattern: str, timeout: float = 120.0) -> "re.Match":
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        line = stream.readline()
        if not line:
            break
        m = re.search(pattern, line)
        if m:
            return m
    raise SystemExit(f"bench_flood: no line matching {pattern!r} within {timeout:g} s")


def vehicle_run(side: Side, scen: Path, datagrams: int, work: Path) -> dict:
    """One realtime vehicle flight behind this script's socket, flooded with ``datagrams`` (0: quiet)."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    steplog = work / f"{side.name}-{datagrams}.parquet"
    proc = side.start(["-m", "vehicle", str(scen), "--out", f"udp:127.0.0.1:{sock.getsockname()[1]}",
                       "--clock", "realtime", "--steplog", str(steplog), "--quiet"]
                      # this checkout's vehicle flies on past its scenario unless told (the baseline's always ended)
                      + (["--exit-at-end"] if side.name == "this" else []))
    peak = [0.0]
    try:
        m = _read_line(proc.stdout, r"READY listen=udp:([\d.]+):(\d+)")
        dest = (m.group(1), int(m.group(2)))
        time.sleep(2.0)
        for _ in range(datagrams):
            sock.sendto(LIST_FLOOD, dest)
            peak[0] = max(peak[0], rss_mib(proc.pid))
            time.sleep(0.2)
        while proc.poll() is None:
            peak[0] = max(peak[0], rss_mib(proc.pid, "VmHWM"))
            time.sleep(0.1)
        out = proc.stdout.read()
    finally:
        sock.close()
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    import pyarrow.parquet as pq

    meta = {k.decode(): v.decode() for k, v in (pq.read_schema(steplog).metadata or {}).items()}
    link = json.loads(meta.get("link", "{}"))
    late = re.search(r"step lateness mean ([\d.]+) ms, max ([\d.]+) ms", out)
    return {"bytes_out": link.get("bytes_out", 0), "peak_mib": peak[0], "late_max_ms": float(late.group(2)) if late else
            float("nan"), "sent": datagrams * len(LIST_FLOOD)}


def part_amplification(sides: list, args, work: Path) -> None:
    scen = work / "flood.yaml"
    scen.write_text(SCENARIO.format(duration=int(args.datagrams / 5 + 6)))
    res = {}
    for s in sides:
        quiet, flood = vehicle_run(s, scen, 0, work), vehicle_run(s, scen, args.datagrams, work)
        back = flood["bytes_out"] - quiet["bytes_out"]
        res[s.name] = back / flood["sent"]
        print(f"[amplification] {s.name:9s}: {flood['sent']:,} B sent, {back:,} B back -> amplification "
              f"{res[s.name]:.3f}; peak RSS {flood['peak_mib']:.0f} MiB (quiet {quiet['peak_mib']:.0f}); step "
              f"lateness max {flood['late_max_ms']:.1f} ms (quiet {quiet['late_max_ms']:.1f})", flush=True)
    if len(res) == 2:
        print(f"[amplification] => ratio this / baseline {res['this'] / res['baseline']:.4f}", flush=True)


def part_shim(sides: list, args, work: Path) -> None:
    blob = GCS.encode(M.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3)) * (60_000 // 21)
    for clock in ("lockstep", "realtime"):
        grown = {}
        for s in sides:
            proc = s.start(["-m", "daa_sil.cli", "shim", "--clock", clock, "--delay", "const:1",
                            "--listen-vehicle", "udp:127.0.0.1:0", "--listen-gcs", "udp:127.0.0.1:0"])
            g = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            try:
                m = _read_line(proc.stderr, r"gcs side udp:([\d.]+):(\d+)")
                side = (m.group(1), int(m.group(2)))
                g.sendto(blob[:21], side)
                time.sleep(0.2)
                rss0 = rss_mib(proc.pid)
                for i in range(args.shim_datagrams):
                    g.sendto(blob, side)
                    time.sleep(0.002)  # paced, so that the shim reads most of them
                time.sleep(0.5)
                peak = rss_mib(proc.pid, "VmHWM")
                grown[s.name] = rss_mib(proc.pid) - rss0
                proc.terminate()
                out, _ = proc.communicate(timeout=30)
            finally:
                g.close()
                if proc.poll() is None:
                    proc.kill()
                    proc.wait()
            stats = json.loads(out)
            up = stats.get("up", {})
            print(f"[shim {clock}] {s.name:9s}: {args.shim_datagrams} x {len(blob):,} B sent; RSS +{grown[s.name]:.0f} "
                  f"MiB (peak {peak:.0f} MiB); in flight {up.get('in_flight', 0)} datagrams, dropped_queue "
                  f"{stats['counters'].get('dropped_queue', 'n/a')}", flush=True)
        if len(grown) == 2:
            print(f"[shim {clock}] => RSS growth ratio this / baseline {grown['this'] / max(grown['baseline'], 1e-9):.3f}",
                  flush=True)


def part_addresses(sides: list, args, work: Path) -> None:
    for s in sides:
        proc = s.start(["-c", ADDRESSES_CODE, str(args.addresses)])
        out, err = proc.communicate(timeout=1800)
        print(f"[addresses] {s.name:9s}: {args.addresses:,} spoofed source addresses dropped: {out.strip() or err[-300:]}",
              flush=True)


def spoofed_udp(src: tuple, dst: tuple, payload: bytes) -> bytes:
    """An IPv4 + UDP packet from ``src`` to ``dst`` (the kernel fills the IP checksum; UDP checksum 0)."""
    ip = struct.pack("!BBHHHBBH4s4s", 0x45, 0, 20 + 8 + len(payload), 0, 0, 64, socket.IPPROTO_UDP, 0,
                     socket.inet_aton(src[0]), socket.inet_aton(dst[0]))
    return ip + struct.pack("!HHHH", src[1], dst[1], 8 + len(payload), 0) + payload


def run_once(side: Side, scen: Path, out: Path, clock: str, args, flood: bool) -> dict:
    cmd = ["-m", "daa_sil.cli", "run", str(scen), "--out", str(out), "--clock", clock]
    if clock == "realtime":
        cmd += ["--speed", f"{args.speed:g}"]
    proc = side.start(cmd)
    sent = [0]
    stop = threading.Event()

    def flooding():
        log = out / "logs" / "vehicle.log"
        end = time.monotonic() + 120
        m = None
        while m is None and time.monotonic() < end and not stop.is_set():
            m = re.search(r"READY listen=udp:([\d.]+):(\d+) out=(?:udp|udpout):([\d.]+):(\d+)",
                          log.read_text(errors="replace") if log.exists() else "")
            time.sleep(0.05)
        if m is None:
            return
        veh, shim = (m.group(1), int(m.group(2))), (m.group(3), int(m.group(4)))
        raw = socket.socket(socket.AF_INET, socket.SOCK_RAW, socket.IPPROTO_RAW)
        packet = spoofed_udp(shim, veh, LIST_FLOOD)
        time.sleep(2.0)
        while not stop.is_set() and proc.poll() is None:
            raw.sendto(packet, (veh[0], 0))
            sent[0] += 1
            time.sleep(0.2)
        raw.close()

    t = threading.Thread(target=flooding, daemon=True) if flood else None
    if t is not None:
        t.start()
    _, err = proc.communicate(timeout=1800)
    stop.set()
    if t is not None:
        t.join(5)
    res = json.loads((out / "result.json").read_text())
    cmds = sum(1 for line in (out / "gcs_commands.jsonl").read_text().splitlines() if '"seq"' in line)
    return {"rt": res.get("realtime") or {}, "cmds": cmds, "sent": sent[0]}


def part_realtime(sides: list, args, work: Path) -> None:
    try:
        socket.socket(socket.AF_INET, socket.SOCK_RAW, socket.IPPROTO_RAW).close()
    except PermissionError:
        print("[realtime] skipped: spoofing the shim's address needs root or CAP_NET_RAW", flush=True)
        return
    scen = work / "flood-rt.yaml"
    scen.write_text(SCENARIO.format(duration=40))
    for s in sides:
        lock = run_once(s, scen, work / f"{s.name}-lockstep", "lockstep", args, flood=False)
        rt = run_once(s, scen, work / f"{s.name}-realtime-flood", "realtime", args, flood=True)
        r = rt["rt"]
        print(f"[realtime] {s.name:9s}: {rt['sent']} flood datagrams spoofed from the shim's address; "
              f"lockstep_equivalent {r.get('lockstep_equivalent')}, steps unconfirmed {r.get('steps_unconfirmed')}, "
              f"step lateness max {r.get('late_max_ms')} ms; GCS commands {rt['cmds']} (lockstep run: {lock['cmds']})",
              flush=True)


PARTS = {"amplification": part_amplification, "shim": part_shim, "addresses": part_addresses,
         "realtime": part_realtime}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0], epilog=__doc__.split("\n\n", 1)[1],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--part", default=",".join(PARTS), help=f"comma-separated parts of {', '.join(PARTS)}")
    ap.add_argument("--baseline", default=str(BASELINE_DIR), help="baseline checkout with its .venv, or none")
    ap.add_argument("--datagrams", type=int, default=15, help="flood datagrams (5 a second) for the vehicle")
    ap.add_argument("--shim-datagrams", type=int, default=2000, help="60 kB datagrams into the shim")
    ap.add_argument("--addresses", type=int, default=1_000_000, help="spoofed source addresses")
    ap.add_argument("--speed", type=float, default=1.0, help="realtime speed of the realtime part")
    ap.add_argument("--limit-gb", type=float, default=4.0, help="address-space limit of each process started")
    args = ap.parse_args()
    parts = [p.strip() for p in args.part.split(",") if p.strip()]
    bad = [p for p in parts if p not in PARTS]
    if bad or not (1 <= args.datagrams <= 200 and 1 <= args.shim_datagrams <= 20_000
                   and 1 <= args.addresses <= 5_000_000 and 0.5 <= args.limit_gb <= 16):
        print(f"bench_flood: error: bad --part {bad} or a size out of its range (see --help)", file=sys.stderr)
        return 2
    sides = [Side("this", Path(sys.executable), ROOT, None, args.limit_gb)]
    if args.baseline != "none":
        base = Path(args.baseline)
        py = BASELINE_PYTHON if base == BASELINE_DIR else base / ".venv" / "bin" / "python"
        if py.is_file():
            sides.append(Side("baseline", py, base, BASELINE_CACHE if base == BASELINE_DIR else None, args.limit_gb))
        else:
            print(f"bench_flood: no baseline at {base} (its .venv); measuring this checkout alone", flush=True)
    with tempfile.TemporaryDirectory(prefix="bench-flood-") as work:
        for p in parts:
            PARTS[p](sides, args, Path(work))
    return 0


if __name__ == "__main__":
    sys.exit(main())
