"""Lockstep SIL speed: a 240 s encounter through three processes (vehicle, shim, GCS).

Prints the wall time of the whole ``daa-sil run`` (process start to result.json) and the ratio
against real time, plus the in-process baseline measured in the same run (the same OnboardCore
steps with no link: the cost of the SIL's processes and sockets is the difference) and the cost of
building and encoding each step's telemetry (the ArduPilot-SITL message set, per link).
Target (lockstep): <= 2.5 s wall for the 240 s encounter with the full telemetry.

    python benchmarks/bench_sil.py [--repeat 3]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--scenario", type=Path, default=ROOT / "scenarios" / "head_on.yaml")
    args = ap.parse_args()

    from daa_sil.commands.run import RunOptions, run_sil
    from daa_sil.scenario import load_scenario, scenario_from_dict

    sc = load_scenario(args.scenario)
    d = sc.to_dict()
    d["duration_s"] = 240.0
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "bench.yaml"
        path.write_text(__import__("yaml").safe_dump(d, sort_keys=False))
        scenario_from_dict(d)  # validate
        from vehicle.core import VehicleCore

        from daa_sil.link.codec import MavCodec
        from vehicle import telemetry as T

        t0 = time.perf_counter()
        vc = VehicleCore(load_scenario(path))
        for k in range(vc.n_steps):
            vc.step(float(k))
        base = time.perf_counter() - t0
        # telemetry: the same steps again, each one's full message set built and encoded (one datagram)
        codec = MavCodec(1, 1)
        vc = VehicleCore(load_scenario(path))
        t_tel, n_msgs, n_bytes = 0.0, 0, 0
        home = None
        for k in range(vc.n_steps):
            out = vc.step(float(k))
            t1 = time.perf_counter()
            home = home or T.kin_of(out.own, 0)
            msgs = [m for ms in T.step_messages(vc, float(k), out, home).values() for m in ms]
            data = codec.encode_many(msgs)
            t_tel += time.perf_counter() - t1
            n_msgs += len(msgs)
            n_bytes += len(data)
        walls = []
        for i in range(args.repeat):
            t0 = time.perf_counter()
            res = run_sil(RunOptions(path, Path(tmp) / f"run{i}"))
            walls.append(time.perf_counter() - t0)
            assert res["steps"] == 240
    best = min(walls)
    print(f"lockstep SIL, 240 s encounter ({sc.name}), 3 processes: best {best:.2f} s wall of {args.repeat} "
          f"(all: {', '.join(f'{w:.2f}' for w in walls)}) -> {240.0 / best:.0f}x real time "
          f"(target <= 2.5 s: {'met' if best <= 2.5 else 'NOT met'})")
    print(f"in-process baseline (same OnboardCore steps, no link, no processes): {base:.2f} s -> "
          f"{240.0 / base:.0f}x real time; SIL/baseline = {best / base:.1f}x")
    print(f"telemetry per step: {n_msgs / 240:.1f} messages, {n_bytes / 240:.0f} bytes, built + encoded in "
          f"{1e3 * t_tel / 240:.2f} ms ({100 * t_tel / best:.1f} % of the SIL wall time, per link)")


if __name__ == "__main__":
    main()
