"""The agent's switchable rules of the paper's readings: an unsafe 'hold' decided as no command, and
the wait read outside the map's box (clamp to the box vs w = H)."""

from dataclasses import replace

import numpy as np
import pytest

from daa_sil.agent.memory import AgentMemory, PilotInput
from daa_sil.agent.decision import D_BLEND, D_NO_WAIT, D_WAIT
from daa_sil.agent.wait_function import WaitValue, make_wait_lookup
from daa_sil.agent.step import agent_step
from daa_sil.config.groups import policy_for_group
from daa_sil.daa import AXIS_NONE, DaaConfig, alert_levels
from daa_sil.errors import UsageError
from daa_sil.waitmap.lookup import LookupResult

from daa_helpers import hold_into_head_on, intruders, own_state

CFG = DaaConfig()



@pytest.mark.parametrize("wait_s, decision", [(60.0, D_WAIT), (0.0, D_NO_WAIT)])
def test_unsafe_hold_is_decided_as_no_command(wait_s, decision):
    own, intr, pin = hold_into_head_on(CFG)
    lookup = lambda o, i, t: WaitValue.constant(o.shape[0], wait_s)  # noqa: E731
    pol = replace(policy_for_group("ID-2"), projl=False)
    _, dec, _ = agent_step(10.0, own, intr, pin, AgentMemory.initial(1, own), pol, CFG, lookup)
    assert dec["decision"][0] == D_BLEND and dec["pilot_axis"][0] == AXIS_NONE  # the default: blended
    _, dec, mem = agent_step(10.0, own, intr, pin, AgentMemory.initial(1, own), replace(pol, unsafe_hold="no-command"),
                             CFG, lookup)
    assert dec["decision"][0] == decision and dec["sm_pilot"][0] <= 0
    assert dec["pilot_cmd_fresh"][0]  # it did arrive (counted over the whole encounter as an arrival)
    assert mem.pilot_trk[0] == pytest.approx(0.0)  # and it is the pilot's latest command


def test_unsafe_hold_rule_is_validated():
    with pytest.raises(UsageError, match="unsafe_hold must be one of blend, no-command"):
        replace(policy_for_group("ID-2"), unsafe_hold="maybe")


class _Family:
    """A stand-in wait-map family: one state inside the box (w = 7 s), one outside (clamped: w = 2 s)."""

    class params:
        horizon = 60.0

    def lookup(self, states, turn):
        shape = np.shape(states)[:-1]
        inside = np.zeros(shape, bool)
        inside[0] = True
        return LookupResult(np.where(inside, 7.0, 2.0), np.full(shape, 0.1), np.zeros(shape, bool), inside,
                            inside.copy(), np.zeros(shape))


def test_outside_the_box_reads_the_nearest_state_or_the_horizon():
    own = own_state(n=2)
    intr = intruders([[[0.0, 1000.0, 1000.0, 60.0, np.pi, 0.0]], [[0.0, 9000.0, 1000.0, 60.0, np.pi, 0.0]]])
    rate = np.zeros((2, 1))
    clamp = make_wait_lookup(_Family(), CFG)(own, intr, rate)
    far = make_wait_lookup(_Family(), CFG, outside="far")(own, intr, rate)
    assert list(clamp.wait_s) == [7.0, 2.0]
    assert list(far.wait_s) == [7.0, 60.0]  # outside: w = H; inside unchanged
    assert list(far.in_box) == [True, False]
    with pytest.raises(UsageError, match="outside must be one of clamp, far"):
        make_wait_lookup(_Family(), CFG, outside="near")


def test_agent_decides_over_the_whole_encounter_until_safe_avoidance():
    """active_from="encounter": with no alert and no fresh command the agent still decides (B-2: no
    wait, DAA authority; ID-2 waits); once the intruder is past its closest point of approach and
    nothing alerts, the encounter is over and the agent stands down for good (unless alerted again)."""
    own = own_state()
    far = intruders([[[0.0, 30000.0, 1000.0, 60.0, np.pi, 0.0]]])  # 30 km ahead, closing, no alert
    behind = intruders([[[0.0, -3000.0, 1000.0, 60.0, np.pi, 0.0]]])  # passed, diverging
    assert alert_levels(own, far, CFG)[0, 0] == 0
    nothing = PilotInput.nothing(1, 10.0)
    mem = AgentMemory.initial(1, own)
    b2 = policy_for_group("B-2")
    _, dec, _ = agent_step(10.0, own, far, nothing, mem, b2, CFG)
    assert not dec["active"][0]  # the default: decisions from the corrective alert only
    enc = replace(b2, active_from="encounter")
    _, dec, m1 = agent_step(10.0, own, far, nothing, mem, enc, CFG)
    assert dec["active"][0] and dec["decision"][0] == D_NO_WAIT and not m1.encounter_over[0]
    lookup = lambda o, i, t: WaitValue.constant(o.shape[0], 30.0)  # noqa: E731
    _, dec, _ = agent_step(10.0, own, far, nothing, mem, replace(policy_for_group("ID-2"), active_from="encounter"),
                           CFG, lookup)
    assert dec["decision"][0] == D_WAIT
    _, dec, m2 = agent_step(11.0, own, behind, nothing, m1, enc, CFG)
    assert not dec["active"][0] and m2.encounter_over[0]
    _, dec, _ = agent_step(12.0, own, far, nothing, m2, enc, CFG)  # latched: no decision without an alert
    assert not dec["active"][0]
    with pytest.raises(UsageError, match="active_from must be one of corrective, encounter"):
        replace(b2, active_from="always")
