"""The round-trip rule in the SIL: a scenario names the round trip (``link.round_trip``), the shim
splits each epoch's draw evenly between the two directions, and a lockstep run equals fast-time under
the same rule, bit for bit (the parity contract of tests/test_sil_parity.py)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from daa_sil.errors import FileFormatError
from daa_sil.models.latency import TruncatedGaussian
from daa_sil.models.link_rule import HalfRoundTrip
from daa_sil.sil.play import shim_argv
from daa_sil.sil.scenario import delay_models, encounter_set, link_legs, load_scenario
from daa_sil.sil.shim_config import ShimConfig, shim_delay_processes
from daa_sil.steplog import read_steplog

from test_sil_parity import column_differences

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = """\
name: head-on-round-trip
description: head-on, the paper's Gaussian latency (mean 5 s, sd 3 s) as the round trip, split evenly
seed: 11
duration_s: 180
thresholds: do365
ownship: {alt_m: 1000, gs_mps: 55, track_deg: 0}
intruders:
  - callsign: HEAD1
    cpa: {angle_deg: 180, hmd_m: 150, t_cpa_s: 120, gs_mps: 60}
link: {round_trip: "gauss:5,3", epoch_s: 10}
pilot: {mode: model, model: {response: deterministic}}
allocation: {group: ID-2}
"""


def _fast_time(sc, seed):
    from daa_sil.study.simulation.fasttime import simulate
    from sil_helpers import sil_fast_time

    legs = link_legs(sc)
    pol, lookup, pilot, daa = sil_fast_time(sc)  # the SIL flies the study's default reading
    return simulate(encounter_set(sc), pol, legs.up, legs.down, pilot, daa, wait_lookup=lookup, seeds=np.array([seed]),
                    preset=sc.thresholds, duration_s=sc.duration_s, epoch_s=sc.link.epoch_s, record_steps=True,
                    link_legs=legs)


def test_scenario_round_trip_form(tmp_path):
    path = tmp_path / "rt.yaml"
    path.write_text(SCENARIO)
    sc = load_scenario(path)
    legs = link_legs(sc)
    assert legs.shared and delay_models(sc) == (HalfRoundTrip(TruncatedGaussian(5, 3)),) * 2
    argv = shim_argv(sc, [], [], tmp_path / "s.json")
    assert argv[argv.index("--delay-round-trip") + 1] == "gauss:5,3" and "--delay-up" not in argv
    # the shim's processes are fast-time's: each direction half of the uplink stream's draw
    cfg = ShimConfig(delay_down=legs.down, delay_up=legs.up, round_trip=True, seed=sc.seed)
    procs = shim_delay_processes(cfg)
    _, _, steps = _fast_time(sc, sc.seed)
    t = np.asarray(steps.column("t").to_numpy())
    up = np.asarray(steps.column("delay_up_s").to_numpy())
    assert np.array_equal(up, [procs["up"].delay(x) for x in t]) and np.array_equal(up, [procs["down"].delay(x) for x in t])
    from daa_sil.sil.scenario import scenario_from_dict

    again = scenario_from_dict(sc.to_dict())  # the dict form round-trips (bench_sil.py uses it)
    assert again.link.round_trip == "gauss:5,3" and again.link.up is None and link_legs(again) == legs
    bad = tmp_path / "bad.yaml"
    bad.write_text(SCENARIO.replace('round_trip: "gauss:5,3"', 'round_trip: "gauss:5,3", up: "const:4"'))
    with pytest.raises(FileFormatError, match="either round_trip or up/down"):
        load_scenario(bad)


def test_lockstep_sil_with_a_split_round_trip_equals_fast_time(tmp_path):
    path = tmp_path / "rt.yaml"
    path.write_text(SCENARIO)
    sc = load_scenario(path)
    out = tmp_path / "run"
    cp = subprocess.run([sys.executable, "-m", "daa_sil.cli", "run", str(path), "--out", str(out), "--json"],
                        capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert cp.returncode == 0, cp.stdout[-2000:] + cp.stderr[-2000:]
    sil = read_steplog(out / "steplog.parquet")
    _, _, fast = _fast_time(sc, sc.seed)
    d_up, d_down = fast.column("delay_up_s").to_pylist(), fast.column("delay_down_s").to_pylist()
    assert d_up == d_down and len(set(d_up)) >= 10 and all(0.1 <= d <= 5.0 for d in d_up)
    shim = json.loads((out / "shim_stats.json").read_text())
    assert shim["down"]["process"]["spawn_key"] == [1] == shim["up"]["process"]["spawn_key"]  # one stream
    # every column identical, bit for bit: fast-time sends its setpoints and shows the pilot its ownship as
    # the link does (daa_sil.link.setpoint), including the return to the plan altitude from ~150 s (its
    # vertical speed is computed from the altitude the pilot observes)
    diffs = column_differences(sil, fast)
    assert diffs == {}, diffs
