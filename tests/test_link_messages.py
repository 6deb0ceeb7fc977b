"""Message builders/readers: wire codes equal the agent's codes; bands split and reassemble."""

from __future__ import annotations

import math

import numpy as np
import pytest

from daa_sil.agent import step as agent
from daa_sil.daa import config as daa_config
from daa_sil.errors import UsageError
from daa_sil.link.codec import MavCodec, mavlink as d
from daa_sil.link.messages import (CODES, NAMES, allocation_decision, bands_from, daa_bands, ms, pilot_command_from,
                                   pilot_maneuver, sim_tick, sim_tick_ack)


def _wire(msgs):
    tx, rx = MavCodec(1, 1), MavCodec(255, 190)
    return [m for x in msgs for m in rx.decode(tx.encode(x))]


def test_wire_codes_equal_agent_codes():
    assert NAMES["decision"] == agent.DECISION_NAMES
    assert NAMES["authority"] == agent.AUTHORITY_NAMES
    assert NAMES["rule"] == daa_config.RULE_NAMES
    assert NAMES["axis"] == daa_config.AXIS_NAMES
    assert NAMES["dir"] == daa_config.DIR_NAMES
    assert NAMES["region"][:5] == daa_config.REGION_NAMES


def test_ms_and_ticks():
    assert ms(1.0004) == 1000 and ms(0) == 0
    with pytest.raises(UsageError):
        ms(-1.0)
    with pytest.raises(UsageError):
        ms(float("nan"))
    tick, ack = _wire([sim_tick(3, 3.0), sim_tick_ack(3, 3.0, 2)])
    assert (tick.tick, tick.time_ms, ack.tick, ack.time_ms, ack.sent) == (3, 3000, 3, 3000, 2)


def test_pilot_maneuver_and_set_position_target_mapping():
    (m,) = _wire([pilot_maneuver(12.5, 4, track_deg=-90.0, vs=2.0)])
    pc = pilot_command_from(m)
    assert pc.t_sent_s == 12.5 and pc.cmd_seq == 4 and pc.track_deg == 270.0 and pc.vs == 2.0
    assert math.isnan(pc.gs)
    # velocity north-east 10/10 m/s, climbing 1 m/s (NED vz = -1) -> track 45 deg, gs 14.14, vs +1
    sp = d.MAVLink_set_position_target_global_int_message(7000, 1, 1, d.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, 0x0DC7,
                                                          0, 0, 0.0, 10.0, 10.0, -1.0, 0, 0, 0, 0, 0)
    (w,) = _wire([sp])
    pc = pilot_command_from(w)
    assert pc.t_sent_s == 7.0 and pc.track_deg == pytest.approx(45.0) and pc.gs == pytest.approx(math.hypot(10, 10))
    assert pc.vs == 1.0 and pc.source == "SET_POSITION_TARGET_GLOBAL_INT"
    pos_only = d.MAVLink_set_position_target_global_int_message(7000, 1, 1, 6, 0x0DF8, 1, 1, 100.0, 0, 0, 0,
                                                                0, 0, 0, 0, 0)
    assert pilot_command_from(pos_only) is None
    with pytest.raises(UsageError, match="cmd_seq"):
        pilot_maneuver(1.0, 0)


def test_bands_split_and_reassemble():
    n = 37
    lo = [float(i) for i in range(n)]
    hi = [float(i) + 0.5 for i in range(n)]
    rg = [NAMES["region"][1 + i % 4] for i in range(n)]
    msgs = daa_bands(5.0, "track", lo, hi, rg)
    assert [(m.part, m.parts, m.count) for m in msgs] == [(0, 3, 16), (1, 3, 16), (2, 3, 5)]
    got = bands_from(_wire(msgs[::-1]))  # any arrival order
    lo2, hi2, rg2 = got[CODES["dimension"]["track"]]
    assert lo2 == lo and hi2 == hi and rg2 == [CODES["region"][r] for r in rg]
    assert bands_from(_wire(msgs[:2])) == {}  # incomplete -> left out
    (empty,) = daa_bands(5.0, "vertical_speed", [], [], [])
    assert bands_from(_wire([empty])) == {CODES["dimension"]["vertical_speed"]: ([], [], [])}
    with pytest.raises(UsageError, match="region"):
        daa_bands(5.0, "track", [0.0], [1.0], ["bogus"])


def test_allocation_decision_from_agent_record():
    rec = {"decision": np.array([agent.D_BLEND, agent.D_WAIT]), "authority": np.array([agent.A_DAA, agent.A_WAITING]),
           "rule": np.array([1, 0]), "wait_s": np.array([np.nan, 7.5]), "projl": np.array([True, False]),
           "sm_pilot": np.array([-3.0, np.nan]), "cmd_trk": np.array([math.pi / 2, np.nan]),
           "cmd_vs": np.array([0.0, np.nan]), "pilot_axis": np.array([1, 0]), "pilot_dir": np.array([2, 0])}
    (m0,) = _wire([allocation_decision(10.0, rec, 0, pilot_cmd_seq=5)])
    assert (m0.decision, m0.authority, m0.rule, m0.projl) == (agent.D_BLEND, agent.A_DAA, 1, 1)
    assert m0.cmd_trk_deg == pytest.approx(90.0) and m0.sm_pilot == -3.0 and m0.pilot_cmd_seq == 5
    assert math.isnan(m0.wait_s) and math.isnan(m0.cmd_gs) and NAMES["dir"][m0.pilot_dir] == "right"
    (m1,) = _wire([allocation_decision(11.0, rec, 1)])
    assert NAMES["decision"][m1.decision] == "wait" and m1.wait_s == 7.5 and math.isnan(m1.cmd_trk_deg)
