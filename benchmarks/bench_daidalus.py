"""Benchmark against the peer: NASA DAIDALUS v2.0.4 (Java) and our ``daidalus`` preset on the 1,000
conformance encounters, one core each, evaluations per second and their ratio, batched and for a batch of
one.

    python benchmarks/bench_daidalus.py --daidalus-jar /path/to/DAIDALUSv2.0.4.jar [--conf DO_365B_no_SUM.conf]
                                        [--rounds 4] [--seconds 6] [--cpu 0] [--baseline DIR]

Both sides compute the same things per encounter: the alert level; the track, ground-speed and
vertical-speed bands with their regions; the region of each current value; the resolutions on both
sides; the preferred directions; the recovery information (DAIDALUS: ``alertLevel``, the
``*IntervalAt`` / ``*RegionAt`` / ``regionOf*`` / ``*Resolution`` / ``preferred*`` /
``*RecoveryInformation`` calls of ``benchmarks/DaidalusBench.java``, our small driver compiled against
the jar; ours: ``alert_levels`` and ``compute_bands`` of the three axes, which make the same fields).
DAIDALUS evaluates one encounter per call (one ``Daidalus`` object, its configuration read once, a new
ownship state per encounter); ours is timed batched (the 1,000 in one call) and one encounter per call
(the SIL's N = 1). The two run alternately on the same CPU (``taskset``; the JVM with one active
processor), ``--rounds`` times, after a warm-up (the JIT; our kernels loaded and touched), and the spread
is printed with the load. The driver's alert levels are checked against the reference's.

Without a JDK (``javac``/``java``) or the jar, it says so in one line and exits 2. Build the jar from
DAIDALUS's public sources (github.com/nasa/daidalus, ``Java/``: ``make lib``); nothing of DAIDALUS is kept
in this repository. ``--baseline DIR`` (default ``/work/baseline`` when it is there; ``none``: no baseline):
also time our side of a baseline checkout (its ``.venv``) in the same rounds, for the ratio to it.
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
DATA = HERE.parent / "tests" / "data" / "daidalus_do365b.jsonl.xz"

#: our side, run as a script in a fresh interpreter (this checkout's or the baseline's): batched and one at a time
OURS = r"""
import os, sys, time
os.sched_setaffinity(0, {{{cpu}}})
from daa_sil.daa import DaaConfig, compute_bands
from daa_sil.daa.alerting import alert_levels
from daa_sil.daa.conformance import read_records, states
recs = read_records({data!r})
cfg = DaaConfig.for_preset("daidalus")
own, intr = states(recs)
n = own.shape[0]
def ev(o, i):
    return compute_bands(o, i, cfg, alert_levels(o, i, cfg))
ev(own, intr)  # (warm: kernels loaded, working arrays made)
for k in range(min(n, 50)):
    ev(own[k:k + 1], intr[k:k + 1])
best = float("inf")
end = time.perf_counter() + {seconds} / 2
while time.perf_counter() < end or best == float("inf"):
    t = time.process_time(); ev(own, intr); best = min(best, time.process_time() - t)
ones = [own[k:k + 1] for k in range(n)], [intr[k:k + 1] for k in range(n)]
t = time.process_time()
for k in range(n):
    ev(ones[0][k], ones[1][k])
one = time.process_time() - t
print(f"batched {{n / best:.1f}} one {{n / one:.1f}}")
"""


def fail(msg: str) -> "NoReturn":  # noqa: F821
    print(f"bench_daidalus: {msg}", file=sys.stderr)
    sys.exit(2)


def load() -> str:
    return f"load {os.getloadavg()[0]:.1f}"


def write_input(path: Path) -> list[dict]:
    """The encounters' states, 12 numbers a line, for the Java driver; returns the records."""
    sys.path.insert(0, str(HERE.parent))
    from daa_sil.daa.conformance import read_records

    recs = read_records(DATA)
    keys = ("own_pos_enu_m", "own_vel_enu_mps", "int_pos_enu_m", "int_vel_enu_mps")
    path.write_text("".join(" ".join(repr(float(x)) for k in keys for x in r[k]) + "\n" for r in recs))
    return recs


def run_java(jar: Path, classes: Path, conf: str, inp: Path, seconds: float, cpu: int) -> dict:
    cmd = ["taskset", "-c", str(cpu)] if shutil.which("taskset") else []
    cmd += ["java", "-XX:ActiveProcessorCount=1", "-cp", f"{jar}{os.pathsep}{classes}", "DaidalusBench", conf, str(inp),
            str(seconds)]
    res = subprocess.run(cmd, capture_output=True, text=True)
    if res.returncode != 0:
        fail(f"DAIDALUS run failed (exit {res.returncode}): {(res.stderr or res.stdout).strip()[-300:]}")
    out = {}
    for line in res.stdout.splitlines():
        key, _, rest = line.partition(" ")
        out[key] = rest.split()
    ev = out["evaluations"]
    evals, secs = int(ev[0]), float(ev[2])
    times = [int(x) for x in out["times"]]
    levels = [tuple(int(y) for y in x.split(":")) for x in out["levels"]]
    return {"rate": evals / secs, "per_call_ms": statistics.median(times) / 1e6, "mean_ms": statistics.fmean(times) / 1e6,
            "times": times, "levels": levels}


def run_ours(python: str, cwd: Path, seconds: float, cpu: int) -> dict:
    code = OURS.format(cpu=cpu, data=str(DATA), seconds=seconds)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    res = subprocess.run([python, "-c", code], capture_output=True, text=True, cwd=cwd, env=env)
    if res.returncode != 0:
        fail(f"our side failed ({python}): {res.stderr.strip()[-300:]}")
    parts = res.stdout.split()
    return {"batched": float(parts[1]), "one": float(parts[3])}


def spread(xs: list) -> str:
    return f"{min(xs):,.0f}-{max(xs):,.0f} (median {statistics.median(xs):,.0f})"


def main(argv: "list[str] | None" = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0], epilog=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--daidalus-jar", type=Path, required=False, metavar="PATH",
                    help="DAIDALUS v2.0.4 jar built from its public sources (Java/: make lib)")
    ap.add_argument("--conf", default=None, metavar="FILE",
                    help="DAIDALUS configuration (default: DO_365B_no_SUM.conf next to the jar's sources, "
                         "else DAIDALUS's own set_DO_365B(true, false))")
    ap.add_argument("--rounds", type=int, default=4, help="alternated rounds (default 4)")
    ap.add_argument("--seconds", type=float, default=6.0, help="seconds DAIDALUS is timed per round (default 6)")
    ap.add_argument("--cpu", type=int, default=0, help="the CPU both sides run on (default 0)")
    ap.add_argument("--baseline", default=None, metavar="DIR",
                    help="a baseline checkout with its own .venv: our side of it timed in the same rounds "
                         "(default /work/baseline when it is there; 'none': no baseline)")
    args = ap.parse_args(argv)
    if args.daidalus_jar is None or not args.daidalus_jar.is_file():
        fail(f"needs --daidalus-jar PATH, a DAIDALUS v2.0.4 jar (got {args.daidalus_jar}); build it from "
             "github.com/nasa/daidalus (Java/: make lib)")
    if not (shutil.which("javac") and shutil.which("java")):
        fail("needs a JDK (javac and java on PATH)")
    if args.rounds < 1 or args.seconds <= 0:
        fail("--rounds must be at least 1 and --seconds positive")
    sys.path.insert(0, str(HERE))
    from baseline_paths import BASELINE_DIR

    if args.baseline is None:
        args.baseline = BASELINE_DIR if (BASELINE_DIR / ".venv" / "bin" / "python").exists() else "none"
    args.baseline = None if str(args.baseline) == "none" else Path(args.baseline)
    conf = args.conf
    if conf is None:
        guess = args.daidalus_jar.resolve().parent.parent.parent / "Configurations" / "DO_365B_no_SUM.conf"
        conf = str(guess) if guess.is_file() else "-"
    elif not Path(conf).is_file():
        fail(f"--conf {conf}: no such file")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        res = subprocess.run(["javac", "-cp", str(args.daidalus_jar), "-d", str(tmp), str(HERE / "DaidalusBench.java")],
                             capture_output=True, text=True)
        if res.returncode != 0:
            fail(f"the Java driver did not compile against {args.daidalus_jar}: {res.stderr.strip()[-300:]}")
        recs = write_input(tmp / "input.txt")
        print(f"DAIDALUS {args.daidalus_jar} ({'set_DO_365B(true, false)' if conf == '-' else conf}); ours: preset "
              f"daidalus, {sys.executable}; {len(recs)} encounters; CPU {args.cpu}; {args.rounds} alternated rounds")
        java, ours, base = [], [], []
        for k in range(args.rounds):
            j = run_java(args.daidalus_jar, tmp, conf, tmp / "input.txt", args.seconds, args.cpu)
            o = run_ours(sys.executable, HERE.parent, args.seconds, args.cpu)
            line = (f"round {k + 1}: DAIDALUS {j['rate']:,.0f}/s ({j['per_call_ms']:.3f} ms median per call); ours "
                    f"batched {o['batched']:,.0f}/s, one at a time {o['one']:,.0f}/s ({1e3 / o['one']:.3f} ms)")
            if args.baseline is not None:
                b = run_ours(str(args.baseline / ".venv" / "bin" / "python"), args.baseline, args.seconds, args.cpu)
                base.append(b)
                line += f"; baseline batched {b['batched']:,.0f}/s, one {b['one']:,.0f}/s"
            print(f"{line}  [{load()}]")
            java.append(j)
            ours.append(o)
    ref_levels = [int(r["alert_level"]) for r in recs]
    agree = sum(lv == ref for (lv, _), ref in zip(java[0]["levels"], ref_levels))
    print(f"check: the driver's DAIDALUS alert levels equal the reference's in {agree} of {len(recs)} encounters")
    jr, jc = [j["rate"] for j in java], [j["per_call_ms"] for j in java]
    ob, oo = [o["batched"] for o in ours], [o["one"] for o in ours]
    rb = [b / j for b, j in zip(ob, jr)]
    r1 = [o / j for o, j in zip(oo, jr)]
    print(f"DAIDALUS: {spread(jr)} evaluations/s, {min(jc):.3f}-{max(jc):.3f} ms per call (median of its encounters)")
    print(f"ours batched (1,000 per call): {spread(ob)} evaluations/s = x{min(rb):.2f}-{max(rb):.2f} DAIDALUS "
          f"(target >= x10)")
    print(f"ours one at a time (batch of one): {spread(oo)} evaluations/s = x{min(r1):.2f}-{max(r1):.2f} DAIDALUS "
          f"(target >= x1.0)")
    if base:
        bb, bo = [b["batched"] for b in base], [b["one"] for b in base]
        print(f"ratio to the baseline: batched x{statistics.median(ob) / statistics.median(bb):.2f}, one at a time "
              f"x{statistics.median(oo) / statistics.median(bo):.2f} (medians)")
    # recovery: the encounters with a recovery band on the track axis, against the others (DAIDALUS's times)
    rec = [bool(r.get("track_recovery", {}).get("recovery_bands_computed")) for r in recs]
    t = java[-1]["times"]
    with_r = [x for x, f in zip(t, rec) if f]
    without = [x for x, f in zip(t, rec) if not f]
    if with_r and without:
        print(f"DAIDALUS per call: {len(with_r)} encounters with a track recovery band {statistics.median(with_r) / 1e6:.3f} "
              f"ms (median), the others {statistics.median(without) / 1e6:.3f} ms")
    return 0


if __name__ == "__main__":
    sys.exit(main())
