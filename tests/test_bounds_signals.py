"""Campaign signals: two Ctrl-Cs a few milliseconds apart (as a terminal sends them, to the whole
process group), SIGTERM and SIGKILL of the driver, with one worker, two workers and a local Dask
cluster. Afterwards: the status (130 / 143), exactly one line naming ``--resume`` and no traceback,
every worker gone (checked by pid with psutil), and ``--resume`` finishing the campaign.

Each campaign runs bounded (``tests/bounded.py``: own session, 3 GiB of address space per process,
CPU limit) and every wait is bounded; the teardown kills the session and any process it started.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time
from pathlib import Path

import pytest

import bounded

CAMPAIGN = ["campaign", "run", "--groups", "B-1,ID-2", "--no-progress"]
#: wall seconds any one wait may take (a hang fails the test instead of blocking the suite)
WAIT_S = 120.0


def start(tmp_path: Path, workers: int, encounters: int = 4000, *extra) -> tuple[subprocess.Popen, Path]:
    out = tmp_path / "camp"
    argv = bounded.cli_argv(*CAMPAIGN, "--encounters", encounters, "--workers", workers, "--out", out, *extra)
    return bounded.start(argv, tmp_path), out


def wait_computing(proc: subprocess.Popen, out: Path, n_children: int) -> list:
    """Block until the campaign computes its chunks (campaign.json written, ``n_children`` processes
    below the driver); its descendants then."""
    end = time.monotonic() + WAIT_S
    while time.monotonic() < end:
        assert proc.poll() is None, proc.communicate()
        kids = bounded.descendants(proc.pid)
        if (out / "campaign.json").is_file() and len(kids) >= n_children:
            time.sleep(1.0)  # into the first tasks
            return bounded.descendants(proc.pid)
        time.sleep(0.1)
    pytest.fail("the campaign did not start computing")


def finish(proc: subprocess.Popen) -> tuple[int, str]:
    """The driver's exit status and stderr, waiting at most :data:`WAIT_S`."""
    try:
        _, err = proc.communicate(timeout=WAIT_S)
    except subprocess.TimeoutExpired:
        pytest.fail(f"the driver did not exit within {WAIT_S:g} s of the signal (a hang)")
    return proc.returncode, err


def resume_completes(tmp_path: Path, out: Path) -> None:
    cp = bounded.run(bounded.cli_argv("campaign", "run", "--out", out, "--resume", "--no-progress"), tmp_path,
                     timeout=900)
    assert cp.returncode == 0, cp.stderr[-2000:]
    assert json.loads((out / "campaign.json").read_text())["status"] == "complete"


@pytest.mark.parametrize("workers", [2, 1])
def test_two_ctrl_c_stop_the_campaign_with_one_line(tmp_path, workers):
    proc, out = start(tmp_path, workers)
    kids = []
    try:
        kids = wait_computing(proc, out, workers if workers > 1 else 0)
        os.killpg(proc.pid, signal.SIGINT)
        time.sleep(0.02)
        os.killpg(proc.pid, signal.SIGINT)
        rc, err = finish(proc)  # a hang fails after WAIT_S
        assert rc == 130, err
        bounded.one_error_line(err, "daa-sil: interrupted by SIGINT", f"daa-sil campaign run --out {out} --resume")
        assert not bounded.wait_gone(kids, 10.0), [p.pid for p in bounded.alive(kids)]
    finally:
        bounded.kill_session(proc, kids)
    if workers > 1:
        resume_completes(tmp_path, out)


def test_sigterm_of_the_driver_stops_its_workers(tmp_path):
    proc, out = start(tmp_path, 2)
    kids = []
    try:
        kids = wait_computing(proc, out, 2)
        os.kill(proc.pid, signal.SIGTERM)  # the driver only, as `timeout` or a CI cancel does
        rc, err = finish(proc)
        assert rc == 128 + signal.SIGTERM, err
        bounded.one_error_line(err, "daa-sil: interrupted by SIGTERM", "--resume")
        assert not bounded.wait_gone(kids, 10.0), [p.pid for p in bounded.alive(kids)]
    finally:
        bounded.kill_session(proc, kids)


def test_sigkill_of_the_driver_kills_its_workers(tmp_path):
    proc, out = start(tmp_path, 2)
    kids = []
    try:
        kids = wait_computing(proc, out, 2)
        assert len(kids) >= 2
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=WAIT_S)
        left = bounded.wait_gone(kids, 10.0)
        assert not left, [(p.pid, p.ppid()) for p in left]  # no orphan adopted by init
    finally:
        bounded.kill_session(proc, kids)


def test_workers_carry_a_name_and_ignore_the_terminal_ctrl_c(tmp_path):
    """The pool's workers are called daa-sil-worker (pgrep finds them) and arm the parent-death
    signal (SIGKILL), so the kernel stops them with their driver."""
    proc, out = start(tmp_path, 2)
    kids = []
    try:
        kids = wait_computing(proc, out, 2)
        workers = [p for p in kids if p.name() == "daa-sil-worker"]
        assert len(workers) == 2, [(p.pid, p.name()) for p in kids]
        for p in workers:
            sig_ign = int(Path(f"/proc/{p.pid}/status").read_text().split("SigIgn:")[1].split()[0], 16)
            assert sig_ign & (1 << (signal.SIGINT - 1)), "a worker must ignore Ctrl-C: its driver stops it"
    finally:
        bounded.kill_session(proc, kids)


def test_local_dask_ctrl_c_twice_is_one_line_and_leaves_no_process(tmp_path):
    pytest.importorskip("dask.distributed")  # the optional executor (daa-sil[dist]); dev installs it
    proc, out = start(tmp_path, 2, 8000, "--scheduler", "local-dask")
    kids = []
    try:
        kids = wait_computing(proc, out, 2)
        os.killpg(proc.pid, signal.SIGINT)
        time.sleep(0.02)
        os.killpg(proc.pid, signal.SIGINT)
        rc, err = finish(proc)
        assert rc == 130, err
        bounded.one_error_line(err, "daa-sil: interrupted by SIGINT", "--resume")
        assert not bounded.wait_gone(kids, 15.0), [p.pid for p in bounded.alive(kids)]
    finally:
        bounded.kill_session(proc, kids)


def test_a_finished_campaign_names_the_report_step(tmp_path):
    out = tmp_path / "small"
    cp = bounded.run(bounded.cli_argv("campaign", "run", "--groups", "B-1", "--encounters", 20, "--out", out,
                                      "--no-progress"), tmp_path, timeout=600)
    assert cp.returncode == 0, cp.stderr
    assert f"next: daa-sil campaign report {out}" in cp.stderr
    assert not (out / ".daa-sil.lock").exists()  # the lock goes with the run


def test_a_ctrl_c_while_the_command_stops_is_ignored():
    """The first Ctrl-C stops the command; a second one a few ms later, while it cleans up or reports,
    must not escape as a bare KeyboardInterrupt (the interpreter would die by SIGINT, status -2)."""
    from daa_sil.sil.children import signals_interrupt

    try:
        with pytest.raises(KeyboardInterrupt):
            with signals_interrupt():
                os.kill(os.getpid(), signal.SIGINT)
                time.sleep(5.0)  # the handler raises at once
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
        os.kill(os.getpid(), signal.SIGINT)  # the second Ctrl-C: ignored, no exception
        time.sleep(0.05)
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)


def test_an_uninterrupted_block_gives_ctrl_c_back():
    from daa_sil.sil.children import signals_interrupt

    before = signal.getsignal(signal.SIGINT)
    with signals_interrupt():
        pass
    assert signal.getsignal(signal.SIGINT) is before
