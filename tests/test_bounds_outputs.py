"""Outputs: ``--out`` is held while a run writes it; a busy or non-empty one is refused in one line
(``--force`` replaces a previous run, ``campaign run --resume`` continues one); output names are
checked at start-up (UTF-8, name length) by every command that takes one; a run whose directory
becomes unwritable mid-run saves its step log and result.json elsewhere and says where; a demo whose
standard output closes still plays; a directory named ``run-12:30`` is a path; an ``--out`` that looks
like a MAVLink connection is refused before anything runs.

Every command runs bounded (``tests/bounded.py``) with bounded waits, and the teardown kills its
session.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

import bounded

ROOT = Path(__file__).resolve().parents[1]
HEAD_ON = ROOT / "scenarios" / "head_on.yaml"
LONG_NAME = "n" * 300
WAIT_S = 120.0


def read_steps(path: Path) -> int:
    import pyarrow as pa
    import pyarrow.parquet as pq

    with pa.OSFile(str(path), "rb") as fh:  # a path with a colon is not a URI
        return pq.read_table(fh).num_rows


def wait_for(pred, proc: "subprocess.Popen | None" = None, what: str = "") -> None:
    end = time.monotonic() + WAIT_S
    while time.monotonic() < end:
        if pred():
            return
        if proc is not None and proc.poll() is not None:
            pytest.fail(f"the run ended before {what}: {proc.communicate()}")
        time.sleep(0.05)
    pytest.fail(f"timed out waiting for {what}")


# --- names checked at start-up, by every command that writes one ----------------------------------
def test_a_300_character_output_name_is_one_line_in_every_command(tmp_path):
    cases = [
        bounded.cli_argv("campaign", "run", "--encounters", 5, "--out", LONG_NAME),
        bounded.cli_argv("waitmap", "build", "--grid", "paper,dx=6,dy=6,dh=3,vi=3,vh=3,theta=4", "--turn-rates", "0",
                         "--out", LONG_NAME),
        bounded.cli_argv("run", HEAD_ON, "--out", "o", "--rrd", LONG_NAME + ".rrd"),
        [sys.executable, "-m", "vehicle", HEAD_ON, "--steplog", LONG_NAME + ".parquet", "--clock", "lockstep"],
        bounded.cli_argv("shim", "--delay", "const:1", "--stats-json", LONG_NAME + ".json", "--duration", 1),
    ]
    for argv in cases:
        cp = bounded.run(argv, tmp_path, timeout=WAIT_S)
        assert cp.returncode == 2, (argv[2:5], cp.returncode, cp.stderr[-1500:])
        bounded.one_error_line(cp.stderr, "bytes long; the file system takes at most")
        assert sorted(os.listdir(tmp_path)) == [], (argv[2:5], os.listdir(tmp_path))


def test_a_steplog_name_that_is_not_utf8_is_refused_before_the_flight(tmp_path):
    """It used to fly 170 s and then die with UnicodeEncodeError, the step log lost."""
    name = os.fsdecode(b"log-\xff.parquet")
    cp = bounded.run([sys.executable, "-m", "vehicle", HEAD_ON, "--steplog", name, "--clock", "realtime", "--speed", 1],
                     tmp_path, timeout=WAIT_S)
    assert cp.returncode == 2, cp.stderr[-1500:]
    bounded.one_error_line(cp.stderr, "--steplog", "not valid UTF-8", "\\xff")
    assert "READY" not in cp.stdout  # nothing was bound or flown


# --- one writer per directory ---------------------------------------------------------------------
def test_a_second_run_into_a_busy_out_is_refused_and_the_first_is_whole(tmp_path):
    out = tmp_path / "shared"
    first = bounded.start(bounded.cli_argv("run", HEAD_ON, "--out", out, "--clock", "realtime", "--speed", 10,
                                           "--quiet"), tmp_path)
    kids = []
    try:
        wait_for(lambda: (out / "logs" / "vehicle.log").is_file(), first, "the first run started")
        kids = bounded.descendants(first.pid)
        second = bounded.run(bounded.cli_argv("run", HEAD_ON, "--out", out, "--quiet"), tmp_path, timeout=WAIT_S)
        assert second.returncode == 2, second.stderr
        bounded.one_error_line(second.stderr, f"--out {out} is in use by another daa-sil process (pid {first.pid})")
        forced = bounded.run(bounded.cli_argv("run", HEAD_ON, "--out", out, "--force"), tmp_path, timeout=WAIT_S)
        assert forced.returncode == 2, forced.stderr  # --force replaces a finished run, never a running one
        _, err = first.communicate(timeout=WAIT_S)
        assert first.returncode == 0, err
    finally:
        bounded.kill_session(first, kids)
    result = json.loads((out / "result.json").read_text())
    assert result["clock"] == "realtime" and result["files"]["steplog"] == str(out / "steplog.parquet")
    assert read_steps(out / "steplog.parquet") == result["steps"] == 180
    log = (out / "logs" / "vehicle.log").read_text()
    assert log.count("READY") == 1  # one vehicle's log, not two interleaved
    assert not (out / ".daa-sil.lock").exists()


def test_a_non_empty_out_is_refused_and_force_replaces_the_run(tmp_path):
    out = tmp_path / "o"
    cp = bounded.run(bounded.cli_argv("run", HEAD_ON, "--out", out, "--quiet"), tmp_path, timeout=WAIT_S)
    assert cp.returncode == 0, cp.stderr
    (out / "mine.txt").write_text("kept")
    before = {p.name: p.stat().st_mtime_ns for p in out.iterdir()}
    again = bounded.run(bounded.cli_argv("run", HEAD_ON, "--out", out, "--quiet"), tmp_path, timeout=WAIT_S)
    assert again.returncode == 2
    bounded.one_error_line(again.stderr, f"--out {out} is not empty", "--force")
    assert {p.name: p.stat().st_mtime_ns for p in out.iterdir()} == before  # untouched, no lock file left
    forced = bounded.run(bounded.cli_argv("run", HEAD_ON, "--out", out, "--force", "--quiet"), tmp_path,
                         timeout=WAIT_S)
    assert forced.returncode == 0, forced.stderr
    assert (out / "mine.txt").read_text() == "kept"  # --force replaces the run's files only
    assert (out / "result.json").stat().st_mtime_ns > before["result.json"]


def test_campaign_resume_takes_its_own_directory_and_a_busy_one_is_refused(tmp_path):
    out = tmp_path / "c"
    proc = bounded.start(bounded.cli_argv("campaign", "run", "--groups", "B-1,ID-2", "--encounters", 4000,
                                          "--out", out, "--no-progress"), tmp_path)
    try:
        wait_for(lambda: (out / "campaign.json").is_file(), proc, "the campaign started")
        cp = bounded.run(bounded.cli_argv("campaign", "run", "--out", out, "--resume"), tmp_path, timeout=WAIT_S)
        assert cp.returncode == 2, cp.stderr
        bounded.one_error_line(cp.stderr, "is in use by another daa-sil process", f"pid {proc.pid}")
    finally:
        bounded.kill_session(proc)
        proc.wait(timeout=WAIT_S)
    cp = bounded.run(bounded.cli_argv("campaign", "run", "--out", out, "--resume", "--no-progress"), tmp_path,
                     timeout=900)  # the killed holder's lock file is stale: the kernel dropped its lock
    assert cp.returncode == 0, cp.stderr
    assert json.loads((out / "campaign.json").read_text())["status"] == "complete"


# --- a directory that becomes unwritable mid-run ----------------------------------------------------
def test_a_run_whose_out_becomes_unwritable_saves_its_step_log_elsewhere_and_says_where(tmp_path):
    """Run without CAP_DAC_OVERRIDE, so that a 0555 directory is read-only to it even as root."""
    rescue = tmp_path / "rescue"
    out = tmp_path / "runs" / "o"
    proc = bounded.start(bounded.cli_argv("run", HEAD_ON, "--out", out, "--clock", "realtime", "--speed", 10,
                                          "--quiet"), tmp_path, env={"DAA_SIL_RESCUE": str(rescue)}, drop_dac=True)
    kids = []
    try:
        log = out / "logs" / "vehicle.log"
        wait_for(lambda: log.is_file() and "t=   60s" in log.read_text(), proc, "the vehicle reached t = 60 s")
        kids = bounded.descendants(proc.pid)
        out.chmod(0o555)
        stdout, err = proc.communicate(timeout=WAIT_S)
    finally:
        out.chmod(0o755)
        bounded.kill_session(proc, kids)
    if proc.returncode == 128 + 97 or "Operation not permitted" in err:
        pytest.skip("cannot drop CAP_DAC_OVERRIDE here")
    assert proc.returncode == 1, err
    saved = sorted(rescue.rglob("*"))
    steplog = next(p for p in saved if p.name == "steplog.parquet")
    summary = next(p for p in saved if p.name == "result.json")
    bounded.one_error_line(err, f"{out} could not be written", str(steplog), str(summary))
    assert read_steps(steplog) == 180  # the whole flight
    result = json.loads(summary.read_text())
    assert result["steps"] == 180 and result["files"]["steplog"] == str(steplog)
    assert not (out / "steplog.parquet").exists() and not (out / "result.json").exists()
    assert f"step log: {steplog}" in stdout  # the summary names where the files are


# --- a demo whose standard output closes ------------------------------------------------------------
def test_a_demo_whose_stdout_closes_still_plays(tmp_path):
    """``daa-sil demo --out D | true`` exited 0 having played nothing. It plays on: the run is the
    product (D), its commentary on stdout is not; one note on stderr says so."""
    out = tmp_path / "D"
    r, w = os.pipe()
    os.close(r)  # the reader is gone before the demo writes its first line
    proc = bounded.start(bounded.cli_argv("demo", "--out", out), tmp_path, stdout=w)
    os.close(w)
    try:
        _, err = proc.communicate(timeout=WAIT_S)
    finally:
        bounded.kill_session(proc)
    assert proc.returncode == 0, err
    assert "Traceback" not in err
    assert "standard output was closed; playing on" in err
    result = json.loads((out / "result.json").read_text())
    assert result["steps"] == 180 and read_steps(out / "steplog.parquet") == 180


# --- directories are paths whatever their characters; MAVLink outputs go elsewhere ------------------
def test_an_out_with_a_colon_works_end_to_end(tmp_path):
    out = tmp_path / "run-12:30"
    cp = bounded.run(bounded.cli_argv("run", HEAD_ON, "--out", "run-12:30", "--json"), tmp_path, timeout=WAIT_S)
    assert cp.returncode == 0, cp.stderr[-2000:]
    result = json.loads((out / "result.json").read_text())
    assert result["steps"] == 180 and read_steps(out / "steplog.parquet") == 180
    assert json.loads(cp.stdout)["steps"] == 180
    camp = bounded.run(bounded.cli_argv("campaign", "run", "--groups", "B-1", "--encounters", 10, "--out", "camp-12:30",
                                        "--no-progress"), tmp_path, timeout=600)
    assert camp.returncode == 0, camp.stderr[-2000:]
    rep = bounded.run(bounded.cli_argv("campaign", "report", "camp-12:30", "--replicates", 100), tmp_path, timeout=600)
    assert rep.returncode == 0, rep.stderr[-2000:]


@pytest.mark.parametrize("conn", ["udp:127.0.0.1:14550", "udpin:0.0.0.0:14550", "tcp:127.0.0.1:5760",
                                  "tcpin:127.0.0.1:5760", "udpout:127.0.0.1:14550", "serial:/dev/ttyUSB0"])
def test_an_out_that_looks_like_mavlink_points_at_vehicle_out(conn, tmp_path):
    cp = bounded.run(bounded.cli_argv("run", HEAD_ON, "--out", conn), tmp_path, timeout=WAIT_S)
    assert cp.returncode == 2, cp.stderr[-1500:]
    bounded.one_error_line(cp.stderr, "looks like a MAVLink connection", f"--vehicle-out {conn}")
    assert os.listdir(tmp_path) == []  # nothing ran, nothing left behind
