"""Lockstep is deterministic on a faulty link (issue 20): the same scenario and seed give the same step
log even when the wall clock changes how many datagrams the shim sees.

The three processes (shim, GCS, vehicle) are started here by hand, as a user would, twice with the
same 60 s scenario (20 % loss, 20 % duplication, 20 % reordering each way). In the second run the
vehicle starts 4 s after the GCS is ready instead of at once, so the GCS greets the shim (a
HEARTBEAT every 0.1 s until the first tick) tens of times more: traffic that exists only because
of wall-clock timing. Every step-log cell must still be identical, and the faults must really have
happened in both runs.

Before the fix (the shim drew each datagram's loss / duplication / reordering from one sequential
stream per direction) the extra greetings shifted the uplink's draws and the step logs differed
(pilot commands lost at other steps, hence other command ages, bands and decisions).
"""

from __future__ import annotations

import json
import selectors
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

from daa_sil.sil.play import shim_argv
from daa_sil.sil.scenario import load_scenario
from daa_sil.sil.supervise import parse_shim_ready
from daa_sil.steplog import cells_equal, read_steplog

ROOT = Path(__file__).resolve().parents[1]
HANG_GUARD_S = 300  # hang guard only: a hung process fails the test instead of blocking CI
LOCKSTEP = ["--clock", "lockstep"]
SCENARIO = """\
name: short-loss-dup-reorder
description: head-on, 4 s delay each way, 20 % loss, duplication and reordering each way, scripted pilot
seed: 31
duration_s: 60
ownship: {alt_m: 1000, gs_mps: 55, track_deg: 0}
intruders:
  - callsign: HEAD1
    cpa: {angle_deg: 180, hmd_m: 150, t_cpa_s: 40, gs_mps: 60}
pilot:
  mode: scripted
  commands: [{t_s: 2, until_s: 58, track_deg: 0, gs_mps: 55, vs_mps: 0}]
allocation: {group: ID-1, link_timeout_s: 10}
link: {up: "const:4", down: "const:4", loss: 0.2, dup: 0.2, reorder: 0.2}
"""


def _read_until(proc: subprocess.Popen, stream, parse, what: str):
    """First line of ``proc``'s ``stream`` that ``parse`` accepts (bounded by the hang guard); the rest of
    the stream is then drained by a thread (so the process never blocks on a full pipe)."""
    sel = selectors.DefaultSelector()
    sel.register(stream, selectors.EVENT_READ)
    end = time.monotonic() + HANG_GUARD_S
    try:
        while time.monotonic() < end:
            if not sel.select(timeout=1.0):
                assert proc.poll() is None, f"{what} exited ({proc.returncode}) before it was ready"
                continue
            line = stream.readline()
            assert line, f"{what} closed its output before it was ready"
            found = parse(line)
            if found:
                threading.Thread(target=stream.read, daemon=True).start()
                return found
    finally:
        sel.close()
    raise AssertionError(f"{what} was not ready within {HANG_GUARD_S} s")


def _stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
    try:
        proc.wait(timeout=60)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def _play(path: Path, out: Path, vehicle_delay_s: float) -> dict:
    """Shim, then GCS, then (``vehicle_delay_s`` wall s after the GCS is ready) the vehicle; lockstep.
    Returns the shim's stats."""
    out.mkdir()
    sc = load_scenario(path)
    procs = []
    try:
        shim = subprocess.Popen(shim_argv(sc, LOCKSTEP, [], out / "shim_stats.json"), cwd=ROOT, text=True,
                                stdout=(out / "shim.json").open("w"), stderr=subprocess.PIPE)
        procs.append(shim)
        sides = _read_until(shim, shim.stderr, parse_shim_ready, "the shim")
        gcs = subprocess.Popen([sys.executable, "-m", "gcs", "--scenario", str(path), "--listen", "udp:127.0.0.1:0",
                                "--vehicle", sides["gcs_side"], "--log", str(out / "gcs_commands.jsonl"), *LOCKSTEP],
                               cwd=ROOT, text=True, stdout=subprocess.PIPE, stderr=(out / "gcs.log").open("w"))
        procs.append(gcs)
        _read_until(gcs, gcs.stdout, lambda line: line.startswith("READY"), "the GCS")
        time.sleep(vehicle_delay_s)  # the GCS greets the shim meanwhile (wall-clock traffic)
        veh = subprocess.run([sys.executable, "-m", "vehicle", str(path), "--listen", "udp:127.0.0.1:0",
                              "--out", sides["vehicle_side"], "--tap", "none", "--quiet", "--exit-at-end",
                              "--steplog", str(out / "steplog.parquet"), *LOCKSTEP],
                             cwd=ROOT, capture_output=True, text=True, timeout=HANG_GUARD_S)
        assert veh.returncode == 0, veh.stdout[-2000:] + veh.stderr[-2000:]
    finally:
        for p in reversed(procs):
            _stop(p)
    assert shim.returncode == 0, f"the shim exited {shim.returncode}"
    return json.loads((out / "shim_stats.json").read_text())


def test_lockstep_step_log_does_not_depend_on_wall_clock_traffic(tmp_path):
    path = tmp_path / "short_loss_dup_reorder.yaml"
    path.write_text(SCENARIO)
    stats = {"at_once": _play(path, tmp_path / "at_once", 0.0),
             "late": _play(path, tmp_path / "late", 4.0)}
    # the runs really differ in wall-clock traffic: more GCS greetings before the first tick
    greet = {k: s["counters"]["datagrams_from_gcs"] for k, s in stats.items()}
    assert greet["late"] >= greet["at_once"] + 5, greet
    # the faults really happened, in both directions, in both runs
    for k, s in stats.items():
        for d in ("up", "down"):
            line = s[d]
            assert line["dropped_loss"] > 0 and line["duplicated"] > 0 and line["reordered"] > 0, (k, d, line)
            assert 0.05 * line["pushed"] < line["dropped_loss"] < 0.4 * line["pushed"], (k, d, line)
    a = read_steplog(tmp_path / "at_once" / "steplog.parquet").to_pylist()
    b = read_steplog(tmp_path / "late" / "steplog.parquet").to_pylist()
    assert len(a) == len(b) == 60
    assert sum(r["pilot_cmd_received"] for r in a) > 10  # commands got through (the link carries the run)
    diff = [(ra["t"], k) for ra, rb in zip(a, b) for k in ra if not cells_equal(ra[k], rb[k])]
    assert not diff, f"{len(diff)} cells differ, first: {diff[:10]}"
    # the simulation's own datagrams met the same faults: equal counts once start-up traffic is set aside
    assert stats["at_once"]["down"]["dropped_loss"] == stats["late"]["down"]["dropped_loss"]
