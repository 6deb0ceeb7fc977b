"""Parity with random delays: a lockstep SIL run through the real link equals fast-time, column by column.

The shim draws its per-direction delays from the encounter's fast-time streams
(``encounter_streams(seed)[STREAM_UP / STREAM_DOWN]``), so with the paper's Gaussian delay
(groups B-2/ID-2: N(5 s, 3 s) truncated to [0.2, 10] s, a new draw every 10 s epoch) the SIL
vehicle receives every pilot command, and the GCS every telemetry frame, at the step fast-time
says it does. What the vehicle logs must then equal ``daa_sil.study.fasttime.simulate``'s step log.

Tolerance (only on continuous columns; every discrete column must be identical): the pilot's
command crosses the link as ``PILOT_MANEUVER`` with **float32** setpoints (track deg, vs, gs), so
the SIL flies ``float32(cmd)``: a relative rounding of at most 2^-24 ~ 6e-8 (e.g. vs -2.4516625 m/s
arrives as -2.45166254 m/s, 4e-8 m/s off). Integrated over at most 240 s that moves positions by
< 2e-5 m. The check therefore allows ``|sil - fast| <= 1e-5 + 1e-6 |fast|`` on float columns.
The wait map is interpolated at the continuous relative state, so ``wait_s`` and ``wait_p_lowc``
inherit that rounding too (about 1e-8 s); the wait / no-wait decision they feed, ``decided_by`` and
the map read are discrete and must be identical.
(The GCS also observes float32 LOCAL_POSITION_NED and integer ADSB_VEHICLE fields, but the pilot's
guidance and decisions are discrete, so that quantisation does not show up in the log.)
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
ATOL, RTOL = 1e-5, 1e-6
#: columns whose values are discrete (strings, bools, ints, step/time): must match exactly
EXACT = {"encounter_id", "step", "t", "alert_level", "wcv", "decision", "rule", "authority", "projl",
         "pilot_cmd_received", "pilot_axis", "pilot_dir", "exec_axis", "exec_dir", "lowc", "nmac",
         "bands_trk_region", "delay_up_s", "delay_down_s", "pilot_cmd_age_s", "decided_by", "wait_in_box",
         "wait_map_turn_dps"}

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


def _fast_time(sc, seed: int):
    from daa_sil.study.fasttime import simulate
    from sil_helpers import sil_fast_time

    up, down = delay_models(sc)
    pol, lookup, pilot, daa = sil_fast_time(sc)  # the SIL flies the study's default reading
    return simulate(encounter_set(sc), pol, up, down, pilot, daa, wait_lookup=lookup, seeds=np.array([seed]),
                    preset=sc.thresholds, duration_s=sc.duration_s, epoch_s=sc.link.epoch_s, record_steps=True)


def _same(x, y, exact: bool) -> bool:
    if isinstance(x, list) or isinstance(y, list):
        return isinstance(x, list) and isinstance(y, list) and len(x) == len(y) and \
            all(_same(u, v, exact) for u, v in zip(x, y))
    if isinstance(x, float) and isinstance(y, float):
        if math.isnan(x) or math.isnan(y):
            return math.isnan(x) and math.isnan(y)
        return x == y if exact else abs(x - y) <= ATOL + RTOL * abs(y)
    return x == y


def column_differences(sil, fast) -> dict:
    """``{column: (n_rows_differing, first (t, sil, fast))}`` over every step-log column."""
    assert sil.schema.names == fast.schema.names and sil.num_rows == fast.num_rows
    t = sil.column("t").to_pylist()
    out = {}
    for name in sil.schema.names:
        a, b = sil.column(name).to_pylist(), fast.column(name).to_pylist()
        bad = [i for i, (x, y) in enumerate(zip(a, b)) if not _same(x, y, name in EXACT)]
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
