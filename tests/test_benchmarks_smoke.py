"""Every script in benchmarks/ still runs and prints its figure (tiny arguments, no timing asserted).

A benchmark is run by hand, rarely: when an API it calls changes it breaks silently (bench_daa.py
and bench_report.py both did). This runs each one as a subprocess with arguments small enough for
the test suite and checks that it exits 0 and prints the line that carries its figure. It asserts
nothing about the numbers: performance targets are for the benchmarks themselves.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pyarrow.parquet as pq
import pytest

ROOT = Path(__file__).resolve().parents[1]
BENCH = ROOT / "benchmarks"

#: script -> (tiny arguments, a fragment of the line that prints its figure)
CASES = {
    "bench_daa.py": (["--n", "20", "--loop", "3", "--repeat", "1"], "speed-up batched / one-at-a-time"),
    "bench_wellclear.py": (["--pairs", "2000", "--loop-pairs", "50", "--repeat", "1"], "vectorised violation_interval"),
    "bench_link.py": (["--part", "codec", "--n", "200"], "MavCodec unsigned"),
    "bench_report.py": (["--encounters", "40", "--replicates", "100", "--repeat", "1"], "ratio new / old"),
    "bench_waitmap.py": (["--skip-large"], "[1] paper grid"),
    "bench_campaign.py": (["--encounters", "6", "--groups", "B-2,ID-2", "--workers", "1", "--no-baseline"],
                          "[campaign] 2 groups x 6 encounters"),
    "bench_sil.py": (["--part", "lockstep", "--repeat", "1"], "SIL/baseline"),
    "bench_viz.py": (["--skip-sil", "--repeat", "1", "--live-repeat", "1"], "[3] fast-time"),
}


def run(script: str, args: list[str], cwd: Path, timeout: float = 900.0) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(BENCH / script), *args], cwd=cwd, capture_output=True, text=True,
                          timeout=timeout)


def test_every_benchmark_is_covered():
    scripts = {p.name for p in BENCH.glob("*.py")}
    assert scripts - set(CASES) == {"compare_campaigns.py"}  # tested below with its own data


@pytest.mark.parametrize("script", sorted(CASES))
def test_benchmark_runs_and_prints_its_figure(script, tmp_path):
    args, figure = CASES[script]
    res = run(script, args, tmp_path)
    out = res.stdout + res.stderr
    assert res.returncode == 0, out[-3000:]
    assert figure in out, out[-3000:]


def test_compare_campaigns_finds_identical_and_different_tables(tmp_path):
    from daa_sil.cli import main

    a, b = tmp_path / "a", tmp_path / "b"
    for d in (a, b):
        assert main(["campaign", "run", "--groups", "B-2", "--encounters", "5", "--seed", "11", "--out", str(d),
                     "--no-progress"]) == 0
    res = run("compare_campaigns.py", [str(a), str(b)], tmp_path)
    assert res.returncode == 0 and "identical: yes" in res.stdout, res.stdout + res.stderr
    # one value changed in one data column: found, named, exit 1
    path = next((b / "B-2").glob("encounters-*.parquet"))
    t = pq.read_table(path)
    col = t.column("min_range_m").to_pylist()
    col[2] += 1e-9
    t = t.set_column(t.column_names.index("min_range_m"), "min_range_m", [col])
    pq.write_table(t, path)
    res = run("compare_campaigns.py", [str(a), str(b)], tmp_path)
    assert res.returncode == 1
    assert "identical: no" in res.stdout and "'min_range_m' differs" in res.stdout
