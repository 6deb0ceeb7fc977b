"""Parity with random delays: a lockstep SIL run through the real link equals fast-time, bit for bit.

The shim draws its per-direction delays from the encounter's fast-time streams
(``encounter_streams(seed)[STREAM_UP / STREAM_DOWN]``), so with the paper's Gaussian delay
(groups B-2/ID-2: N(5 s, 3 s) truncated to [0.2, 10] s, a new draw every 10 s epoch) the SIL
vehicle receives every pilot command, and the GCS every telemetry frame, at the step fast-time
says it does. What the vehicle logs must then equal ``daa_sil.study.simulation.fasttime.simulate``'s step log,
every column bit for bit (the sign of a zero included), with the encounter alone and inside a batch of
other encounters.

The pilot's command crosses the link as ``PILOT_MANEUVER`` with float32 setpoints (track in degrees,
vs, gs); fast-time sends its commands through the same rounding (``daa_sil.link.setpoint``), so both
fly the same setpoints. (The GCS also observes float32 LOCAL_POSITION_NED and integer ADSB_VEHICLE
fields; the pilot's guidance and decisions come out the same from both views here.)
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from daa_sil.sil.scenario import delay_models, encounter_set, load_scenario
from daa_sil.steplog import read_steplog

ROOT = Path(__file__).resolve().parents[1]

SCENARIO = """\
name: head-on-gauss-{group}
description: head-on, paper B-2/ID-2 Gaussian link delay (mean 5 s, sd 3 s) each way, group {group}
seed: {seed}
duration_s: 180
thresholds: do365
ownship: {{alt_m: 1000, gs_mps: 55, track_deg: 0}}
intruders:
  - callsign: HEAD1
    cpa: {{angle_deg: 180, hmd_m: 150, t_cpa_s: 120, gs_mps: 60}}
{maneuvers}link: {{up: "gauss:5,3", down: "gauss:5,3", epoch_s: 10}}
pilot: {{mode: model, model: {{response: deterministic}}}}
allocation: {{group: {group}}}
"""


def _fast_time(sc, seed: int, others: "list | None" = None):
    """Fast-time of scenario ``sc`` with encounter seed ``seed``, as the SIL flies it (the study's default
    reading); with ``others`` (scenarios), inside a batch of them too (encounter ids 1, 2, ...; seeds
    ``seed + 1``, ...): then the step log's rows of encounter 0."""
    from daa_sil.models.encounters import concat_encounters
    from daa_sil.study.simulation.fasttime import simulate
    from sil_helpers import sil_fast_time

    up, down = delay_models(sc)
    pol, lookup, pilot, daa = sil_fast_time(sc)  # the SIL flies the study's default reading
    scs = [sc] + list(others or [])
    encs = concat_encounters([encounter_set(s, encounter_id=i) for i, s in enumerate(scs)])
    enc, dec, log = simulate(encs, pol, up, down, pilot, daa, wait_lookup=lookup, seeds=seed + np.arange(len(scs)),
                             preset=sc.thresholds, duration_s=sc.duration_s, epoch_s=sc.link.epoch_s,
                             record_steps=True)
    if others:
        import pyarrow.compute as pc

        log = log.filter(pc.equal(log.column("encounter_id"), 0))
        enc = enc.filter(pc.equal(enc.column("encounter_id"), 0))
    return enc, dec, log


def _same(x, y) -> bool:
    """Equal bit for bit (nan equal to nan, the sign of a zero counts), lists element by element."""
    if isinstance(x, list) or isinstance(y, list):
        return isinstance(x, list) and isinstance(y, list) and len(x) == len(y) and \
            all(_same(u, v) for u, v in zip(x, y))
    if isinstance(x, float) and isinstance(y, float):
        if math.isnan(x) or math.isnan(y):
            return math.isnan(x) and math.isnan(y)
        return x == y and math.copysign(1.0, x) == math.copysign(1.0, y)
    return x == y


def column_differences(sil, fast) -> dict:
    """``{column: (n_rows_differing, first (t, sil, fast))}`` over every step-log column."""
    assert sil.schema.names == fast.schema.names and sil.num_rows == fast.num_rows
    t = sil.column("t").to_pylist()
    out = {}
    for name in sil.schema.names:
        a, b = sil.column(name).to_pylist(), fast.column(name).to_pylist()
        bad = [i for i, (x, y) in enumerate(zip(a, b)) if not _same(x, y)]
        if bad:
            out[name] = (len(bad), (t[bad[0]], a[bad[0]], b[bad[0]]))
    return out


#: the intruder turns right at 4 deg/s for 25 s from t = 70 s (it then reads the turning wait maps)
TURN = "    maneuvers: [{start_s: 70, end_s: 95, turn_rate_dps: 4}]\n"


@pytest.mark.parametrize("group,seed,maneuvers", [("ID-2", 11, ""), ("ID-2", 11, TURN),
                                                  pytest.param("B-2", 4, "", marks=pytest.mark.slow)])
def test_lockstep_sil_with_gaussian_delays_equals_fast_time(group, seed, maneuvers, tmp_path):
    path = tmp_path / "gauss.yaml"
    path.write_text(SCENARIO.format(group=group, seed=seed, maneuvers=maneuvers))
    sc = load_scenario(path)
    out = tmp_path / "run"
    cp = subprocess.run([sys.executable, "-m", "daa_sil.cli", "run", str(path), "--out", str(out), "--json"],
                        capture_output=True, text=True, timeout=180, cwd=ROOT)
    assert cp.returncode == 0, cp.stdout[-2000:] + cp.stderr[-2000:]
    res = json.loads(cp.stdout)
    sil = read_steplog(out / "steplog.parquet")
    enc, _, fast = _fast_time(sc, sc.seed)

    # the delays really are random and really reach the run: several epochs, several values
    d_up, d_down = fast.column("delay_up_s").to_pylist(), fast.column("delay_down_s").to_pylist()
    assert len(set(d_up)) >= 10 and len(set(d_down)) >= 10 and d_up != d_down
    assert all(0.2 <= d <= 10.0 for d in d_up + d_down)
    # the shim applied exactly these delays (its stats: sampled mean over the delivered datagrams)
    shim = json.loads((out / "shim_stats.json").read_text())
    assert shim["down"]["process"]["spawn_key"] == [2] and shim["up"]["process"]["spawn_key"] == [1]

    diffs = column_differences(sil, fast)
    assert diffs == {}, diffs
    # the same encounter inside a batch of others (another geometry each) gives the same rows
    others = []
    for k, (angle, hmd) in enumerate(((150, 400), (200, 50), (175, 900))):
        p = tmp_path / f"other{k}.yaml"
        p.write_text(SCENARIO.format(group=group, seed=seed, maneuvers=maneuvers)
                     .replace("angle_deg: 180, hmd_m: 150", f"angle_deg: {angle}, hmd_m: {hmd}"))
        others.append(load_scenario(p))
    _, _, in_batch = _fast_time(sc, sc.seed, others)
    assert column_differences(sil, in_batch) == {}
    if maneuvers:  # the turn is estimated the same way in both and picks the +2.5 / +5 deg/s maps
        maps = {m for m in fast.column("wait_map_turn_dps").to_pylist() if m == m}
        assert maps & {2.5, 5.0} and 0.0 in maps, maps
        est = [r[0] for r in sil.column("intr_turn_est_dps").to_pylist()]
        assert max(est) == pytest.approx(4.0, abs=1e-6)
    # the outcome fast-time reports for the encounter is the SIL's
    assert res["lowc"] == bool(enc.column("lowc")[0].as_py())
    assert res["nmac"] == bool(enc.column("nmac")[0].as_py())
    assert res["min_range_m"] == pytest.approx(min(min(r) for r in fast.column("range_m").to_pylist()), abs=1e-4)
    assert enc.column("min_range_m")[0].as_py() <= res["min_range_m"]  # between-sample minimum <= sampled
    assert res["n_active_steps"] == enc.column("n_active_steps")[0].as_py() > 0

    # the comparison can fail: another seed gives other delays and another step log
    _, _, other = _fast_time(sc, sc.seed + 1)
    assert "delay_up_s" in column_differences(sil, other)


def test_wire_command_is_the_pilot_maneuver_round_trip():
    """``link.setpoint.wire_command`` (what fast-time sends) gives, bit for bit, the setpoints a vehicle reads
    from the PILOT_MANEUVER the GCS builds for a command: the GCS's track in degrees mod 360, the message's
    float32 fields encoded and decoded, the vehicle's ``setpoint_command`` and its track back in radians."""
    from daa_sil.geometry.kinematics import Command
    from daa_sil.link.codec import MavCodec, mavlink as M
    from daa_sil.link.setpoint import wire_command
    from vehicle.commands import setpoint_command

    rng = np.random.default_rng(3)
    n = 3000
    trk = np.concatenate([rng.uniform(-7, 14, n - 8), [0.0, -0.0, np.pi, 2 * np.pi, -1e-12, np.nan, 6.283185307179586,
                                                       1e-300]])
    vs = np.concatenate([rng.normal(0, 8, n - 4), [0.0, -0.0, np.nan, 1e-45]])
    gs = np.concatenate([rng.uniform(20, 120, n - 3), [np.nan, 55.0, 1e-9]])
    got = wire_command(Command(trk, vs, gs))
    tx, rx = MavCodec(255, 190), MavCodec(1, 1)
    for i in range(n):
        t = float(trk[i])
        track_deg = math.degrees(t) % 360.0 if math.isfinite(t) else math.nan  # (gcs/node.py)
        msg = M.MAVLink_pilot_maneuver_message(1000, i + 1, 1, 1, track_deg, float(vs[i]), float(gs[i]))
        cmd = setpoint_command(rx.decode(tx.encode(msg))[0])
        want_trk = math.radians(cmd.track_deg) if math.isfinite(cmd.track_deg) else math.nan  # (vehicle/core.py)
        for g, w in ((got.trk[i], want_trk), (got.vs[i], cmd.vs_mps), (got.gs[i], cmd.gs_mps)):
            assert _same(float(g), float(w)), (i, trk[i], vs[i], gs[i], g, w)
    assert np.any(got.vs != vs) and np.any(got.trk[np.isfinite(trk)] != np.mod(trk[np.isfinite(trk)], 2 * np.pi))


@pytest.mark.parametrize("name", ["head_on", "climbing"])
def test_lockstep_sil_of_a_scenario_file_equals_fast_time(name, tmp_path):
    """A scenario of ``scenarios/`` whose pilot returns to its plan altitude after the conflict (its
    vertical speed is computed from the altitude it observes): bit for bit, every column."""
    path = ROOT / "scenarios" / f"{name}.yaml"
    sc = load_scenario(path)
    out = tmp_path / "run"
    cp = subprocess.run([sys.executable, "-m", "daa_sil.cli", "run", str(path), "--out", str(out), "--json"],
                        capture_output=True, text=True, timeout=180, cwd=ROOT)
    assert cp.returncode == 0, cp.stdout[-2000:] + cp.stderr[-2000:]
    sil = read_steplog(out / "steplog.parquet")
    _, _, fast = _fast_time(sc, sc.seed)
    assert column_differences(sil, fast) == {}
    pilot_vs = [v for v in fast.column("pilot_vs").to_pylist() if v == v and v != 0.0]
    assert pilot_vs  # (the pilot did command a vertical speed)
