"""The settings of the ``paper`` reading that follow the text: every setting has a basis; the wait
outside the map's box falls as the intruder closes; an unsafe 'hold' is blended or overridden; every
command the link releases is counted; a Gaussian delay drawn once per encounter; the DAA keeping its
authority (our extension)."""

from dataclasses import fields, replace

import numpy as np
import pytest

from daa_sil.agent.decision import A_DAA, D_DAA_OVERRIDE, D_NO_WAIT, D_WAIT
from daa_sil.agent.memory import AgentMemory, PilotInput
from daa_sil.agent.wait_function import WaitValue, make_wait_lookup
from daa_sil.agent.step import agent_step
from daa_sil.config.groups import policy_for_group
from daa_sil.config.basis import PAPER_BASIS, basis_records, consumed_findings
from daa_sil.config.readings import READINGS, Reading, reading_for
from daa_sil.daa import DaaConfig
from daa_sil.agent.decision import BY_KEPT
from daa_sil.errors import UsageError
from daa_sil.agent.wait_function import box_entry_time

from daa_helpers import hold_into_head_on, intruders, own_state

CFG = DaaConfig()


def test_every_setting_of_a_reading_has_a_basis_and_every_basis_a_setting():
    settings = {f.name for f in fields(Reading)} - {"name", "description"}
    keyed = {k for b in PAPER_BASIS for k in b.keys}
    assert keyed == settings
    for b in PAPER_BASIS:
        assert b.kind in ("text", "inference", "choice")
        assert b.quote or b.kind != "text"
    # the inference from the reception table uses B-1's count: under paper it is input, not a result
    assert consumed_findings(basis_records(READINGS["paper"])) == {("received", "B-1"), ("pilot-executed", "B-1")}
    # a reading without the 'hold' stream makes no such inference
    assert consumed_findings(basis_records(READINGS["paper-no-hold"])) == set()
    rec = {r["setting"]: r for r in basis_records(READINGS["paper-contradicted"])}
    assert rec["the wait outside the map's box"]["differs"] and rec["the wait outside the map's box"]["values"] == {
        "outside": "clamp"}
    with pytest.raises(ValueError, match="needs its quote"):
        type(PAPER_BASIS[0])("x", (), "v", "text")


def test_box_entry_time_by_hand():
    lo, hi = np.array([-1500.0, -1500.0, -200.0]), np.array([1500.0, 1500.0, 200.0])
    pos = np.array([[10000.0, 0.0, 0.0], [0.0, 0.0, 0.0], [10000.0, 0.0, 0.0], [10000.0, 3000.0, 0.0]])
    vel = np.array([[-100.0, 0.0, 0.0], [-100.0, 0.0, 0.0], [100.0, 0.0, 0.0], [-100.0, 0.0, 0.0]])
    t = box_entry_time(pos, vel, lo, hi)
    assert t[0] == pytest.approx(85.0) and t[1] == 0.0 and np.isinf(t[2]) and np.isinf(t[3])


@pytest.fixture(scope="module")
def paper_family():
    from daa_sil import waitmap

    return waitmap.family_for("paper", preset="paper", horizon=40.0)


def test_outside_the_box_the_wait_falls_as_the_intruder_closes(paper_family):
    """A co-altitude intruder dead ahead, closing at 155 m/s: clamped, it reads the box edge's short wait
    from 20 km to 1.5 km; under 'approach' the wait is H far out and falls one second per second to meet
    the map's value at the edge ("The decrease in the wait time is observed as the relative X distance
    reduces")."""
    ranges = np.array([20000.0, 8000.0, 4000.0, 2500.0, 1600.0, 1500.0, 1200.0])
    n = ranges.size
    own = own_state(n=n)
    intr = intruders([[[0.0, r, 1000.0, 100.0, np.pi, 0.0]] for r in ranges])
    rate = np.zeros((n, 1))
    clamp = make_wait_lookup(paper_family, CFG, outside="clamp")(own, intr, rate).wait_s
    appr = make_wait_lookup(paper_family, CFG, outside="approach")(own, intr, rate)
    w = appr.wait_s
    assert np.all(np.diff(w) <= 1e-9)  # never grows as the range shrinks
    assert w[0] == pytest.approx(40.0)  # capped at the maps' maximum
    assert np.all(w <= 40.0 + 1e-9) and np.all(w >= clamp - 1e-9)
    assert clamp[0] == pytest.approx(clamp[4])  # clamped: 20 km reads what 1.6 km reads
    assert clamp[0] < 4.0 <= w[0]  # where clamping forbids the wait, the text's rule allows it
    # 2.5 km out: 1,000 m / 155 m/s = 6.45 s to the edge, plus the edge's wait
    assert w[3] == pytest.approx(min(40.0, 1000.0 / 155.0 + w[5]), abs=0.05)
    assert w[5] == pytest.approx(clamp[5]) and w[6] == pytest.approx(clamp[6])  # inside the box: the map
    # an intruder that never enters the box (passing 3 km to the side) waits H
    side = make_wait_lookup(paper_family, CFG, outside="approach")(
        own_state(), intruders([[[3000.0, 5000.0, 1000.0, 100.0, np.pi, 0.0]]]), np.zeros((1, 1)))
    assert side.wait_s[0] == pytest.approx(40.0) and side.p_lowc[0] == 0.0



def test_an_unsafe_hold_is_overridden_in_the_baseline():
    """Algorithm 1 + the paper's definition of an override: an unsafe received command, a 'hold' too, is
    a DAA override in a baseline group (it was 'no command', a no-wait, under the old setting)."""
    own, intr, pin = hold_into_head_on(CFG)
    b2 = policy_for_group("B-2")
    _, dec, _ = agent_step(10.0, own, intr, pin, AgentMemory.initial(1, own), b2, CFG)
    assert dec["decision"][0] == D_DAA_OVERRIDE and dec["sm_pilot"][0] <= 0
    _, dec, _ = agent_step(10.0, own, intr, pin, AgentMemory.initial(1, own), replace(b2, unsafe_hold="no-command"), CFG)
    assert dec["decision"][0] == D_NO_WAIT


def test_the_daa_keeps_its_authority_until_clear_under_the_extension():
    own, intr, _ = hold_into_head_on(CFG)
    nothing = PilotInput.nothing(1, 10.0)
    lookup = lambda o, i, t: WaitValue.constant(o.shape[0], 30.0)  # noqa: E731 -- the map says: wait
    pol = replace(policy_for_group("ID-2"), projl=False, active_from="encounter")
    mem = replace(AgentMemory.initial(1, own), authority=np.array([A_DAA], np.int8))
    _, dec, _ = agent_step(10.0, own, intr, nothing, mem, pol, CFG, lookup)
    assert dec["decision"][0] == D_WAIT  # Algorithm 1 every step: back to waiting
    _, dec, m2 = agent_step(10.0, own, intr, nothing, mem, replace(pol, daa_authority="until-clear"), CFG, lookup)
    assert dec["decision"][0] == D_NO_WAIT and dec["decided_by"][0] == BY_KEPT and m2.authority[0] == A_DAA
    far = intruders([[[0.0, 30000.0, 1000.0, 60.0, np.pi, 0.0]]])  # clear: no alert
    _, dec, _ = agent_step(10.0, own, far, nothing, mem, replace(pol, daa_authority="until-clear"), CFG, lookup)
    assert dec["decision"][0] == D_WAIT
    with pytest.raises(UsageError, match="daa_authority must be one of per-step, until-clear"):
        replace(pol, daa_authority="forever")


def _one_encounter():
    from daa_sil.models.encounters import sample_encounters

    return sample_encounters(1, seed=11, preset="paper")


def test_every_released_command_is_counted_burst_by_hand():
    """The uplink delay drops from 8 s to 2 s at t = 50 s: the commands sent at 49..55 s are released
    together at 57 s (first in, first out). The vehicle flies the newest; the other six were received
    and superseded within their step: counted, not lost."""
    from daa_sil.models.delay_spec import parse_delay_spec
    from daa_sil.models.pilot_config import PilotConfig
    from daa_sil.study.simulation.fasttime import simulate

    pilot = reading_for("paper").pilot_config(PilotConfig())
    b2 = replace(policy_for_group("B-2"), active_from="encounter")
    spike = parse_delay_spec("spike:2,8,30,20")
    enc, _, _ = simulate(_one_encounter(), b2, spike, parse_delay_spec("const:2"), pilot)
    assert enc.column("n_superseded_whole").to_pylist() == [6]
    const, _, _ = simulate(_one_encounter(), b2, parse_delay_spec("const:2"), parse_delay_spec("const:2"), pilot)
    assert const.column("n_superseded_whole").to_pylist() == [0]


def test_received_equals_its_fates_under_the_paper_counting(tmp_path):
    """Under paper every fresh released command lands in one execution column (executed as sent,
    blended, overridden), itself or with the newer command it was released with."""
    from daa_sil.study.campaign.run import run_campaign
    from daa_sil.study.campaign.config import CampaignConfig
    from daa_sil.study.campaign.files import read_results

    run_campaign(CampaignConfig(groups=("B-2", "ID-2"), n_encounters=16, seed=3), tmp_path / "c", progress=False)
    for g in ("B-2", "ID-2"):
        t = read_results(tmp_path / "c", "encounters", [g])
        c = {k: np.asarray(t.column(k).to_numpy(), np.int64) for k in t.column_names if k.startswith("n_")}
        arrived = c["n_pilot_received_whole"] + c["n_superseded_whole"]
        fates = (c["n_pilot_exec_whole"] + c["n_blend"] + c["n_daa_override"] + c["n_superseded_exec_whole"]
                 + c["n_superseded_blend"] + c["n_superseded_override"])
        assert np.array_equal(arrived, fates), g
        assert c["n_superseded_whole"].sum() > 0  # the Gaussian delay's drops make bursts


def test_a_delay_drawn_once_per_encounter_is_the_first_epoch_of_the_same_stream():
    from daa_sil.study.campaign.run import simulate_group
    from daa_sil.study.campaign.config import CampaignConfig

    encs = _one_encounter()
    seeds = np.asarray(encs.seed, np.int64)
    logs = {}
    for r in ("paper", "paper-delay-per-encounter"):
        cfg = CampaignConfig(groups=("B-2",), n_encounters=1, seed=11, reading=r)
        logs[r] = np.asarray(simulate_group(cfg, "B-2", encs, seeds, record_steps=True)[2].column("delay_up_s"))
    per_enc, per_epoch = logs["paper-delay-per-encounter"], logs["paper"]
    assert np.all(per_enc == per_enc[0]) and per_enc[0] == per_epoch[0]
    assert np.unique(per_epoch).size > 1  # redrawn every 10 s: time varying


def test_resume_refuses_a_reading_whose_settings_changed(tmp_path):
    import json

    from daa_sil.study.campaign.run import run_campaign
    from daa_sil.study.campaign.config import CampaignConfig

    cfg = CampaignConfig(groups=("B-2",), n_encounters=4, seed=3)
    run_campaign(cfg, tmp_path / "c", progress=False)
    meta_path = tmp_path / "c" / "campaign.json"
    meta = json.loads(meta_path.read_text())
    meta["config"]["readings"]["outside"] = "clamp"  # as a campaign made before the setting changed
    meta_path.write_text(json.dumps(meta))
    with pytest.raises(UsageError, match=r"reading 'paper' has other settings .*\(outside\)"):
        run_campaign(cfg, tmp_path / "c", progress=False, resume=True)


def test_the_step_log_names_every_provenance_code():
    from daa_sil import steplog
    from daa_sil.agent.decision import DECIDED_BY_NAMES

    assert steplog.DECIDED_BY == DECIDED_BY_NAMES  # 'kept' (the extension) is written, not refused
