"""End to end through three real processes (``daa-sil run``, lockstep), parity with fast-time, Ctrl-C."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from daa_sil.sil.scenario import delay_models, encounter_set, load_scenario
from daa_sil.steplog import read_steplog
from vehicle.core import build_policy
from sil_helpers import wait_for_vehicle_time

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = sorted((ROOT / "scenarios").glob("*.yaml"))
RUN = [sys.executable, "-m", "daa_sil.cli", "run"]
LIMIT_S = 180  # generous bound so a hung process fails the test instead of blocking CI


def _run(scenario: Path, out: Path, *extra: str) -> subprocess.CompletedProcess:
    return subprocess.run(RUN + [str(scenario), "--out", str(out), *extra], capture_output=True, text=True,
                          timeout=LIMIT_S, cwd=ROOT)


def _procs_mentioning(text: str) -> list[int]:
    """PIDs whose command line contains ``text`` (our unique output directory)."""
    pids = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                cmd = (d / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
            except OSError:
                continue
            if text in cmd and int(d.name) != os.getpid():
                pids.append(int(d.name))
    return pids


@pytest.mark.parametrize("path", SCENARIOS, ids=[p.stem for p in SCENARIOS])
def test_every_scenario_meets_its_expected_outcome(path, tmp_path):
    out = tmp_path / "run"
    cp = _run(path, out, "--json")
    assert cp.returncode == 0, cp.stdout[-2000:] + cp.stderr[-2000:]
    res = json.loads(cp.stdout)
    sc = load_scenario(path)
    assert res["expectation"] == {"checked": True, "ok": True, "violations": []}
    assert res["steps"] == sc.n_steps and res["clock"] == "lockstep"
    table = read_steplog(out / "steplog.parquet")
    assert table.num_rows == sc.n_steps
    assert (out / "result.json").is_file() and (out / "gcs_commands.jsonl").is_file()
    # the summary agrees with the step log it came from
    assert res["lowc"] == any(table.column("lowc").to_pylist())
    assert res["n_active_steps"] == sum(d != "none" for d in table.column("decision").to_pylist())
    assert _procs_mentioning(str(out)) == []


def test_link_loss_hands_control_to_daa_within_timeout(tmp_path):
    path = ROOT / "scenarios" / "link_loss.yaml"
    sc = load_scenario(path)
    out = tmp_path / "run"
    assert _run(path, out).returncode == 0
    rows = read_steplog(out / "steplog.parquet").to_pylist()
    # outage starts at 30 s; the last GCS packet (sent 29 s) arrives at 29 + 4 = 33 s; timeout 10 s
    last_arrival = sc.link.outages[0].start_s - 1 + 4
    lost = [r for r in rows if r["decision"] == "link_lost"]
    assert lost, "the agent never declared link loss"
    assert last_arrival + build_policy(sc).link_timeout_s < lost[0]["t"] <= last_arrival + build_policy(sc).link_timeout_s + 1
    assert all(r["authority"] == "daa" for r in lost)
    # no link_lost while packets were still arriving
    assert not [r for r in rows if r["decision"] == "link_lost" and r["t"] <= last_arrival + build_policy(sc).link_timeout_s]


def test_lockstep_is_deterministic_and_matches_fast_time(tmp_path):
    from daa_sil.study.simulation.fasttime import simulate
    from sil_helpers import sil_fast_time

    path = ROOT / "scenarios" / "head_on.yaml"
    sc = load_scenario(path)
    seqs = []
    for i in range(2):
        out = tmp_path / f"run{i}"
        assert _run(path, out).returncode == 0
        t = read_steplog(out / "steplog.parquet")
        seqs.append([(a, d) for a, d in zip(t.column("t").to_pylist(), t.column("decision").to_pylist()) if d != "none"])
    assert seqs[0] == seqs[1] and len(seqs[0]) > 0
    up, down = delay_models(sc)
    pol, lookup, pilot, daa = sil_fast_time(sc)  # the SIL flies the study's default reading
    _, _, steps = simulate(encounter_set(sc), pol, up, down, pilot, daa, wait_lookup=lookup, seeds=np.array([sc.seed]),
                           preset=sc.thresholds, duration_s=sc.duration_s, epoch_s=sc.link.epoch_s, record_steps=True)
    fast = [(a, d) for a, d in zip(steps.column("t").to_pylist(), steps.column("decision").to_pylist()) if d != "none"]
    assert fast == seqs[0]


def test_ctrl_c_leaves_no_orphans_and_a_valid_steplog(tmp_path):
    out = tmp_path / "run"
    # real time at 20x: a 180 s scenario takes ~9 s, so the interrupt lands mid-encounter
    proc = subprocess.Popen(RUN + [str(ROOT / "scenarios" / "head_on.yaml"), "--out", str(out),
                                   "--clock", "realtime", "--speed", "20"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    try:
        wait_for_vehicle_time(out, 20, proc)
        assert len(_procs_mentioning(str(out))) >= 3  # orchestrator + vehicle + shim + gcs
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, err
    assert "interrupted" in err and "Traceback" not in err
    assert _procs_mentioning(str(out)) == []
    table = read_steplog(out / "steplog.parquet")
    assert 20 <= table.num_rows < 180
    assert json.loads((out / "result.json").read_text())["interrupted"] is True


def test_bad_scenario_is_one_line_exit_2(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: x\nownship: {alt_m: 1000, gs_mps: 55, track_deg: 0}\nintruders: []\n")
    cp = _run(bad, tmp_path / "o")
    assert cp.returncode == 2
    assert cp.stderr.strip() == f"daa-sil: error: {bad}:3: intruders: must have 1..8 items, got 0"
    assert not (tmp_path / "o" / "logs").exists()  # nothing was started
