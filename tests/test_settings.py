"""Each shared default and range is defined once (``daa_sil/config/settings.py``, docs/configuration.md).

The defaults are written here by hand (the paper's and the SIL's numbers); every consumer must hold
exactly them, and its dataclass field must name the setting it took them from, so a literal
written back into a field fails here. The ranges are probed through each input: the largest value
is accepted, one just above it refused.
"""

from __future__ import annotations

from dataclasses import fields
from pathlib import Path

import pytest
import yaml

from daa_sil.config import settings as S
from daa_sil.errors import FileFormatError, UsageError

ROOT = Path(__file__).resolve().parents[1]


def field_setting(cls, name: str):
    return {f.name: f for f in fields(cls)}[name].metadata.get("setting")


def test_the_defaults_every_consumer_holds():
    from daa_sil.config.groups import GroupSpec, group_spec
    from daa_sil.config.policy import AllocationPolicy
    from daa_sil.config.run_config import RunConfig
    from daa_sil.geometry.thresholds import DEFAULT_PRESET
    from daa_sil.models.encounters import EncounterConfig
    from daa_sil.models.latency import DEFAULT_EPOCH_S
    from daa_sil.sil.scenario.schema import AllocationSpec, LinkSpec, Scenario
    from daa_sil.study.campaign.config import CampaignConfig
    from daa_sil.waitmap.source import DEFAULT_MAP

    pol = AllocationPolicy("map")
    assert (pol.wait_threshold_s, pol.projl_horizon_s, pol.constant_wait_s, pol.stale_command_s,
            pol.link_timeout_s) == (4.0, 25.0, 5.0, 15.0, 20.0)
    g = GroupSpec.from_dict("x", {"setup": "setup", "latency": {"type": "constant", "seconds": 4}, "wait": "map"})
    assert (g.allocation.wait_threshold_s, g.allocation.projl_horizon_s) == (4.0, 25.0)
    al = AllocationSpec()  # a scenario gives no per-group setting unless it names one: its group's hold
    assert (al.group, al.settings.given()) == ("ID-1", {})
    assert (group_spec("ID-1").allocation.wait_threshold_s, group_spec("IC-1").allocation.constant_wait_s) == (4.0, 5.0)
    assert (LinkSpec().up, LinkSpec().epoch_s, DEFAULT_EPOCH_S) == ("const:4", 10.0, 10.0)
    sc_fields = {f.name: f.default for f in fields(Scenario)}
    assert (sc_fields["duration_s"], sc_fields["thresholds"]) == (240.0, "do365")
    cc, rc = CampaignConfig(), RunConfig()
    assert (cc.duration_s, cc.preset, cc.n_encounters, cc.seed, cc.n_intruders, cc.chunk_size, cc.waitmap) == (
        240.0, "paper", 10_000, 0, 1, 2000, "alerting")
    assert dict(rc.study) == {"encounters": 10_000, "seed": 0, "duration_s": 240.0, "intruders": 1, "chunk_size": 2000}
    assert (rc.thresholds, rc.waitmap["source"], DEFAULT_PRESET, DEFAULT_MAP) == ("paper", "alerting", "paper", "alerting")
    assert (EncounterConfig().duration_s, EncounterConfig().preset) == (240.0, "do365")


def test_the_fields_name_their_setting():
    from daa_sil.config.overrides import setting_for_key
    from daa_sil.config.policy import AllocationPolicy
    from daa_sil.config.sections import StudySection, WaitmapSection
    from daa_sil.sil.scenario.schema import LinkSpec, Scenario

    expected = [
        (AllocationPolicy, "wait_threshold_s", S.WAIT_THRESHOLD), (AllocationPolicy, "projl_horizon_s", S.PROJL_HORIZON),
        (AllocationPolicy, "constant_wait_s", S.CONSTANT_WAIT), (AllocationPolicy, "stale_command_s", S.STALE_COMMAND),
        (AllocationPolicy, "link_timeout_s", S.LINK_TIMEOUT),
        (LinkSpec, "epoch_s", S.DELAY_EPOCH), (Scenario, "duration_s", S.DURATION),
        (StudySection, "duration_s", S.DURATION),
        (StudySection, "encounters", S.ENCOUNTERS), (WaitmapSection, "gamma", S.GAMMA),
    ]
    wrong = [(cls.__name__, name) for cls, name, setting in expected if field_setting(cls, name) is not setting]
    assert not wrong, wrong
    # the per-group settings of a group file, a run configuration and a scenario are read by the setting
    # itself: each key (its name, an old one) names exactly one setting
    keys = {"wait_threshold_s": S.WAIT_THRESHOLD, "wt": S.WAIT_THRESHOLD, "projl_horizon_s": S.PROJL_HORIZON,
            "projl_lookahead": S.PROJL_HORIZON, "constant_wait_s": S.CONSTANT_WAIT, "wait_constant_s": S.CONSTANT_WAIT,
            "stale_command_s": S.STALE_COMMAND, "link_timeout_s": S.LINK_TIMEOUT}
    assert {k: setting_for_key(k) for k in keys} == keys


@pytest.mark.parametrize("key, setting", [("projl_lookahead", S.PROJL_HORIZON), ("wt", S.WAIT_THRESHOLD),
                                          ("projl_horizon_s", S.PROJL_HORIZON), ("wait_threshold_s", S.WAIT_THRESHOLD)])
def test_a_run_configuration_and_a_campaign_check_the_same_range(key, setting):
    from daa_sil.config.overrides import Overrides
    from daa_sil.config.run_config import config_from_dict
    from daa_sil.study.campaign.config import CampaignConfig

    assert config_from_dict({"allocation": {key: 120}}, "c.yaml").allocation[key] == 120
    with pytest.raises(UsageError, match=rf"c.yaml: allocation.{key} must be a number within \[0, 120\], got 121"):
        config_from_dict({"allocation": {key: 121}}, "c.yaml")
    assert CampaignConfig(settings=Overrides.of_values({setting: 120.0})).validate().policy("ID-2") \
        .__getattribute__(setting.name) == 120.0
    with pytest.raises(UsageError, match="within \\[0, 120\\]"):
        CampaignConfig(settings=Overrides.of_values({setting: 121.0})).validate()
    with pytest.raises(UsageError, match="within \\[0, 120\\]"):  # a settings object built around the check
        CampaignConfig(settings=Overrides(((setting.name, 121.0),))).validate()


@pytest.mark.parametrize("key", ["link_timeout_s", "stale_command_s"])
def test_the_link_timeouts_have_one_range(tmp_path, key):
    """[1, 120] s for a run configuration, a scenario and the vehicle's parameter."""
    from daa_sil.config.policy import AllocationPolicy
    from daa_sil.config.run_config import config_from_dict
    from daa_sil.sil.scenario import load_scenario
    from vehicle.params import ParamTable

    for ok in (1, 120):
        assert config_from_dict({"link": {key: ok}}, "c.yaml").link[key] == ok
    for bad in (0.5, 121):
        with pytest.raises(UsageError, match=rf"link.{key} must be a number within \[1, 120\]"):
            config_from_dict({"link": {key: bad}}, "c.yaml")
    d = yaml.safe_load((ROOT / "scenarios" / "head_on.yaml").read_text())
    for value, good in ((1, True), (120, True), (0.5, False), (121, False)):
        d["allocation"][key] = value
        f = tmp_path / f"{key}-{value}.yaml"
        f.write_text(yaml.safe_dump(d))
        if good:
            assert load_scenario(f).allocation.settings.of(getattr(S, {"link_timeout_s": "LINK_TIMEOUT",
                                                                       "stale_command_s": "STALE_COMMAND"}[key])) == value
        else:
            with pytest.raises(FileFormatError, match=rf"allocation.{key}: must be within \[1, 120\], got {value:g}"):
                load_scenario(f)
    name = {"link_timeout_s": "DAA_LINK_TO", "stale_command_s": "DAA_STALE_S"}[key]
    table, pol = ParamTable("paper"), AllocationPolicy("map")
    assert [table.set(name, v, pol).status for v in (0.5, 1.0, 120.0, 121.0)] == [
        "out_of_range", "accepted", "accepted", "out_of_range"]


def test_a_setting_checks_counts_and_numbers():
    assert S.SEED.check(7, "f.yaml") == 7 and isinstance(S.SEED.check(7.0, "f.yaml"), int)
    with pytest.raises(UsageError, match=r"f.yaml: study.seed must be an integer within"):
        S.SEED.check(1.5, "f.yaml", "study.seed")
    for bad in (True, float("nan"), "4", -0.1, 120.5):
        assert not S.WAIT_THRESHOLD.contains(bad)
    assert S.WAIT_THRESHOLD.flag_help("W_T") == "W_T, s within [0, 120] (default 4.0)"


def test_an_integer_too_large_for_a_float_is_out_of_range_not_a_crash():
    from daa_sil.config.settings import SEED, WAIT_THRESHOLD

    for setting in (WAIT_THRESHOLD, SEED):
        assert not setting.contains(10 ** 400)
        with pytest.raises(UsageError, match="within"):
            setting.check(10 ** 400, "f.yaml")


def test_a_campaign_reads_the_duration_range():
    from daa_sil.study.campaign.config import CampaignConfig

    for bad in (0.5, 1e6, float("nan")):
        with pytest.raises(UsageError, match="duration"):
            CampaignConfig(duration_s=bad).validate()
    CampaignConfig(duration_s=1.0).validate()


def test_a_scenario_sets_projl_n_as_it_sets_w_t(tmp_path, capsys):
    """ProjL's N is a per-group setting like W_T: a scenario sets it (by its name, or the old key with
    a notice); a run configuration's value holds where the scenario gives none, a flag's over both."""
    from daa_sil.config.overrides import Overrides
    from daa_sil.config.run_config import config_from_dict
    from daa_sil.sil.scenario import load_scenario
    from vehicle.core import resolve_policy

    d = yaml.safe_load((ROOT / "scenarios" / "head_on.yaml").read_text())
    d["allocation"].update(projl_horizon_s=15, wait_threshold_s=6)
    f = tmp_path / "n.yaml"
    f.write_text(yaml.safe_dump(d))
    sc = load_scenario(f)
    pol = resolve_policy(sc)
    assert (pol.projl_horizon_s, pol.wait_threshold_s) == (15.0, 6.0)
    config = config_from_dict({"allocation": {"projl_horizon_s": 30, "wait_threshold_s": 8}, "link": {"link_timeout_s": 9}})
    pol = resolve_policy(sc, config=config)
    assert (pol.projl_horizon_s, pol.wait_threshold_s, pol.link_timeout_s) == (15.0, 6.0, 9.0)
    pol = resolve_policy(sc, config=config, flags=Overrides.of_values({S.PROJL_HORIZON: 20.0}))
    assert (pol.projl_horizon_s, pol.wait_threshold_s) == (20.0, 6.0)
    del d["allocation"]["projl_horizon_s"]
    d["allocation"]["projl_lookahead"] = 12
    f.write_text(yaml.safe_dump(d))
    capsys.readouterr()
    assert resolve_policy(load_scenario(f)).projl_horizon_s == 12.0
    assert "allocation.projl_lookahead is now called allocation.projl_horizon_s" in capsys.readouterr().err
    d["allocation"]["projl_lookahead"] = 121
    f.write_text(yaml.safe_dump(d))
    with pytest.raises(FileFormatError, match=r"allocation.projl_lookahead: must be within \[0, 120\], got 121"):
        load_scenario(f)


def test_the_legacy_reading_of_an_old_campaign_file():
    """A campaign.json that records no reading was flown before readings were recorded: under the
    simulator's first reading, ``extended`` (not today's default)."""
    from daa_sil.config.readings import DEFAULT_READING, LEGACY_READING, READINGS
    from daa_sil.study.campaign.config import CampaignConfig

    assert LEGACY_READING == "extended" and LEGACY_READING in READINGS and DEFAULT_READING == "paper"
    d = CampaignConfig(groups=("B-2",), n_encounters=3).to_dict()
    del d["reading"]
    assert CampaignConfig.from_dict(d).reading == LEGACY_READING
    d["reading"] = "paper"
    assert CampaignConfig.from_dict(d).reading == "paper"
