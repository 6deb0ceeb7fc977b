"""DAIDALUS-style hysteresis, M-of-N and persistence (DaaState) on hand-worked time sequences.

Values are those of DO_365B_no_SUM.conf (the ``daidalus`` preset): hysteresis 5 s, persistence 4 s,
M-of-N 2 of 4, early alerting times 75 / 75 / 55 s, preferred-direction delta 15 deg.
"""

import numpy as np
import pytest

from daa_sil.agent.memory import AgentMemory, PilotInput
from daa_sil.agent.step import agent_step
from daa_sil.config.groups import policy_for_group
from daa_sil.daa import DaaConfig, DaaState, alert_levels
from daa_sil.daa.bands import AxisBands, Bands, compute_bands
from daa_sil.daa.config import AXIS_HORIZONTAL, REGION_MID, REGION_NEAR, REGION_NONE
from daa_sil.daa.hysteresis import mofn_output, push, seeded_queue
from daa_sil.geometry.units import DEG

from daa_helpers import intruders, own_state

CFG = DaaConfig.for_preset("daidalus")


def test_preset_values_are_the_configuration_files():
    assert (CFG.hysteresis_s, CFG.persistence_s, CFG.alert_m, CFG.alert_n) == (5.0, 4.0, 2, 4)
    assert CFG.stateful and not DaaConfig.for_preset("do365").stateful and not DaaConfig.for_preset("paper").stateful


def test_mofn_queue_by_hand():
    q = seeded_queue(np.array([3]), 2, 4)  # M copies of the first value, then empty slots; oldest first
    assert q.tolist() == [[3, 3, -1, -1]]
    q = push(q, np.array([3]))  # the first update: [3, -1, -1, 3], two 3s -> 3
    assert q.tolist() == [[3, -1, -1, 3]] and mofn_output(q, 2).tolist() == [3]
    q = push(q, np.array([0]))  # [-1, -1, 3, 0]: only one value >= 3, two >= 0 -> 0
    assert q.tolist() == [[-1, -1, 3, 0]] and mofn_output(q, 2).tolist() == [0]
    assert mofn_output(np.array([[-1, -1, -1, 2]]), 2).tolist() == [-1]  # fewer than M valid values


def test_mofn_literal():
    q = push(seeded_queue(np.array([0]), 2, 4), np.array([0]))  # [0, -1, -1, 0]
    seq = []
    for raw in (3, 3, 0, 0, 0):
        q = push(q, np.array([raw]))
        seq.append(int(mofn_output(q, 2)[0]))
    # queues: [-1,-1,0,3] [-1,0,3,3] [0,3,3,0] [3,3,0,0] [3,0,0,0]
    assert seq == [0, 3, 3, 3, 0]


def _alert_run(raws, times):
    st = DaaState.initial(1, 1, CFG)
    return [int(st.update_alerts(t, np.array([[r]]), CFG)[0, 0]) for r, t in zip(raws, times)]


def test_alert_persistence_holds_a_raised_level_for_4_s():
    # t=0 raw 2 -> 2 (raised at 0); raw 0 afterwards: M-of-N gives 0 from t=1, persistence keeps 2 while
    # t - 0 < 4 s, i.e. at t = 1, 2, 3; at t = 4 it drops
    assert _alert_run([2, 0, 0, 0, 0, 0], [0, 1, 2, 3, 4, 5]) == [2, 2, 2, 2, 0, 0]


def test_alert_mofn_rejects_a_single_spike_and_needs_2_of_4():
    # queues: seeded [0,0,-1,-1]+0 -> [0,-1,-1,0]; +0 [-1,-1,0,0]; +3 [-1,0,0,3] -> 0; +0 [0,0,3,0] -> 0;
    # +3 [0,3,0,3] -> 3
    assert _alert_run([0, 0, 3, 0, 3], [0, 1, 2, 3, 4]) == [0, 0, 0, 0, 3]


def test_alert_hysteresis_resets_after_more_than_5_s():
    assert _alert_run([2, 0], [0.0, 3.0]) == [2, 2]  # within persistence
    assert _alert_run([2, 0], [0.0, 5.0]) == [2, 0]  # persistence over (5 - 0 >= 4)
    assert _alert_run([2, 0], [0.0, 6.0]) == [2, 0]  # gap > 5 s: history dropped
    # a gap of 5.5 s drops the history: the 0 is then seeded, a later single 2 is a spike
    assert _alert_run([2, 0, 2], [0.0, 5.5, 6.5]) == [2, 0, 0]
    assert _alert_run([2, 0, 2], [0.0, 4.5, 5.5]) == [2, 0, 2]  # no reset: [2,2,0,2] has two 2s
    # time not advancing also resets
    assert _alert_run([3, 0], [1.0, 1.0]) == [3, 0]


def _head_on(t_in_s, dz=0.0):
    """Co-altitude head-on at 110 m/s closure whose corrective-volume violation starts at t_in_s."""
    D = CFG.th.dthr
    r_star = (35 * 110 + np.sqrt((35 * 110) ** 2 + 4 * D * D)) / 2  # tau_mod = 35 s here
    own = own_state()
    return own, intruders([[[0.0, r_star + t_in_s * 110.0, 1000.0 + dz, 55.0, np.pi, 0.0]]])


def test_early_alerting_time_keeps_a_corrective_alert_out_to_75_s():
    own, i50 = _head_on(50.0)
    _, i60 = _head_on(60.0)
    _, i80 = _head_on(80.0)
    assert alert_levels(own, i50, CFG)[0, 0] == 2 and alert_levels(own, i60, CFG)[0, 0] == 0  # stateless
    st = DaaState.initial(1, 1, CFG)
    levels = []
    for t, intr in ((0.0, i50), (1.0, i60), (2.0, i80)):
        raw = alert_levels(own, intr, CFG, prev=st.early_alert_level(t))
        levels.append((int(raw[0, 0]), int(st.update_alerts(t, raw, CFG)[0, 0])))
    # t=1: the previous output was 2, so level 2 uses 75 s and 60 s qualifies; t=2: 80 s > 75 s, raw 0,
    # but persistence (raised at 0, 2 - 0 < 4) keeps the output at 2
    assert levels == [(2, 2), (2, 2), (0, 2)]


def _track_bands(regions: np.ndarray) -> Bands:
    """Synthetic 1-deg track bands (own track 0) with the given per-candidate regions, -180..180 deg."""
    k = regions.size
    j = (k - 1) // 2
    deg = np.arange(-j, j + 1) * 1.0
    delta = deg * DEG
    vals = np.mod(delta, 2 * np.pi)
    side = np.sign(deg).astype(int)
    ab = AxisBands(AXIS_HORIZONTAL, vals[None], delta[None], side, (np.abs(delta) / CFG.turn_rate)[None],
                   np.full((1, k), np.inf), np.full((1, k), -np.inf), regions[None].astype(np.int8),
                   np.array([np.nan]), np.array([np.nan]), np.zeros(1, np.int8))
    # the other axes are not looked at by these tests: give them an all-NONE single-candidate band
    one = AxisBands(3, np.array([[50.0]]), np.zeros((1, 1)), np.array([0]), np.zeros((1, 1)), np.full((1, 1), np.inf),
                    np.full((1, 1), -np.inf), np.zeros((1, 1), np.int8), np.array([np.nan]), np.array([np.nan]),
                    np.zeros(1, np.int8))
    two = AxisBands(2, np.array([[0.0]]), np.zeros((1, 1)), np.array([0]), np.zeros((1, 1)), np.full((1, 1), np.inf),
                    np.full((1, 1), -np.inf), np.zeros((1, 1), np.int8), np.array([np.nan]), np.array([np.nan]),
                    np.zeros(1, np.int8))
    return Bands(ab, two, one, alert=np.zeros((1, 1), np.int8), preset="daidalus")


def _regions(spans, k=361):
    """Region array over -180..180 deg: spans = [(lo_deg, hi_deg, region)]."""
    deg = np.arange(-(k - 1) // 2, (k - 1) // 2 + 1)
    r = np.zeros(k, np.int8)
    for lo, hi, reg in spans:
        r[(deg >= lo) & (deg <= hi)] = reg
    return r, deg


def test_band_mofn_a_new_band_needs_two_of_four_steps():
    st = DaaState.initial(1, 1, CFG)
    clear, deg = _regions([])
    band, _ = _regions([(40, 60, REGION_NEAR)])
    out = [st.update_bands(t, _track_bands(r), CFG).trk.region[0] for t, r in
           ((0.0, clear), (1.0, band), (2.0, band), (3.0, clear), (4.0, clear))]
    at50 = [int(o[deg == 50][0]) for o in out]
    # bin queues: seeded [0,0,-1,-1]+0; +3 -> [-1,-1,0,3] -> 0; +3 -> [-1,0,3,3] -> 3; +0 -> [0,3,3,0] -> 3;
    # +0 -> [3,3,0,0] -> 3 (the band outlives the raw one by two steps)
    assert at50 == [REGION_NONE, REGION_NONE, REGION_NEAR, REGION_NEAR, REGION_NEAR]
    assert all(int(o[deg == 80][0]) == REGION_NONE for o in out)


def test_band_persistence_keeps_the_current_conflict_band_for_4_s():
    st = DaaState.initial(1, 1, CFG)
    band, deg = _regions([(-10, 10, REGION_NEAR)])
    clear, _ = _regions([])
    seq = [(0.0, band)] + [(float(t), clear) for t in range(1, 6)]
    out = [st.update_bands(t, _track_bands(r), CFG).trk for t, r in seq]
    cur = [int(o.region[0, o.k0]) for o in out]
    # M-of-N alone drops the band at t=1 ([3,-1,-1,0] -> 0); persistence repaints the remembered band
    # [-10, 10] NEAR while t - 0 < 4 s
    assert cur == [REGION_NEAR, REGION_NEAR, REGION_NEAR, REGION_NEAR, REGION_NONE, REGION_NONE]
    assert int(out[2].region[0][deg == 10][0]) == REGION_NEAR and int(out[2].region[0][deg == 11][0]) == REGION_NONE
    # while the band is held, the resolutions are those of the held band (first conflict-free degree)
    assert np.degrees(out[2].res_hi[0]) == pytest.approx(11.0) and np.degrees(out[2].res_lo[0]) % 360 == pytest.approx(349.0)


def test_preferred_direction_is_kept_for_4_s_and_within_15_deg():
    st = DaaState.initial(1, 1, CFG)
    # current value in a MID band; left resolution at -20 deg, right at +30 deg: left is nearer
    a, deg = _regions([(-19, 29, REGION_MID)])
    b, _ = _regions([(-59, 29, REGION_MID)])  # then the left one moves to -60: right is nearer by 30 deg
    c, _ = _regions([(-39, 29, REGION_MID)])  # left at -40: right nearer by 10 deg (< 15 deg delta)
    seq = [(0.0, a), (1.0, b), (2.0, b), (3.0, b), (4.0, b)]
    pref = [int(st.update_bands(t, _track_bands(r), CFG).trk.preferred[0]) for t, r in seq]
    assert pref == [-1, -1, -1, -1, +1]  # switched once 4 s have passed since the direction was set
    st = DaaState.initial(1, 1, CFG)
    pref = [int(st.update_bands(t, _track_bands(r), CFG).trk.preferred[0]) for t, r in
            ((0.0, a), (1.0, c), (5.0 - 0.5, c), (6.0 - 0.5, c))]
    assert pref == [-1, -1, -1, -1]  # |30 - 40| = 10 deg < 15 deg: kept after 4 s as well


def test_resolution_kept_while_in_the_same_conflict_free_region():
    st = DaaState.initial(1, 1, CFG)
    a, deg = _regions([(-19, 29, REGION_MID)])
    d, _ = _regions([(-24, 29, REGION_MID)])  # left resolution moves 5 deg further; -20 now in conflict
    e, _ = _regions([(-19, 29, REGION_MID), (-40, -35, REGION_MID)])  # still free at -20, same region
    out = [st.update_bands(t, _track_bands(r), CFG).trk for t, r in ((0.0, a), (1.0, e), (2.0, d), (3.0, d))]
    lo = [float(np.degrees(r.res_lo[0]) % 360) for r in out]
    # t=1: -20 still free and in the same free region as the raw one: kept (and equal). t=2: the new MID
    # degrees -24..-20 appear once, M-of-N ([-1,0,0,2] -> 0) does not show them yet: still -20. t=3: they
    # are MID ([0,0,2,2] -> 2), -20 is inside a conflict band: the raw resolution -25 replaces it
    assert lo == pytest.approx([340.0, 340.0, 340.0, 335.0])


def test_agent_uses_the_state_only_with_the_daidalus_preset():
    own, i50 = _head_on(50.0)
    _, i60 = _head_on(60.0)
    pol = policy_for_group("B-1")
    for cfg, want in ((CFG, [2, 2]), (DaaConfig.for_preset("do365"), None)):
        mem = AgentMemory.initial(1, own)
        got = []
        for t, intr in ((0.0, i50), (1.0, i60)):
            _, dec, mem = agent_step(t, own, intr, PilotInput.nothing(1, t), mem, pol, cfg)
            got.append(int(dec["alert_level"][0, 0]))
        if want is None:
            assert mem.daa_state is None
            assert got == [int(alert_levels(own, i50, cfg)[0, 0]), int(alert_levels(own, i60, cfg)[0, 0])]
        else:
            assert got == want and isinstance(mem.daa_state, DaaState)


def test_state_selection_and_batch_independence():
    rng = np.random.default_rng(7)
    n = 6
    own = own_state(n)
    rows = np.stack([rng.uniform(-3000, 3000, n), rng.uniform(2000, 7000, n), 1000 + rng.uniform(-100, 100, n),
                     rng.uniform(40, 150, n), rng.uniform(2.5, 3.8, n), rng.uniform(-3, 3, n)], -1)[:, None, :]
    intr = intruders(rows)
    st = DaaState.initial(n, 1, CFG)
    singles = [DaaState.initial(1, 1, CFG) for _ in range(n)]
    for t in (0.0, 1.0, 2.0):
        raw = alert_levels(own, intr, CFG, prev=st.early_alert_level(t))
        lv = st.update_alerts(t, raw, CFG)
        b = st.update_bands(t, compute_bands(own, intr, CFG, lv), CFG)
        for i in range(n):
            si = singles[i]
            raw_i = alert_levels(own[i:i + 1], intr[i:i + 1], CFG, prev=si.early_alert_level(t))
            lv_i = si.update_alerts(t, raw_i, CFG)
            bi = si.update_bands(t, compute_bands(own[i:i + 1], intr[i:i + 1], CFG, lv_i), CFG)
            assert lv_i[0, 0] == lv[i, 0]
            assert np.array_equal(bi.trk.region[0], b.trk.region[i])
    assert np.array_equal(st[2:4].level, st.level[2:4])


def test_resolution_kept_when_the_raw_one_moves_within_15_deg():
    st = DaaState.initial(1, 1, CFG)
    wide, deg = _regions([(-24, 29, REGION_MID)])
    narrow, _ = _regions([(-19, 29, REGION_MID)])
    seq = [(0.0, wide)] + [(float(t), narrow) for t in range(1, 7)]
    out = [st.update_bands(t, _track_bands(r), CFG).trk for t, r in seq]
    lo = [float(np.degrees(r.res_lo[0]) % 360) for r in out]
    # raw left resolution -25 deg at t=0, then -20 deg (the band shrank): the old -25 deg is in the same
    # conflict-free region, and raw - old = 5 deg < 15 deg, so it is kept, also after the 4 s persistence
    assert lo == pytest.approx([335.0] * 7)
    fresh = DaaState.initial(1, 1, CFG)
    assert float(np.degrees(fresh.update_bands(0.0, _track_bands(narrow), CFG).trk.res_lo[0]) % 360) == pytest.approx(340.0)
