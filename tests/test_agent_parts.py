"""The agent's parts on their own: the decision record, the wait-function registry and the link sub-step.

Expected values are written by hand: the wire order of the record's fields (the step-log columns
and ALLOCATION_DECISION read it), the wait each function gives, and which command is fresh.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import pytest

from daa_sil.agent.memory import AgentMemory, PilotInput
from daa_sil.agent.substeps import link_step
from daa_sil.agent.allocation import PolicyRows
from daa_sil.config.policy import WAIT_MODES, AllocationPolicy
from daa_sil.agent.decision import DECISION_FIELDS, Decision, decode
from daa_sil.errors import UsageError
from daa_sil.geometry.kinematics import Command
from daa_sil.agent.wait_function import WAIT_FUNCTIONS, WaitValue, wait_values

from daa_helpers import intruders, own_state

#: the order the step log and the wire have always used (written out, not derived)
WIRE_ORDER = (
    "active", "decision", "rule", "authority", "wait_s", "projl", "decided_by", "wait_p_lowc", "wait_in_box",
    "wait_turn_dps", "wait_map_turn_dps", "link_lost", "max_alert", "alert_level",
    "pilot_cmd_received", "pilot_cmd_fresh", "pilot_cmd_age_s", "sm_pilot", "sm_exec",
    "pilot_axis", "pilot_dir", "exec_axis", "exec_dir", "exact_match",
    "cmd_trk", "cmd_vs", "cmd_gs", "pilot_trk", "pilot_vs", "pilot_gs", "daa_trk", "daa_vs", "daa_gs",
    "bands_trk", "bands_trk_region",
)


def far_intruders(n: int):
    """One intruder per row, 5 km north, head-on."""
    return intruders([[(0.0, 5000.0, 1000.0, 55.0, np.pi, 0.0)]] * n)


def test_the_record_keeps_the_wire_order_and_reads_as_a_mapping():
    assert DECISION_FIELDS == WIRE_ORDER
    values = {k: np.array([1]) for k in WIRE_ORDER}  # code 1 is a valid code of every coded field
    dec = Decision(**values)
    assert isinstance(dec, Mapping) and list(dec) == list(WIRE_ORDER) and len(dec) == 35
    assert dec["wait_s"] is values["wait_s"] and dec.wait_s is values["wait_s"]
    with pytest.raises(KeyError):
        dec["nosuch"]
    assert (decode(dec)["decision"][0], decode(dec)["authority"][0]) == ("wait", "daa")


def test_the_wait_functions_by_name():
    assert tuple(WAIT_FUNCTIONS) == WAIT_MODES
    own, intr = own_state(3), far_intruders(3)
    rate = np.zeros((3, 1))
    const = np.array([2.0, 5.0, 9.0])
    assert WAIT_FUNCTIONS["none"](const)(own, intr, rate).wait_s.tolist() == [0.0, 0.0, 0.0]
    assert WAIT_FUNCTIONS["constant"](const)(own, intr, rate).wait_s.tolist() == [2.0, 5.0, 9.0]
    assert WAIT_FUNCTIONS["always"](const)(own, intr, rate).wait_s.tolist() == [np.inf] * 3
    with pytest.raises(UsageError, match="needs a wait_lookup"):
        WAIT_FUNCTIONS["map"](const)
    # one batch, one row per wait mode: each row reads its own function (the map row its lookup)
    pols = [AllocationPolicy(m, constant_wait_s=7.0) for m in WAIT_MODES]
    rows = PolicyRows(tuple(pols), np.arange(4))
    lookup = lambda o, i, t: WaitValue(np.full(o.shape[0], 33.0), np.full(o.shape[0], 0.25),  # noqa: E731
                                       np.ones(o.shape[0], bool), np.zeros(o.shape[0]), np.zeros(o.shape[0]))
    wv = wait_values(own_state(4), far_intruders(4), rows, lookup, None, np.arange(4))
    assert wv.wait_s.tolist() == [0.0, 7.0, 33.0, np.inf]  # none, constant, map, always
    assert wv.in_box.tolist() == [False, False, True, False]
    assert np.isnan(wv.p_lowc[[0, 1, 3]]).all() and wv.p_lowc[2] == 0.25


def test_link_step_freshness_and_loss():
    """Row 0: a command sent 2 s ago (fresh); row 1: sent 20 s ago (stale, > 15 s); row 2: nothing
    for 25 s (> the 20 s link timeout: lost)."""
    own = own_state(3)
    mem = AgentMemory.initial(3, own, t0=0.0)
    nan = np.nan
    cmd = Command(np.array([1.0, 2.0, nan]), np.array([0.0, 0.0, nan]), np.array([50.0, 50.0, nan]))
    pilot = PilotInput(np.array([True, True, False]), cmd, np.array([23.0, 5.0, nan]), np.array([24.0, 24.0, nan]),
                       np.array([24.0, 24.0, nan]))
    lk = link_step(25.0, own, pilot, mem, PolicyRows.of(AllocationPolicy("map"), 3))
    assert lk.fresh.tolist() == [True, False, False] and lk.stale.tolist() == [False, True, False]
    assert lk.link_lost.tolist() == [False, False, True]
    assert lk.age[:2].tolist() == [2.0, 20.0] and np.isnan(lk.age[2])
    assert lk.last_pilot.trk[0] == 1.0 and lk.last_pilot.trk[1] == own.trk[1]  # a stale command is not stored
