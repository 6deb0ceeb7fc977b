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
    "bench_waitmap.py": (["--skip-large"], "[5] first-run build"),
    "bench_campaign.py": (["--encounters", "6", "--groups", "B-2,ID-2", "--workers", "1", "--no-baseline"],
                          "[campaign] 2 groups x 6 encounters"),
    "bench_sil.py": (["--part", "lockstep", "--repeat", "1", "--baseline", "none", "--pyc", "present"],
                     "=> with .pyc:"),
    "bench_viz.py": (["--skip-sil", "--repeat", "1", "--live-repeat", "1"], "[3] fast-time"),
    "bench_flood.py": (["--part", "amplification,addresses", "--datagrams", "1", "--addresses", "2000",
                        "--baseline", "none"], "[amplification] this"),
}


def run(script: str, args: list[str], cwd: Path, timeout: float = 900.0) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(BENCH / script), *args], cwd=cwd, capture_output=True, text=True,
                          timeout=timeout)


def test_every_benchmark_is_covered():
    scripts = {p.name for p in BENCH.glob("*.py")}
    # compare_campaigns.py, check_identity.py and bench_daidalus.py are tested below; sil_probe.py and sil_realtime.py
    # (bench_sil.py's) and baseline_paths.py (where the baseline is installed) are helpers
    assert scripts - set(CASES) == {"compare_campaigns.py", "check_identity.py", "bench_daidalus.py", "sil_probe.py",
                                    "sil_realtime.py", "baseline_paths.py"}


def test_bench_daidalus_without_a_jar_says_so_in_one_line(tmp_path):
    """Without the DAIDALUS jar (which this repository does not hold) or with a path that is not one: one line,
    exit 2, before anything is run."""
    for args in ([], ["--daidalus-jar", str(tmp_path / "missing.jar")]):
        res = run("bench_daidalus.py", args, tmp_path)
        assert res.returncode == 2 and res.stdout == "", res.stdout + res.stderr
        lines = res.stderr.strip().splitlines()
        assert len(lines) == 1 and "--daidalus-jar" in lines[0] and "Traceback" not in res.stderr


def test_check_identity_against_itself_and_without_a_baseline(tmp_path):
    # this checkout as its own baseline: the campaign and the conformance run twice and compare identical
    res = run("check_identity.py", ["--baseline", str(ROOT), "--baseline-python", sys.executable,
                                    "--baseline-cache", "none", "--readings", "paper", "--groups", "B-2",
                                    "--encounters", "6", "--workers", "1", "--conformance", "--presets", "paper"],
              tmp_path)
    out = res.stdout + res.stderr
    assert res.returncode == 0, out[-3000:]
    assert "campaign paper" in out and "conformance --preset paper" in out
    assert "identical: yes (2 of 2 comparisons)" in out, out[-3000:]
    # a "baseline" that flies another seed: the campaigns differ, and the script says so and exits 1
    other = tmp_path / "other-seed-python"
    other.write_text(f"#!{sys.executable}\nimport os, sys\nargs = sys.argv[1:]\n"
                     f"if '--seed' in args:\n    args[args.index('--seed') + 1] = '8'\n"
                     f"os.execv({sys.executable!r}, [{sys.executable!r}] + args)\n")
    other.chmod(0o755)
    res = run("check_identity.py", ["--baseline", str(ROOT), "--baseline-python", str(other), "--baseline-cache", "none",
                                    "--readings", "paper", "--groups", "B-2", "--encounters", "6", "--workers", "1"],
              tmp_path)
    out = res.stdout + res.stderr
    assert res.returncode == 1, out[-3000:]
    assert "campaign paper" in out and "DIFFERENT" in out and "identical: no (0 of 1 comparisons)" in out, out[-3000:]
    # no baseline: one line, exit 2
    res = run("check_identity.py", ["--baseline", str(tmp_path / "nowhere")], tmp_path)
    assert res.returncode == 2 and res.stdout == "" and len(res.stderr.strip().splitlines()) == 1, res.stderr


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


def test_compare_campaigns_maps_old_authority_names_so_old_step_logs_still_compare(tmp_path):
    """Issue 20 §15: the waiting authority was called ``hold`` up to bba2fd8 (the pilot's command kind
    is ``hold`` too). ``tests/data/steplog_head_on_bba2fd8.parquet`` is the fast-time step log of
    ``scenarios/head_on.yaml`` written by bba2fd8 itself (17 steps ``hold``); the same log made now
    says ``waiting`` at those steps, and compare_campaigns.py reads the old name as the new one
    (documented in its --help), so the old log and the old log with today's name compare identical (a
    log made now differs in continuous columns since fast-time flies the link's float32 setpoints); a
    real difference is still found."""
    import numpy as np

    from daa_sil import waitmap
    from daa_sil.daa.config import DaaConfig
    from daa_sil.models.pilot_config import PilotConfig
    from daa_sil.sil.scenario import delay_models, encounter_set, load_scenario
    from daa_sil.steplog import read_steplog, write_steplog
    from daa_sil.study.simulation.fasttime import simulate
    from vehicle.core import build_policy

    old = ROOT / "tests" / "data" / "steplog_head_on_bba2fd8.parquet"
    raw = pq.read_table(old).column("authority").to_pylist()
    assert raw.count("hold") == 17 and "waiting" not in raw
    sc = load_scenario(ROOT / "scenarios" / "head_on.yaml")
    up, down = delay_models(sc)
    _, _, log = simulate(encounter_set(sc), build_policy(sc), up, down, PilotConfig(mode=sc.pilot.response),
                         DaaConfig(thresholds=sc.thresholds), waitmap.family_for(None, preset="paper"),
                         seeds=np.array([sc.seed]), preset=sc.thresholds, duration_s=sc.duration_s,
                         epoch_s=sc.link.epoch_s, record_steps=True)
    new_auth = log.column("authority").to_pylist()
    assert [i for i, a in enumerate(new_auth) if a == "waiting"] == [i for i, a in enumerate(raw) if a == "hold"]
    new = tmp_path / "new.parquet"
    old_table = pq.read_table(old)
    renamed = old_table.set_column(old_table.column_names.index("authority"), "authority",
                                   [["waiting" if a == "hold" else a for a in raw]])
    write_steplog(renamed, new)
    res = run("compare_campaigns.py", [str(old), str(new)], tmp_path)
    assert res.returncode == 0 and "identical: yes" in res.stdout, res.stdout + res.stderr
    assert read_steplog(old).column("authority").to_pylist() == renamed.column("authority").to_pylist()  # (the reader too)
    # as run directories, and as directories of runs (one per scenario)
    for d, f in ((tmp_path / "A" / "head_on", old), (tmp_path / "B" / "head_on", new)):
        d.mkdir(parents=True)
        (d / "steplog.parquet").write_bytes(f.read_bytes())
    res = run("compare_campaigns.py", [str(tmp_path / "A"), str(tmp_path / "B")], tmp_path)
    assert res.returncode == 0 and "head_on/steplog.parquet: 180 rows" in res.stdout, res.stdout + res.stderr
    i = new_auth.index("waiting")
    auth = renamed.column("authority").to_pylist()
    changed = renamed.set_column(renamed.column_names.index("authority"), "authority", [auth[:i] + ["daa"] + auth[i + 1:]])
    write_steplog(changed, new)
    res = run("compare_campaigns.py", [str(old), str(new)], tmp_path)
    assert res.returncode == 1 and "'authority' differs" in res.stdout
    helptext = run("compare_campaigns.py", ["--help"], tmp_path).stdout
    assert "'hold' -> 'waiting'" in helptext


@pytest.mark.slow  # ~100 s: two more copies of the packages, each compiling its kernels once
def test_bench_sil_pairs_its_runs_with_a_baseline_of_the_same_interpreter(tmp_path):
    """``--baseline-python``: a checkout without its own venv (here this one) as the baseline, run by the given
    interpreter; with two repeats the paired differences are printed, and the step logs compared."""
    from daa_sil.waitmap.cache import cache_dir

    res = run("bench_sil.py", ["--part", "lockstep", "--repeat", "2", "--pyc", "present", "--baseline", str(ROOT),
                               "--baseline-python", sys.executable, "--baseline-cache", str(cache_dir())], tmp_path)
    out = res.stdout + res.stderr
    assert res.returncode == 0, out[-3000:]
    assert "=> paired, new - base, median over 2 back-to-back repeats (with .pyc): wall s " in out, out[-3000:]
    assert "(lower in " in out and "/2)" in out
    assert "=> step logs identical to the baseline's: yes" in out, out[-3000:]
