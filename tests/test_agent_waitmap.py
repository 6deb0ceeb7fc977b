"""The agent with the production wait maps: lookups, turn-rate map choice, decision provenance."""

from dataclasses import replace

import numpy as np
import pytest

from daa_sil import waitmap
from daa_sil.agent.decision import BY_BOTH, BY_MAP, BY_NEITHER, BY_NONE, BY_PROJL, D_NO_WAIT, D_WAIT
from daa_sil.agent.memory import AgentMemory, PilotInput
from daa_sil.agent.wait_function import WaitValue, make_wait_lookup
from daa_sil.agent.step import agent_step
from daa_sil.config.groups import policy_for_group
from daa_sil.daa import DaaConfig
from daa_sil.geometry.frames import to_paper_state

from daa_helpers import intruders, own_state

CFG = DaaConfig(thresholds="paper")


@pytest.fixture(scope="module")
def family():
    """The paper-grid family the campaigns use with ``--waitmap paper`` (built once, cached)."""
    return waitmap.family_for("paper")


def test_lookup_reads_the_map_of_the_most_threatening_intruder(family):
    lookup = make_wait_lookup(family, cfg=CFG)
    own = own_state(1)
    near = [0.0, 900.0, 1000.0, 55.0, np.pi, 0.0]  # LoWC now
    far = [0.0, -30000.0, 1000.0, 55.0, np.pi, 0.0]  # 30 km behind, flying away
    zero = np.zeros((1, 2))
    w_far = lookup(own, intruders([[far]]), zero[:, :1])
    assert w_far.wait_s[0] > 0 and not w_far.in_box[0]
    for pair in ([far, near], [near, far]):
        v = lookup(own, intruders([pair]), zero)
        assert v.wait_s[0] == 0.0 and v.p_lowc[0] == 1.0


def test_turn_rate_picks_the_map_and_is_recorded(family):
    """An intruder turning right at 5 deg/s (compass) reads the paper-sense -5 deg/s map, at the
    value that map gives for its paper state."""
    lookup = make_wait_lookup(family, cfg=CFG)
    own = own_state(3)
    row = [900.0, 900.0, 1200.0, 100.0, np.radians(200.0), 0.0]  # ahead right, 200 m above, converging
    intr = intruders([[row]] * 3)
    rate = np.radians(np.array([[5.0], [-2.4], [0.4]]))
    v = lookup(own, intr, rate)
    np.testing.assert_allclose(v.turn_dps, [5.0, -2.4, 0.4])
    np.testing.assert_allclose(v.map_turn_dps, [5.0, -2.5, 0.0])
    paper = to_paper_state(own.position()[:1, None], own.velocity()[:1, None], intr.position()[:1], intr.velocity()[:1])
    for k, paper_rate in enumerate((-5.0, 2.5, 0.0)):
        direct = family.map_for(paper_rate).lookup(paper[0, 0])
        assert v.wait_s[k] == pytest.approx(float(direct.wait_s))
    assert len({round(float(w), 3) for w in v.wait_s}) > 1  # the turn rate changes the answer here
    assert np.all((v.wait_s > 0) & (v.wait_s < family.params.horizon))  # a non-trivial state


def _const(values):
    """A lookup answering fixed waits (s) per encounter."""
    def lookup(own, intr, turn):
        v = WaitValue.constant(own.shape[0], 0.0)
        v.wait_s = np.asarray(values, float)[: own.shape[0]]
        return v
    return lookup


def test_decided_by_is_the_counterfactual_of_always_wait():
    """Four encounters with a corrective alert, no pilot command: w below / above W_T, with / without
    ProjL. decided_by says which veto fired; replacing the map by 'always wait' changes exactly the
    'map' rows."""
    own = own_state(4)
    # ProjL within 25 s: a head-on at 3 km closing at 110 m/s; none: the same 6 km away, 300 m above
    hot = [0.0, 3000.0, 1000.0, 55.0, np.pi, 0.0]
    cool = [0.0, 6000.0, 1250.0, 55.0, np.pi, -4.0]
    intr = intruders([[cool], [hot], [cool], [hot]])
    mem = AgentMemory.initial(4, own)
    pol = policy_for_group("ID-2")
    pin = PilotInput.nothing(4, 9.0)
    _, dec, _ = agent_step(10.0, own, intr, pin, mem, pol, CFG, _const([1.0, 1.0, 30.0, 30.0]))
    assert dec["active"].all(), dec["max_alert"]
    np.testing.assert_array_equal(dec["projl"], [False, True, False, True])
    np.testing.assert_array_equal(dec["decided_by"], [BY_MAP, BY_BOTH, BY_NEITHER, BY_PROJL])
    np.testing.assert_array_equal(dec["decision"], [D_NO_WAIT, D_NO_WAIT, D_WAIT, D_NO_WAIT])
    always = replace(pol, wait_mode="always")
    _, dec2, _ = agent_step(10.0, own, intr, pin, mem, always, CFG, None)
    changed = dec2["decision"] != dec["decision"]
    np.testing.assert_array_equal(changed, dec["decided_by"] == BY_MAP)
    # without the ProjL veto (ID-2-map) only the map decides
    _, dec3, _ = agent_step(10.0, own, intr, pin, mem, policy_for_group("ID-2-map"), CFG, _const([1.0, 1.0, 30.0, 30.0]))
    np.testing.assert_array_equal(dec3["decided_by"], [BY_MAP, BY_MAP, BY_NEITHER, BY_NEITHER])
    np.testing.assert_array_equal(dec3["decision"], [D_NO_WAIT, D_NO_WAIT, D_WAIT, D_WAIT])
    assert BY_NONE == 0


def test_agent_with_the_production_map_records_the_lookup(family):
    lookup = make_wait_lookup(family, cfg=CFG)
    own = own_state(1)
    intr = intruders([[[300.0, 3000.0, 1200.0, 100.0, np.pi, -4.0]]])  # head-on, 200 m above, descending
    _, dec, _ = agent_step(10.0, own, intr, PilotInput.nothing(1, 9.0), AgentMemory.initial(1, own),
                           policy_for_group("ID-2"), CFG, lookup, turn_rate=np.zeros((1, 1)))
    v = lookup(own, intr, np.zeros((1, 1)))
    assert dec["active"][0] and dec["wait_s"][0] == v.wait_s[0] and dec["wait_p_lowc"][0] == v.p_lowc[0]
    assert dec["wait_map_turn_dps"][0] == 0.0 and bool(dec["wait_in_box"][0]) == bool(v.in_box[0])
    assert 4.0 <= v.wait_s[0] < family.params.horizon  # the map alone would wait here ...
    assert dec["projl"][0] and dec["decision"][0] == D_NO_WAIT and dec["decided_by"][0] == BY_PROJL  # ... ProjL vetoes
