"""The group table (paper Table 2 + ablations) as data, group files and campaign overrides."""

import pytest

from daa_sil.config.overrides import Overrides
from daa_sil.config.settings import LINK_TIMEOUT, PROJL_HORIZON, STALE_COMMAND, WAIT_THRESHOLD
from daa_sil.study.campaign.config import CampaignConfig
from daa_sil.errors import UsageError
from daa_sil.config.groups import PAPER_GROUPS, group_spec, group_table, load_group_file, parse_groups, policy_for_group


def test_table_holds_the_papers_groups_and_the_ablations():
    t = group_table()
    assert list(t)[:5] == list(PAPER_GROUPS) == ["B-1", "B-2", "IC-1", "ID-1", "ID-2"]
    assert {"ID-2-projl", "ID-2-map"} <= set(t)
    # paper Table 2: latency type / value and wait
    assert t["B-1"].delay_model().mean() == 4.0 and t["ID-1"].delay_model().mean() == 4.0
    assert t["IC-1"].delay_model().mean() == 5.0
    assert t["B-2"].delay_model().kind == t["ID-2"].delay_model().kind == "gaussian"
    assert [t[g].wait_mode for g in PAPER_GROUPS] == ["none", "none", "constant", "map", "map"]
    assert t["IC-1"].policy().constant_wait_s == 5.0
    assert not t["B-1"].policy().blending and not t["B-2"].policy().blending and t["ID-2"].policy().blending
    # the ablations fly ID-2's link and differ only in the wait function / ProjL veto
    for name, mode, projl in (("ID-2-projl", "always", True), ("ID-2-map", "map", False)):
        pol = t[name].policy()
        assert (pol.wait_mode, pol.projl, pol.name) == (mode, projl, name)
        assert t[name].latency == t["ID-2"].latency
    assert all(t[g].policy().projl for g in PAPER_GROUPS)


def test_parse_names_and_errors():
    assert [g.name for g in parse_groups("id-2, B-1")] == ["ID-2", "B-1"]
    assert [g.name for g in parse_groups(None)] == list(PAPER_GROUPS)
    with pytest.raises(UsageError, match="unknown group 'X'"):
        parse_groups("B-1,X")
    with pytest.raises(UsageError, match="given twice"):
        parse_groups("B-1,b-1")


def test_group_file_with_base_and_overrides(tmp_path):
    f = tmp_path / "g.yaml"
    f.write_text("slow-wt:\n  base: ID-2\n  wait_threshold_s: 8\n  latency: {type: constant, seconds: 2}\n"
                 "mine:\n  setup: integrated\n  latency: {type: constant, seconds: 1}\n  wait: 3\n")
    a, b = parse_groups(str(f))
    assert (a.name, a.wait_mode, a.policy().wait_threshold_s, a.delay_model().mean()) == ("slow-wt", "map", 8.0, 2.0)
    assert a.policy().blending and a.policy().projl  # inherited from ID-2
    assert (b.wait_mode, b.policy().constant_wait_s) == ("constant", 3.0)


@pytest.mark.parametrize("body, message", [
    ("g:\n  base: ID-2\n  wiat: map\n", "unknown field 'wiat'"),
    ("g:\n  base: ID-2\n  wait: sometimes\n", "wait must be none, map, always or a number"),
    ("g:\n  base: ID-2\n  projl: 3\n", "projl must be true or false"),
    ("g:\n  base: ID-2\n  latency: {type: constant}\n", "missing seconds"),
    ("g:\n  base: ID-9\n", "unknown group 'ID-9'"),
    ("'a b':\n  base: ID-2\n", "bad group name 'a b'"),
    ("[1, 2]\n", "expected a mapping"),
])
def test_bad_group_file_is_one_line(tmp_path, body, message):
    f = tmp_path / "bad.yaml"
    f.write_text(body)
    with pytest.raises(UsageError, match=message) as ei:
        load_group_file(f)
    assert "\n" not in str(ei.value)


def test_campaign_overrides_apply_to_the_right_groups():
    cfg = CampaignConfig(groups=("B-2", "IC-1", "ID-2", "ID-2-projl"), latency="const:0.5",
                         settings=Overrides.of_values({WAIT_THRESHOLD: 7.0, PROJL_HORIZON: 12.0})).validate()
    eff = {g.name: g.policy() for g in cfg.effective_groups}
    assert eff["B-2"].wait_threshold_s == 4.0  # no wait function: W_T does not apply
    assert all(eff[g].wait_threshold_s == 7.0 for g in ("IC-1", "ID-2", "ID-2-projl"))
    assert all(p.projl_horizon_s == 12.0 for p in eff.values())
    assert all(g.delay_model().mean() == 0.5 for g in cfg.effective_groups)
    # the definitions as given stay as they were (campaign.json records both)
    assert {g.name: g.policy().wait_threshold_s for g in cfg.groups}["ID-2"] == 4.0
    assert CampaignConfig.from_dict(cfg.to_dict()) == cfg


def test_one_override_rule_for_fast_time_and_the_vehicle():
    """``group_policy`` is the rule both routes use: W_T only where a group waits, N everywhere,
    the reading's wait rule where a group waits; the flown policy matches the recorded group."""
    from daa_sil.config.overrides import group_policy

    cfg = CampaignConfig(groups="B-2,IC-1,ID-2", reading_set={"wait_rule": "countdown"},
                         settings=Overrides.of_values({WAIT_THRESHOLD: 7.0, PROJL_HORIZON: 12.0, LINK_TIMEOUT: 9.0}))
    want = {"B-2": (4.0, "threshold"), "IC-1": (7.0, "countdown"), "ID-2": (7.0, "countdown")}
    for name, (wt, rule) in want.items():
        pol = cfg.policy(name)
        assert (pol.wait_threshold_s, pol.projl_horizon_s, pol.wait_rule, pol.link_timeout_s) == (wt, 12.0, rule, 9.0)
        rec = cfg.group(name).policy()  # what campaign.json records
        assert (rec.wait_threshold_s, rec.projl_horizon_s, rec.wait_rule) == (wt, 12.0, rule)
    # the vehicle's route: a policy, not a group definition, through the same function
    b2 = group_policy(policy_for_group("B-2"), flags=Overrides.of_values(
        {WAIT_THRESHOLD: 7.0, PROJL_HORIZON: 12.0, STALE_COMMAND: 3.0}))
    assert (b2.wait_threshold_s, b2.projl_horizon_s, b2.stale_command_s) == (4.0, 12.0, 3.0)
    assert group_policy(policy_for_group("ID-2")) == policy_for_group("ID-2")  # nothing given: unchanged
