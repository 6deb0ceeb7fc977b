"""Allocation agent: hand-built encounters and invariants (brute-force oracle for safety)."""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from daa_sil.agent.memory import AgentMemory, PilotInput
from daa_sil.agent.decision import (DECISION_FIELDS, D_BLEND, D_NO_WAIT, D_NONE, D_PILOT, D_STALE, D_WAIT, D_LINK_LOST,
    D_DAA_OVERRIDE, decode)
from daa_sil.agent.wait_function import WaitValue
from daa_sil.agent.step import agent_step
from daa_sil.config.groups import policy_for_group
from daa_sil.daa import (AXIS_NONE, AXIS_HORIZONTAL, AXIS_VERTICAL, DIR_DOWN, DIR_LEFT, DIR_UP, RULE_AXIS, RULE_AXIS_DIR,
                         RULE_ANY, DaaConfig, alert_levels, compute_bands)
from daa_sil.geometry.kinematics import Command
from daa_sil.geometry.units import DEG

from daa_helpers import brute_first_lowc, intruders, own_state

CFG = DaaConfig()
H = CFG.sm_horizon_s
ID2 = policy_for_group("ID-2")


def const_lookup(w):
    return lambda own, intr, turn: WaitValue.constant(own.shape[0], w)


def pilot_cmd(n, cmd: Command, t_sent=9.0, t_recv=10.0, received=True):
    return PilotInput(np.full(n, received), cmd, np.full(n, t_sent), np.full(n, t_recv), np.full(n, t_recv))


def oracle_safe(own, intr, cmd, margin=1.05):
    """Brute-force: no LoWC within H with a 5 % larger volume (so 'safe' holds with some margin)."""
    th = CFG.th
    big = th.with_(dthr=th.dthr * margin, zthr=th.zthr * margin)
    return brute_first_lowc(own, intr, cmd, CFG.performance(), big, H) > H


def oracle_unsafe(own, intr, cmd):
    th = CFG.th
    small = th.with_(dthr=th.dthr * 0.95, zthr=th.zthr * 0.95)
    return brute_first_lowc(own, intr, cmd, CFG.performance(), small, H) <= H


def test_head_on_clear_left_turn_is_executed():
    # ownship 30 m/s north, intruder 20 m/s south 3 km ahead, co-altitude: warning (LoWC in ~12 s)
    own = own_state(gs=30.0)
    intr = intruders([[[0.0, 3000.0, 1000.0, 20.0, np.pi, 0.0]]])
    left = Command(np.array([300 * DEG]), np.array([0.0]), np.array([30.0]))
    assert alert_levels(own, intr, CFG)[0, 0] >= 2
    assert oracle_safe(own, intr, left)[0]
    cmd, dec, mem = agent_step(10.0, own, intr, pilot_cmd(1, left), AgentMemory.initial(1, own), ID2, CFG,
                               const_lookup(0.0))
    assert dec["active"][0] and dec["decision"][0] == D_PILOT
    assert cmd.trk[0] == pytest.approx(300 * DEG) and dec["sm_pilot"][0] > 0
    assert dec["pilot_axis"][0] == AXIS_HORIZONTAL and dec["pilot_dir"][0] == DIR_LEFT
    assert mem.pilot_trk[0] == pytest.approx(300 * DEG)


def test_unsafe_climb_into_descending_intruder_is_blended():
    # intruder 300 m above, 3 km ahead head-on, descending 5 m/s; pilot climbs 10 m/s into it
    own = own_state(gs=40.0)
    intr = intruders([[[0.0, 3000.0, 1300.0, 40.0, np.pi, -5.0]]])
    climb = Command(np.array([0.0]), np.array([10.0]), np.array([40.0]))
    assert oracle_unsafe(own, intr, climb)[0]
    max_climb = Command(np.array([0.0]), np.array([CFG.max_vs]), np.array([40.0]))
    cmd, dec, _ = agent_step(10.0, own, intr, pilot_cmd(1, climb), AgentMemory.initial(1, own), ID2, CFG,
                             const_lookup(10.0))
    d = decode(dec)
    assert d["decision"][0] == "blend" and dec["sm_pilot"][0] <= 0
    assert dec["rule"][0] in (RULE_AXIS_DIR, RULE_AXIS, RULE_ANY)
    assert oracle_safe(own, intr, cmd, margin=1.0)[0] and dec["sm_exec"][0] > 0
    if oracle_unsafe(own, intr, max_climb)[0]:  # no climb is safe -> cannot be matched exactly
        assert dec["rule"][0] != RULE_AXIS_DIR
    if dec["rule"][0] == RULE_AXIS:  # same axis, other direction: descend
        assert dec["exec_axis"][0] == AXIS_VERTICAL and dec["exec_dir"][0] == DIR_DOWN
    assert dec["exact_match"][0] == (dec["rule"][0] == RULE_AXIS_DIR)


def test_baseline_overrides_unsafe_pilot_with_daa():
    own = own_state(gs=40.0)
    intr = intruders([[[0.0, 3000.0, 1300.0, 40.0, np.pi, -5.0]]])
    climb = Command(np.array([0.0]), np.array([10.0]), np.array([40.0]))
    cmd, dec, _ = agent_step(10.0, own, intr, pilot_cmd(1, climb), AgentMemory.initial(1, own),
                             policy_for_group("B-1"), CFG, None)
    assert dec["decision"][0] == D_DAA_OVERRIDE and dec["rule"][0] == 0
    assert cmd.trk[0] == dec["daa_trk"][0] and cmd.vs[0] == dec["daa_vs"][0]


def _no_cmd_case():
    # 300 m above, descending 5 m/s: corrective alert, LoWC in ~33 s (> the 25 s ProjL horizon)
    own = own_state(gs=55.0)
    intr = intruders([[[0.0, 3000.0, 1300.0, 55.0, np.pi, -5.0]]])
    return own, intr


def test_wait_map_zero_hands_control_to_daa_immediately():
    own, intr = _no_cmd_case()
    cmd, dec, _ = agent_step(10.0, own, intr, PilotInput.nothing(1, 9.0), AgentMemory.initial(1, own), ID2, CFG,
                             const_lookup(0.0))
    assert dec["active"][0] and not dec["projl"][0]
    assert dec["decision"][0] == D_NO_WAIT and decode(dec)["authority"][0] == "daa"
    assert (cmd.trk[0], cmd.vs[0], cmd.gs[0]) == (dec["daa_trk"][0], dec["daa_vs"][0], dec["daa_gs"][0])
    assert dec["sm_exec"][0] > 0 and oracle_safe(own, intr, cmd, margin=1.0)[0]


def test_long_wait_holds_pilot_course_without_projl():
    own, intr = _no_cmd_case()
    mem = AgentMemory.initial(1, own)
    mem.pilot_trk[:] = 10 * DEG  # the last pilot command differs from the current course
    cmd, dec, mem2 = agent_step(10.0, own, intr, PilotInput.nothing(1, 9.0), mem, ID2, CFG, const_lookup(30.0))
    assert dec["decision"][0] == D_WAIT and decode(dec)["authority"][0] == "waiting"
    assert cmd.trk[0] == pytest.approx(10 * DEG) and dec["wait_s"][0] == 30.0


def test_projl_forbids_waiting_whatever_the_map_says():
    own = own_state(gs=55.0)
    intr = intruders([[[0.0, 5000.0, 1000.0, 55.0, np.pi, 0.0]]])  # LoWC in ~7 s
    cmd, dec, _ = agent_step(10.0, own, intr, PilotInput.nothing(1, 9.0), AgentMemory.initial(1, own), ID2, CFG,
                             const_lookup(1000.0))
    assert dec["projl"][0] and dec["decision"][0] == D_NO_WAIT


def test_multi_intruder_one_forbids_the_pilot_direction():
    own = own_state(gs=30.0)
    a = [0.0, 3000.0, 1000.0, 20.0, np.pi, 0.0]  # head-on, as in the clear-left-turn case
    b = [-5000.0, 1000.0, 1000.0, 50.0, 90 * DEG, 0.0]  # from the left, crossing eastbound; harmless if held
    left = Command(np.array([300 * DEG]), np.array([0.0]), np.array([30.0]))
    alone = intruders([[a]])
    both = intruders([[a, b]])
    assert oracle_safe(own, alone, left)[0] and oracle_unsafe(own, both, left)[0]
    assert oracle_safe(own, intruders([[b]]), Command.hold(own))[0]
    _, d1, _ = agent_step(10.0, own, alone, pilot_cmd(1, left), AgentMemory.initial(1, own), ID2, CFG, None)
    cmd, d2, _ = agent_step(10.0, own, both, pilot_cmd(1, left), AgentMemory.initial(1, own), ID2, CFG, None)
    assert d1["decision"][0] == D_PILOT and d2["decision"][0] == D_BLEND
    assert d2["sm_exec"][0] > 0 and oracle_safe(own, both, cmd, margin=1.0)[0]
    assert d2["rule"][0] in (RULE_AXIS_DIR, RULE_AXIS) and d2["exec_axis"][0] == AXIS_HORIZONTAL


def test_link_lost_and_inactive():
    own, intr = _no_cmd_case()
    cmd, dec, _ = agent_step(40.0, own, intr, PilotInput.nothing(1, 10.0), AgentMemory.initial(1, own), ID2, CFG,
                             const_lookup(30.0))
    assert dec["decision"][0] == D_LINK_LOST and cmd.trk[0] == dec["daa_trk"][0]
    far = intruders([[[0.0, 60000.0, 1000.0, 55.0, np.pi, 0.0]]])
    turn = Command(np.array([20 * DEG]), np.array([0.0]), np.array([55.0]))
    cmd, dec, _ = agent_step(10.0, own, far, pilot_cmd(1, turn), AgentMemory.initial(1, own), ID2, CFG, None)
    assert not dec["active"][0] and dec["decision"][0] == D_NONE and cmd.trk[0] == pytest.approx(20 * DEG)
    assert set(DECISION_FIELDS) <= set(dec)


def _frozen_decisions(pol, steps=8):
    own, intr = _no_cmd_case()
    mem = AgentMemory.initial(1, own)
    seen = []
    for k in range(steps):  # the ownship is frozen: only the clock runs
        _, dec, mem = agent_step(10.0 + k, own, intr, PilotInput.nothing(1, 10.0 + k), mem, pol, CFG, None)
        seen.append(int(dec["decision"][0]))
    return seen


def test_ic1_constant_wait_literal_eq11():
    # Eq. 11 with w(S) = 5 s >= W_T = 4 s everywhere: wait every step while no ProjL
    assert _frozen_decisions(policy_for_group("IC-1")) == [D_WAIT] * 8


def test_constant_wait_as_budget_variant():
    # 5 s budget and W_T = 4 s: waits while 5 - elapsed >= 4, then hands over to the DAA
    from dataclasses import replace
    seen = _frozen_decisions(replace(policy_for_group("IC-1"), wait_rule="countdown"))
    assert seen[:2] == [D_WAIT, D_WAIT] and set(seen[2:]) == {D_NO_WAIT}


def _random_batch(rng, n):
    own = own_state(n, gs=rng.uniform(30, 80, n), trk=rng.uniform(0, 2 * np.pi, n), vs=rng.uniform(-3, 3, n))
    rngm = rng.uniform(2000, 7000, n)
    brg = own.trk + rng.uniform(-0.8, 0.8, n)
    rows = np.stack([rngm * np.sin(brg), rngm * np.cos(brg), 1000 + rng.uniform(-200, 200, n),
                     rng.uniform(30, 200, n), brg + np.pi + rng.normal(0, 0.3, n), rng.uniform(-6, 6, n)], -1)
    intr = intruders(rows[:, None, :])
    cmd = Command((own.trk + rng.uniform(-1.5, 1.5, n)) % (2 * np.pi), rng.choice([0.0, -8.0, 8.0], n),
                  own.gs + rng.choice([0.0, 10.0], n))
    t_sent = 10.0 - rng.uniform(0, 25, n)
    pilot = PilotInput(rng.random(n) < 0.6, cmd, t_sent, np.full(n, 10.0), np.full(n, 10.0))
    return own, intr, pilot


@settings(max_examples=6, deadline=None)
@given(st.integers(0, 2**31 - 1))
def test_invariants_safe_execution_and_no_stale(seed):
    rng = np.random.default_rng(seed)
    n = 60
    own, intr, pilot = _random_batch(rng, n)
    mem = AgentMemory.initial(n, own)
    cmd, dec, mem2 = agent_step(10.0, own, intr, pilot, mem, ID2, CFG, const_lookup(rng.uniform(0, 8)))
    bands = compute_bands(own, intr, CFG)
    any_safe = np.zeros(n, bool)
    for ab in bands.axes():
        any_safe |= (ab.t_in > H).any(axis=1)
    daa_exec = np.isin(dec["decision"], (D_BLEND, D_NO_WAIT, D_DAA_OVERRIDE, D_LINK_LOST))
    assert np.all(dec["sm_exec"][daa_exec & any_safe] > 0)
    assert np.all(dec["sm_exec"][dec["decision"] == D_PILOT] > 0)
    # a stale command is never executed nor remembered
    age = 10.0 - pilot.t_sent
    stale = pilot.received & (age > ID2.stale_command_s)
    assert np.all(dec["decision"][stale & dec["active"]] == D_STALE)
    differs = stale & (np.abs(np.angle(np.exp(1j * (pilot.cmd.trk - mem.pilot_trk)))) > 1e-3)
    assert not np.any(np.isclose(cmd.trk, pilot.cmd.trk)[differs & ~np.isclose(cmd.trk, dec["daa_trk"])])
    np.testing.assert_array_equal(mem2.pilot_trk[stale], mem.pilot_trk[stale])


def test_batch_of_1000_equals_one_at_a_time():
    rng = np.random.default_rng(11)
    n = 1000
    own, intr, pilot = _random_batch(rng, n)
    def lookup(o, i, turn):  # state-dependent, element-wise
        v = WaitValue.constant(o.shape[0], 0.0)
        v.wait_s = 2.0 + (np.abs(o.trk) * 10 % 6)
        return v
    cmd, dec, mem = agent_step(10.0, own, intr, pilot, AgentMemory.initial(n, own), ID2, CFG, lookup)
    for i in rng.choice(n, 8, replace=False):
        s = slice(i, i + 1)
        p1 = PilotInput(pilot.received[s], pilot.cmd[s], pilot.t_sent[s], pilot.t_recv[s], pilot.link_alive_t[s])
        c1, d1, m1 = agent_step(10.0, own[s], intr[s], p1, AgentMemory.initial(1, own[s]), ID2, CFG, lookup)
        for f in ("trk", "vs", "gs"):
            np.testing.assert_array_equal(getattr(cmd, f)[s], getattr(c1, f))
        for key in DECISION_FIELDS:
            if key.startswith("bands_"):
                continue
            np.testing.assert_array_equal(np.asarray(dec[key])[s], np.asarray(d1[key]), err_msg=key)


def test_pilot_intent_is_relative_to_the_previous_pilot_course_not_the_current_state():
    # the pilot's course was north (track 0); a blend has since turned the ownship to 320 deg
    own = own_state(gs=30.0, trk=320 * DEG)
    intr = intruders([[[0.0, 3000.0, 1000.0, 20.0, np.pi, 0.0]]])
    mem = AgentMemory.initial(1, own_state(gs=30.0))  # pilot course: track 0, vs 0, gs 30
    # a new command to 330 deg is a LEFT turn from the pilot's course, although it is a right turn
    # from where the ownship now points
    left = Command(np.array([330 * DEG]), np.array([0.0]), np.array([30.0]))
    _, dec, mem2 = agent_step(10.0, own, intr, pilot_cmd(1, left), mem, ID2, CFG, const_lookup(0.0))
    assert dec["pilot_axis"][0] == AXIS_HORIZONTAL and dec["pilot_dir"][0] == DIR_LEFT
    # the same command repeated next step keeps the preference (it is not a new maneuver)
    _, dec, _ = agent_step(11.0, own, intr, pilot_cmd(1, left, 10.0, 11.0), mem2, ID2, CFG, const_lookup(0.0))
    assert dec["pilot_axis"][0] == AXIS_HORIZONTAL and dec["pilot_dir"][0] == DIR_LEFT
    # a "hold" of the pilot's own course carries no maneuver preference, whatever the current track
    hold = Command(np.array([0.0]), np.array([0.0]), np.array([30.0]))
    _, dec, _ = agent_step(10.0, own, intr, pilot_cmd(1, hold), mem, ID2, CFG, const_lookup(0.0))
    assert dec["pilot_axis"][0] == AXIS_NONE


def test_stateful_preset_takes_the_whole_batchs_bands_on_its_active_rows():
    """With a stateful preset (DAIDALUS hysteresis), bands passed for the whole batch while only some rows are
    active (the agent then reads a rows view of them) give the decisions of bands computed by the agent
    itself; the hysteresis once failed on the rows view (``dataclasses.replace`` of it)."""
    from daa_sil.agent.memory import PilotInput
    from daa_sil.agent.wait_function import WaitValue
    from daa_sil.config.groups import policy_for_group
    from daa_sil.daa import DaaConfig, compute_bands
    from daa_sil.geometry.kinematics import AircraftState

    cfg = DaaConfig.for_preset("daidalus")
    assert cfg.stateful
    rng = np.random.default_rng(5)
    n = 40
    own = AircraftState(np.zeros(n), np.zeros(n), np.full(n, 1000.0), np.full(n, 55.0), np.zeros(n), np.zeros(n))
    rng_m = np.where(np.arange(n) % 2 == 0, rng.uniform(3000, 6000, n), 40000.0)  # odd rows far away: inactive
    b = rng.uniform(-0.5, 0.5, n)
    intr = AircraftState((rng_m * np.sin(b))[:, None], (rng_m * np.cos(b))[:, None], np.full((n, 1), 1000.0),
                         np.full((n, 1), 80.0), (np.pi + b)[:, None], np.zeros((n, 1)))
    pilot = PilotInput(rng.random(n) < 0.5, Command(rng.uniform(-0.5, 0.5, n) % (2 * np.pi), np.zeros(n), np.full(n, 55.0)),
                       np.full(n, 5.0), np.full(n, 10.0), np.full(n, 10.0))
    lookup = lambda o, i, rate: WaitValue.constant(o.shape[0], 6.0)  # noqa: E731
    runs = []
    for bands in (compute_bands(own, intr, cfg), None):
        cmd, dec, _ = agent_step(10.0, own, intr, pilot, AgentMemory.initial(n, own), policy_for_group("ID-2"), cfg,
                                 lookup, bands=bands)
        runs.append((cmd, dec))
    (c1, d1), (c2, d2) = runs
    assert 0 < d1["active"].sum() < n
    for a, b_ in ((c1.trk, c2.trk), (c1.vs, c2.vs), (c1.gs, c2.gs), (d1["decision"], d2["decision"])):
        np.testing.assert_array_equal(a, b_)
