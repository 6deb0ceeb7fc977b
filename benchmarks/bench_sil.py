"""Lockstep SIL speed: a 240 s encounter through three processes (vehicle, shim, GCS).

Prints the wall time of the whole ``daa-sil run`` (process start to result.json) and the ratio
against real time, plus the in-process baseline measured in the same run (the same OnboardCore
steps with no link: the cost of the SIL's processes and sockets is the difference).
Target: <= 5 s wall, >= 50x real time.

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

        t0 = time.perf_counter()
        vc = VehicleCore(load_scenario(path))
        for k in range(vc.n_steps):
            vc.step(float(k))
        base = time.perf_counter() - t0
        walls = []
        for i in range(args.repeat):
            t0 = time.perf_counter()
            res = run_sil(RunOptions(path, Path(tmp) / f"run{i}"))
            walls.append(time.perf_counter() - t0)
            assert res["steps"] == 240
    best = min(walls)
    print(f"lockstep SIL, 240 s encounter ({sc.name}), 3 processes: best {best:.2f} s wall of {args.repeat} "
          f"(all: {', '.join(f'{w:.2f}' for w in walls)}) -> {240.0 / best:.0f}x real time "
          f"(target >= 50x, <= 5 s)")
    print(f"in-process baseline (same OnboardCore steps, no link, no processes): {base:.2f} s -> "
          f"{240.0 / base:.0f}x real time; SIL/baseline = {best / base:.1f}x")


if __name__ == "__main__":
    main()
