"""Every size-like input has its range, checked before any work: intruders 1..8 everywhere, the
encounters' stated upper bound, workers at most 4 per core, wait-map grids, bootstrap replicates;
where the product of sizes matters, the estimated peak memory is checked against the machine's.

Each refusal is one line, exit 2, and nothing is written, sampled, built or started. The commands
that would allocate or spawn on a version without these checks run bounded (``tests/bounded.py``:
own session, 3 GiB of address space per process, CPU limit, bounded wait, killed in teardown), or
with the process pool replaced by a fake that fails the test if it is ever constructed. The memory
estimates are checked against the peak RSS measured of real runs (an upper bound, and not more than
a few times it).
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import io
import subprocess
import sys
from pathlib import Path

import pytest

import bounded
from daa_sil.cli import main

ROOT = Path(__file__).resolve().parents[1]


def cli(argv) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            rc = main([str(a) for a in argv])
        except SystemExit as exc:
            rc = exc.code
    return int(rc), out.getvalue(), err.getvalue()


def machine_gib() -> str:
    """This machine's memory as the refusals name it, from /proc/meminfo (not from the code under test)."""
    kb = next(int(line.split()[1]) for line in Path("/proc/meminfo").read_text().splitlines()
              if line.startswith("MemTotal:"))
    return f"{kb * 1024 / 2**30:.1f} GiB"


@pytest.fixture
def no_work(monkeypatch):
    """Fail the test if a campaign gets as far as running, or any process pool is created."""
    import daa_sil.study.campaign.run as campaign

    def refuse(*a, **k):
        raise AssertionError("the campaign started: the input was not checked first")

    class NoPool:
        def __init__(self, *a, **k):
            raise AssertionError(f"a process pool was created ({k.get('max_workers', a[:1])} workers)")

    monkeypatch.setattr(campaign, "run_campaign", refuse)
    monkeypatch.setattr(cf, "ProcessPoolExecutor", NoPool)


MEASURE = ("import resource, subprocess, sys; rc = subprocess.call(sys.argv[1:]); "
           "print('PEAK_RSS_KB', resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss, file=sys.stderr); "
           "sys.exit(rc)")


def run_measured(argv: list, cwd: Path, timeout: float = 300.0) -> tuple[subprocess.CompletedProcess, int]:
    """Run ``argv`` bounded under a small wrapper that reports the peak RSS (bytes) of its largest
    process; returns (result with the report line removed from stderr, peak bytes)."""
    cp = bounded.run([sys.executable, "-c", MEASURE, *argv], cwd, timeout=timeout)
    lines = cp.stderr.splitlines()
    peak = [int(ln.split()[1]) * 1024 for ln in lines if ln.startswith("PEAK_RSS_KB")]
    cp.stderr = "\n".join(ln for ln in lines if not ln.startswith("PEAK_RSS_KB")) + "\n"
    return cp, (peak[0] if peak else -1)


# --- intruders 1..8, everywhere -------------------------------------------------------------------
@pytest.mark.parametrize("argv,needle", [
    (["campaign", "run", "--intruders", "9", "--encounters", "5"], "--intruders must be an integer within [1, 8], got 9"),
    (["campaign", "run", "--intruders", "0", "--encounters", "5"], "--intruders must be an integer within [1, 8], got 0"),
    (["campaign", "sweep", "--vary", "intruders=1,9", "--encounters", "5"], "--intruders must be an integer within [1, 8], got 9"),
], ids=["run-9", "run-0", "sweep-9"])
def test_intruders_out_of_range_are_refused_by_campaigns(argv, needle, tmp_path, no_work):
    out = tmp_path / "o"
    rc, _, err = cli(argv + ["--out", out])
    assert rc == 2
    bounded.one_error_line(err, needle)
    assert not out.exists()


def test_daa_takes_at_most_eight_intruders():
    state = "500,6000,1000,0,-55,0"
    rc, _, err = cli(["daa", "--own", "0,0,1000,0,55,0"] + [a for _ in range(9) for a in ("--intruder", state)])
    assert rc == 2
    bounded.one_error_line(err, "--intruder is given 9 times; at most 8 intruders")
    rc, out, _ = cli(["daa", "--own", "0,0,1000,0,55,0"] + [a for _ in range(8) for a in ("--intruder", state)])
    assert rc == 0 and out.count("warning") >= 8  # eight are fine: one alert level each


def test_campaign_config_validate_checks_the_upper_limits():
    from daa_sil.errors import UsageError
    from daa_sil.study.campaign.config import CampaignConfig

    for kw, needle in ((dict(n_intruders=9), "--intruders"), (dict(n_intruders=1000), "--intruders"),
                       (dict(n_encounters=10_000_001), "--encounters"), (dict(chunk_size=10_000_001), "--chunk-size"),
                       (dict(seed=2**63), "--seed")):
        with pytest.raises(UsageError, match=needle):
            CampaignConfig(groups=("B-1",), **kw).validate()
    CampaignConfig(groups=("B-1",), n_intruders=8, n_encounters=10_000_000).validate()  # the ends are allowed


# --- sizes whose product matters: refused by memory before anything is allocated ------------------
def test_absurd_campaign_sizes_are_one_line_and_allocate_nothing(tmp_path):
    """The issue's typos: 1,000 intruders (6 GB in 9.9 s) and 10,000,000 encounters (65 MB/s, silent)."""
    cases = [
        (["--intruders", "1000"], ["--intruders must be an integer within [1, 8], got 1000"]),
        (["--encounters", "10000001"], ["--encounters must be an integer within [1, 10,000,000]"]),
        (["--encounters", "10000000"], ["this campaign would need about", "encounter set (10,000,000 x 1 intruder)",
                                        f"this machine has {machine_gib()}", "--allow-large"]),
        (["--encounters", "100000", "--batch-rows", "5000000"], ["would need about", "one task in this process",
                                                                 f"this machine has {machine_gib()}"]),
        (["--waitmap", "paper,dx=200,dy=200,dh=100,vi=100"], ["10,000,000,000 states",
                                                              f"this machine has {machine_gib()}"]),
    ]
    for extra, needles in cases:
        out = tmp_path / "o"
        cp, peak = run_measured(bounded.cli_argv("campaign", "run", "--out", out, *extra), tmp_path, timeout=120)
        assert cp.returncode == 2, (extra, cp.returncode, cp.stderr[-2000:])
        bounded.one_error_line(cp.stderr, *needles)
        assert not out.exists(), extra
        assert 0 < peak < 400 * 2**20, (extra, peak)  # refused before anything was sampled or built


def test_allow_large_is_the_explicit_way_past_the_memory_check(tmp_path, monkeypatch):
    """The refusal names --allow-large; with it the same campaign goes on to run (stopped here before
    any work by a fake run, as this machine could not hold it)."""
    from daa_sil.runtime.resources import memory_budget
    from daa_sil.study.campaign import run as campaign
    from daa_sil.study.campaign.config import CampaignConfig
    from daa_sil.study.campaign.memory import campaign_memory

    cfg = CampaignConfig(groups=("B-1",), n_encounters=10_000_000)
    assert campaign_memory(cfg, 1, 10_000).total > memory_budget()
    reached = []
    monkeypatch.setattr(campaign, "make_executor", lambda *a, **k: reached.append(a) or contextlib.nullcontext())
    monkeypatch.setattr(campaign, "_run_with", lambda *a, **k: (_ for _ in ()).throw(KeyboardInterrupt()))
    with pytest.raises(KeyboardInterrupt):
        campaign.run_campaign(cfg, tmp_path / "big", allow_large=True, progress=False)
    assert reached  # past every check


def test_workers_beyond_four_per_core_start_no_process(tmp_path, no_work):
    """``--workers 1000`` started 1,049 processes, then a 22-line BrokenProcessPool traceback."""
    import os

    cores = len(os.sched_getaffinity(0))
    out = tmp_path / "o"
    rc, _, err = cli(["campaign", "run", "--workers", "1000", "--encounters", "5", "--out", out])
    assert rc == 2
    bounded.one_error_line(err, f"--workers must be within [1, {4 * cores}]", f"this machine has {cores}")
    rc, _, err = cli(["waitmap", "build", "--grid", "paper,dx=6,dy=6,dh=3,vi=3,vh=3,theta=4", "--turn-rates", "0",
                      "--workers", "1000", "--out", out])
    assert rc == 2
    bounded.one_error_line(err, f"--workers must be within [1, {4 * cores}]")
    assert not out.exists()


def test_report_replicates_have_an_upper_bound(tmp_path, no_work):
    rc, _, err = cli(["campaign", "report", tmp_path, "--replicates", "1000000000"])
    assert rc == 2
    bounded.one_error_line(err, "--replicates must be an integer within [100, 100,000]")


def test_wait_map_grids_are_bounded_before_any_array_is_made(tmp_path):
    """An axis of 10^9 points (an 8 GB linspace) and a grid of 10^10 states (2 builders x 9,686 GiB):
    one line, exit 2, nothing created, a small peak RSS."""
    cases = [
        (["--grid", "paper,dx=1e9"], ["grid axis 'dx': n must be an integer within [2, 1,000]"]),
        (["--grid", "paper,dx=200,dy=200,dh=100,vi=100"], ["building 5 wait maps of 10,000,000,000 states",
                                                            f"this machine has {machine_gib()}", "--allow-large"]),
    ]
    for extra, needles in cases:
        out = tmp_path / "maps"
        cp, peak = run_measured(bounded.cli_argv("waitmap", "build", "--out", out, *extra), tmp_path, timeout=120)
        assert cp.returncode == 2, (extra, cp.returncode, cp.stderr[-2000:])
        bounded.one_error_line(cp.stderr, *needles)
        assert not out.exists()
        assert 0 < peak < 400 * 2**20, (extra, peak)


# --- the estimates against measured runs ----------------------------------------------------------
def test_campaign_memory_estimate_bounds_a_measured_campaign(tmp_path):
    from daa_sil.study.campaign.config import CampaignConfig
    from daa_sil.study.campaign.memory import campaign_memory

    cfg = CampaignConfig(groups=("B-1", "ID-2"), n_encounters=3000, n_intruders=2)
    out = tmp_path / "c"
    cp, peak = run_measured(bounded.cli_argv("campaign", "run", "--groups", "B-1,ID-2", "--encounters", 3000,
                                             "--intruders", 2, "--out", out, "--no-progress"), tmp_path, timeout=900)
    assert cp.returncode == 0, cp.stderr[-2000:]
    est = campaign_memory(cfg, 1, 10_000).total
    assert peak <= est <= 4 * peak, (peak, est)


def test_build_memory_estimate_bounds_a_measured_build(tmp_path):
    from daa_sil.waitmap.build import build_memory
    from daa_sil.waitmap.grid import resolve_grid

    spec = "paper,dx=24,dy=24"
    cp, peak = run_measured(bounded.cli_argv("waitmap", "build", "--grid", spec, "--turn-rates", "0,5",
                                             "--workers", "1", "--out", tmp_path / "m"), tmp_path, timeout=900)
    assert cp.returncode == 0, cp.stderr[-2000:]
    est = build_memory(resolve_grid(spec), 2, 1).total
    assert peak <= est <= 4 * peak, (peak, est)
