"""The agent with a real wait-map family (one small map built in the test)."""

import numpy as np
import pytest

from daa_sil.agent import AgentMemory, D_NO_WAIT, D_WAIT, PilotInput, agent_step, make_wait_lookup, policy_for_group
from daa_sil.daa import DaaConfig

from daa_helpers import intruders, own_state

waitmap = pytest.importorskip("daa_sil.waitmap")


@pytest.fixture(scope="module")
def family():
    from daa_sil.waitmap.grid import paper_grid
    from daa_sil.waitmap.model import MdpParams

    return waitmap.build_family(paper_grid(), MdpParams(preset="paper"), turn_rates=(0.0,))


def test_real_family_drives_wait_decisions(family):
    cfg = DaaConfig(thresholds="paper")
    lookup = make_wait_lookup(family, cfg=cfg)
    own = own_state(2)
    # 0: already in LoWC (map: W = 0 inside); 1: 300 m above descending 10 m/s, 2.5 km ahead
    intr = intruders([[[0.0, 900.0, 1000.0, 55.0, np.pi, 0.0]], [[200.0, 2500.0, 1300.0, 55.0, np.pi, -10.0]]])
    w = lookup(own, intr)
    assert w.shape == (2,) and w[0] == 0.0 and np.all(np.isfinite(w)) and np.all(w >= 0)
    _, dec, _ = agent_step(10.0, own, intr, PilotInput.nothing(2, 9.0), AgentMemory.initial(2, own),
                           policy_for_group("ID-1"), cfg, lookup)
    assert dec["active"].all() and dec["decision"][0] == D_NO_WAIT
    np.testing.assert_array_equal(dec["wait_s"], w)
    expect = D_WAIT if (w[1] >= 4.0 and not dec["projl"][1]) else D_NO_WAIT
    assert dec["decision"][1] == expect


def test_most_threatening_intruder_sets_the_wait(family):
    cfg = DaaConfig(thresholds="paper")
    lookup = make_wait_lookup(family, cfg=cfg)
    own = own_state(1)
    near = [0.0, 900.0, 1000.0, 55.0, np.pi, 0.0]  # LoWC now
    far = [0.0, 30000.0, 1000.0, 55.0, np.pi, 0.0]  # out of the grid, no LoWC for minutes
    w_far = lookup(own, intruders([[far]]))[0]
    assert w_far > 0
    assert lookup(own, intruders([[far, near]]))[0] == 0.0 == lookup(own, intruders([[near, far]]))[0]
