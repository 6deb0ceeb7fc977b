"""OnboardCore: a hand-built head-on encounter, between-sample NMAC detection, step bookkeeping."""

import numpy as np
import pytest

from daa_sil.geometry import wellclear as wc
from daa_sil.agent.decision import D_NO_WAIT
from daa_sil.agent.memory import PilotInput
from daa_sil.agent.wait_function import WaitValue
from daa_sil.config.groups import policy_for_group
from daa_sil.daa import DaaConfig
from daa_sil.models.encounter_geometry import IntruderGeometry, encounter_from_geometry
from daa_sil.geometry.kinematics import AircraftState
from daa_sil.onboard import OnboardCore, band_intervals
from daa_sil.geometry.thresholds import PAPER


def _run(core: OnboardCore, steps: int):
    outs = []
    for k in range(steps):
        outs.append(core.step(float(k), PilotInput.nothing(core.n, link_alive_t=float(k))))
    return outs


def test_head_on_baseline_without_pilot_is_resolved_by_daa():
    # Co-altitude head-on, HMD 0 at t = 120 s, intruder 100 m/s: flown straight this is a collision
    # (range 0 at CPA). Baseline policy, no pilot command ever and no latency: with no command the
    # agent must hand control to the DAA (no_wait), which turns away, so no NMAC.
    es = encounter_from_geometry(IntruderGeometry(angle_deg=180, hmd_m=0.0, t_cpa_s=120, gs_mps=100.0))
    core = OnboardCore.from_encounters(es, policy_for_group("B-1"), DaaConfig(thresholds="paper"))
    outs = _run(core, 240)
    dec = np.array([o.decisions["decision"][0] for o in outs])
    active = np.array([o.decisions["active"][0] for o in outs])
    assert active.any()
    assert set(dec[active]) == {D_NO_WAIT}  # baseline, no pilot: every active step allocates to DAA
    assert not any(o.nmac[0] for o in outs)
    min_range = min(o.seg_min_range_m[0] for o in outs)
    assert min_range > PAPER.nmac_h
    # the executed track left the pilot course (north) while active
    trk = np.degrees(np.array([o.command.trk[0] for o in outs]))
    assert np.abs((trk[active] + 180) % 360 - 180).max() >= 5.0
    # without any maneuver the same geometry closes to (near) zero range
    s0 = es.own.position()[:, None] - es.intr.position()
    v = es.own.velocity()[:, None] - es.intr.velocity()
    assert wc.hmd(s0, v)[0, 0] < 1.0


def test_nmac_strictly_between_samples_is_detected():
    # Intruder 227.5 m dead ahead closing at 55 + 400 = 455 m/s: both samples (t = 0 and 1 s) are at
    # 227.5 m > 152.4 m (500 ft) but the aircraft pass through each other in between.
    own = AircraftState([0.0], [0.0], [1000.0], [55.0], [0.0], [0.0])
    intr = AircraftState([[0.0]], [[227.5]], [[1000.0]], [[400.0]], [[np.pi]], [[0.0]])
    zero = np.zeros((1, 1))
    core = OnboardCore(own, intr, lambda t: (zero, zero, zero), policy_for_group("B-1"),
                       DaaConfig(thresholds="paper"))
    out = core.step(0.0, PilotInput.nothing(1, 0.0))
    s0 = out.own.position()[:, None] - out.intruders.position()
    s1 = core.own.position()[:, None] - core.intruders.position()
    assert not wc.nmac(s0, PAPER).any() and not wc.nmac(s1, PAPER).any()  # sampled check misses it
    assert out.nmac[0] and out.lowc[0]
    assert out.seg_min_range_m[0] < 5.0
    assert out.lowc_time_s[0] == pytest.approx(1.0)  # inside DMOD for the whole step


def test_without_outcomes_every_other_output_is_the_same():
    """``outcomes=False`` (the SIL vehicle) leaves the fast-time outcome figures None and every other
    output of every step bit for bit as with them (a head-on found too late to avoid an NMAC, so the
    LoWC interval, the PI and the minimum range are non-trivial on some steps)."""
    es = encounter_from_geometry(IntruderGeometry(angle_deg=180, hmd_m=0.0, t_cpa_s=10, gs_mps=100.0))
    runs = {flag: _run(OnboardCore.from_encounters(es, policy_for_group("B-1"), DaaConfig(thresholds="paper"),
                                                   outcomes=flag), 60) for flag in (True, False)}
    assert any(o.pi_s[0] > 0 for o in runs[True]) and any(o.nmac[0] for o in runs[True])
    for a, b in zip(runs[True], runs[False]):
        for name in ("lowc_time_s", "seg_min_range_m", "seg_vsep_m", "pi_s", "pi_paper_s"):
            assert getattr(b, name) is None
        for st_a, st_b in ((a.own, b.own), (a.intruders, b.intruders)):
            assert all(np.array_equal(getattr(st_a, f), getattr(st_b, f)) for f in ("x", "y", "z", "gs", "trk", "vs"))
        assert np.array_equal(a.lowc, b.lowc) and np.array_equal(a.nmac, b.nmac)
        assert all(np.array_equal(x, y, equal_nan=True) for x, y in
                   ((a.command.trk, b.command.trk), (a.command.vs, b.command.vs), (a.command.gs, b.command.gs)))
        assert {k: str(v) for k, v in a.geometry.items()} == {k: str(v) for k, v in b.geometry.items()}


def test_step_advances_time_and_rejects_wrong_time():
    es = encounter_from_geometry(IntruderGeometry(angle_deg=90, hmd_m=500.0, t_cpa_s=120, gs_mps=80.0))
    core = OnboardCore.from_encounters(es, policy_for_group("ID-1"), DaaConfig(thresholds="paper"),
                                       wait_lookup=lambda own, intr, turn: WaitValue.constant(own.shape[0], 10.0))
    out = core.step(0.0, PilotInput.nothing(1, 0.0))
    assert out.step == 0 and core.t == 1.0 and core.k == 1
    assert out.telemetry.t == 0.0 and out.telemetry.alert_level.shape == (1, 1)
    # the ownship flew 55 m north in the step (no alert this early)
    assert core.own.y[0] == pytest.approx(55.0)
    with pytest.raises(ValueError, match="t=1 s"):
        core.step(5.0, PilotInput.nothing(1, 0.0))


def test_band_intervals_merge_runs_of_equal_region():
    vals = np.array([[350.0, 355.0, 0.0, 5.0, 10.0], [0, 0, 0, 0, 0]])
    reg = np.array([[0, 2, 2, 0, 4], [-1, -1, -1, -1, -1]])
    b = band_intervals(vals, reg)
    assert b["bands_count"].tolist() == [4, 0]
    assert b["bands_trk_lo_deg"][0].tolist() == [350.0, 355.0, 5.0, 10.0]
    assert b["bands_trk_hi_deg"][0].tolist() == [350.0, 0.0, 5.0, 10.0]
    assert b["bands_trk_region"][0].tolist() == [0, 2, 0, 4]


def test_a_policy_replaced_mid_flight_is_the_one_the_next_step_flies():
    """The core reads its policy's settings once per policy, not per step (``policy_rows``); replacing
    the policy (as the SIL vehicle does on a mode or parameter change) must reach the very next step:
    with the agent disabled the DAA stops acting at once."""
    from dataclasses import replace

    es = encounter_from_geometry(IntruderGeometry(angle_deg=180, hmd_m=0.0, t_cpa_s=60, gs_mps=100.0))
    core = OnboardCore.from_encounters(es, policy_for_group("B-1"), DaaConfig(thresholds="paper"))
    outs = _run(core, 40)
    assert any(o.decisions["active"][0] for o in outs)  # alerting and deciding by now
    first = core.policy_rows()
    assert core.policy_rows() is first and first.value("enabled")[0]
    core.policy = replace(core.policy, enabled=False)
    assert core.policy_rows() is not first and not core.policy_rows().value("enabled")[0]
    out = core.step(40.0, PilotInput.nothing(core.n, link_alive_t=40.0))
    assert not out.decisions["active"][0]


@pytest.mark.parametrize("scenario", ["pilot_unsafe_blend", "head_on"])
def test_one_encounter_makes_no_daa_call_on_no_rows(scenario, monkeypatch):
    # at N = 1 (the SIL vehicle): a step with no active row, no fresh pilot command or
    # nothing to revert makes no bands or SM(u) call (each used to cost ~1.8 ms on an empty set)
    from pathlib import Path

    import daa_sil.agent.step as agent_mod
    from daa_sil.sil.scenario import load_scenario
    from vehicle.core import VehicleCore

    calls: list = []
    real_sm, real_bands = agent_mod.safety_metric, agent_mod.compute_bands

    def sm(own, intr, cmd, *a, **k):
        calls.append(("sm", own.shape[0]))
        return real_sm(own, intr, cmd, *a, **k)

    def bands(own, intr, *a, **k):
        calls.append(("bands", own.shape[0]))
        return real_bands(own, intr, *a, **k)

    sc = load_scenario(Path(__file__).resolve().parents[1] / "scenarios" / f"{scenario}.yaml")
    # a step with no active row records bands of the track axis's shape, from one empty call cached per
    # configuration and process: made here, by one whole flight before counting (it is not a per-step
    # cost; one step is not enough when the encounter reaches another configuration later)
    warm = VehicleCore(sc)
    for k in range(warm.n_steps):
        warm.step(float(k))
    monkeypatch.setattr(agent_mod, "safety_metric", sm)
    monkeypatch.setattr(agent_mod, "compute_bands", bands)
    vc = VehicleCore(sc)
    quiet = 0
    for k in range(vc.n_steps):
        calls.clear()
        out = vc.step(float(k))
        assert all(rows > 0 for _, rows in calls), f"t = {k} s: a DAA call on no rows: {calls}"
        if not out.decisions.active[0]:
            assert not any(kind == "bands" for kind, _ in calls), f"t = {k} s: bands of an inactive step"
            quiet += 1
    assert 0 < quiet < vc.n_steps  # the encounter has steps of both kinds
