"""Named readings of the paper's simulator: what each changes, recorded and checked on --resume."""

import json

import numpy as np
import pytest

from daa_sil.study.campaign.run import run_campaign
from daa_sil.study.campaign.config import CampaignConfig
from daa_sil.study.campaign.files import read_results
from daa_sil.cli import main
from daa_sil.errors import UsageError
from daa_sil.config.readings import READINGS, canonical_name, parse_reading_settings, reading_for
from daa_sil.geometry.units import FT


def test_bundles_and_what_they_change():
    ext = reading_for("extended")
    assert ext.encounter_overrides() == {} and ext.simulation_key() == (
        "metres", "corrective", None, "alert", True, "blend", None, "clamp", "one-way", None, "corrective")
    p = ext.pilot_config()
    assert (p.alert_level_min, p.stream_level_min, p.stream_hold, p.stream_until) == (2, None, True, "alert")
    feet = reading_for("feet")
    assert feet.encounter_overrides() == {"hmd_max_m": pytest.approx(838.2), "vmd_max_m": pytest.approx(278.892)}
    assert feet.pilot_config().alert_level_min == 1 and (feet.window, feet.received) == ("whole", "pilot+blend")
    # feet and preventive differ in the unit alone (the unit's effect, separated from the pilot start)
    assert {k for k, v in feet.to_dict().items() if v != reading_for("preventive").to_dict()[k]} == {
        "name", "units", "description"}
    assert reading_for("detection").pilot_config().stream_level_min == 0
    assert reading_for("no-hold").pilot_config().stream_hold is False
    # counting-only readings share the extended simulation
    assert reading_for("paper-counts").simulation_key() == ext.simulation_key()
    assert set(READINGS) >= {"paper", "extended", "paper-counts", "feet", "preventive", "detection", "no-hold",
                             "paper-grid"}
    with pytest.raises(UsageError, match="unknown reading 'x'"):
        reading_for("x")
    with pytest.raises(UsageError, match="units must be one of metres, feet"):
        reading_for("extended", units="yards")
    assert parse_reading_settings("units=feet, hold_commands=false") == {"units": "feet", "hold_commands": False}
    with pytest.raises(UsageError, match="KEY=VALUE"):
        parse_reading_settings("colour=blue")


def test_the_paper_reading_and_its_alternatives():
    p = reading_for("paper")
    assert (p.waitmap, p.wait_horizon_s, p.outside, p.latency, p.pilot_start, p.pilot_stop, p.hold_commands,
            p.unsafe_hold) == ("paper", 40.0, "approach", "round-trip", "detection", "safe-avoidance", True, "blend")
    assert (p.window, p.received, p.blends, p.superseded, p.units, p.wait_rule, p.agent_active, p.delay_draw,
            p.daa_authority) == ("whole", "pilot+blend", "all", "fate", "metres", None, "encounter", "epoch",
                                 "per-step")
    pc = p.pilot_config()
    assert (pc.stream_level_min, pc.alert_level_min, pc.stream_until) == (0, 2, "safe-avoidance")
    assert p.policy_overrides() == {"active_from": "encounter"}
    assert p.epoch_s(10.0, 240.0, 1.0) == 10.0
    assert reading_for("paper-delay-per-encounter").epoch_s(10.0, 240.0, 1.0) == 242.0
    assert reading_for("paper-keep-daa").policy_overrides() == {"active_from": "encounter",
                                                                "daa_authority": "until-clear"}
    # each alternative changes exactly the setting it is named for
    alt = {"paper-outside-far": {"outside"}, "paper-clamp": {"outside"}, "paper-hold-none": {"unsafe_hold"},
           "paper-h60": {"wait_horizon_s"}, "paper-one-per-step": {"superseded"},
           "paper-delay-per-encounter": {"delay_draw"}, "paper-keep-daa": {"daa_authority"},
           "paper-one-way": {"latency"}, "paper-countdown": {"wait_rule"},
           "paper-hold-blend": {"blends"}, "paper-no-hold": {"hold_commands"},
           "paper-preventive": {"pilot_engage"}, "paper-alerting": {"waitmap", "wait_horizon_s"},
           "paper-feet": {"units"}, "paper-corrective": {"agent_active"},
           "paper-contradicted": {"outside", "unsafe_hold", "wait_horizon_s", "superseded"}}
    for name, keys in alt.items():
        d = reading_for(name).to_dict()
        assert {k for k, v in d.items() if v != p.to_dict()[k]} - {"name", "description"} == keys, name
    # the readings that keep an older behaviour keep their simulation key, so their results are the old ones
    assert reading_for("paper-contradicted").simulation_key() == (
        "metres", "detection", None, "safe-avoidance", True, "no-command", "paper", "clamp", "round-trip", None,
        "encounter")
    assert reading_for("paper-hold-blend").simulation_key() == p.simulation_key()  # counting only
    assert reading_for("paper-one-per-step").simulation_key() == p.simulation_key()


def test_old_names_are_accepted_with_a_notice_and_mean_the_same_reading(capsys):
    assert reading_for("literal") is READINGS["extended"]
    assert canonical_name("literal") == ("extended", "reading 'literal' is now called 'extended' (same settings, "
                                                     "same results)")
    assert CampaignConfig(groups=("B-2",), reading="literal").reading == "extended"
    # campaign.json of an old campaign (no 'reading' key was written before readings existed) -> extended
    assert CampaignConfig.from_dict({**CampaignConfig(groups=("B-2",)).to_dict(), "reading": "literal"}).reading == \
        "extended"
    assert CampaignConfig().reading == "paper"  # the default


def test_campaign_defaults_to_the_paper_reading_and_records_it(tmp_path, capsys):
    """daa-sil campaign run --groups B-2,ID-2 --encounters N --out D runs the paper's method and says so."""
    out = tmp_path / "D"
    assert main(["campaign", "run", "--groups", "B-2,ID-2", "--encounters", "12", "--seed", "5", "--out", str(out),
                 "--no-progress"]) == 0
    meta = json.loads((out / "campaign.json").read_text())
    r = meta["config"]["readings"]
    assert meta["config"]["reading"] == "paper"
    assert (r["waitmap"], r["latency"], r["pilot_start"], r["pilot_stop"]) == (
        "paper", "round-trip", "detection", "safe-avoidance")
    assert (r["window"], r["received"], r["unsafe_hold"], r["outside"], r["superseded"]) == (
        "whole", "pilot+blend", "blend", "approach", "fate")
    assert meta["waitmap"]["source"] == "paper" and meta["waitmap"]["params"]["horizon"] == 40.0
    assert meta["resolved_config"]["pilot"]["stream_until"] == "safe-avoidance"
    assert meta["resolved_config"]["policies"]["ID-2"]["unsafe_hold"] == "blend"
    assert meta["resolved_config"]["policies"]["B-2"]["active_from"] == "encounter"
    # the basis of every setting, machine-readable: the one definition the study page prints
    from daa_sil.config.basis import PAPER_BASIS

    basis = meta["basis"]
    assert [b["setting"] for b in basis] == [b.setting for b in PAPER_BASIS]
    assert not any(b["differs"] for b in basis)
    assert {b["kind"] for b in basis} == {"text", "inference", "choice"}
    outside = next(b for b in basis if b["keys"] == ["outside"])
    assert outside["kind"] == "inference" and "relative X distance reduces" in outside["quote"]
    assert "reading paper" in capsys.readouterr().err
    # the encounter sampler checked start states with the run's preset, not EncounterConfig's do365 default
    from daa_sil.models.encounter_files import load_encounters

    assert load_encounters(out / "encounters.parquet").config["preset"] == meta["config"]["preset"] == "paper"
    # the old name: a one-line notice, the extended reading recorded
    out2 = tmp_path / "E"
    assert main(["campaign", "run", "--groups", "B-2", "--encounters", "4", "--out", str(out2), "--reading", "literal",
                 "--no-progress"]) == 0
    err = capsys.readouterr().err
    assert "reading 'literal' is now called 'extended'" in err
    assert json.loads((out2 / "campaign.json").read_text())["config"]["reading"] == "extended"


def test_waitmap_under_a_reading_with_its_own_grid_sets_the_readings_grid(tmp_path):
    from daa_sil.commands.campaign import _waitmap_into_reading

    f = _waitmap_into_reading({"reading": "paper", "reading_set": {}, "waitmap": "fine"}, "fine")
    assert f["reading_set"] == {"waitmap": "fine"} and f["waitmap"] == "alerting"
    assert CampaignConfig(groups=("ID-2",), reading="paper", reading_set={"waitmap": "fine"}).map_source == "fine"
    f = _waitmap_into_reading({"reading": "extended", "reading_set": {}, "waitmap": "fine"}, "fine")
    assert f["waitmap"] == "fine" and f["reading_set"] == {}
    with pytest.raises(UsageError, match="--reading-set waitmap=fine"):
        CampaignConfig(groups=("ID-2",), reading="paper", waitmap="fine").validate()


def test_feet_reading_draws_cpas_inside_dmod_and_is_recorded(tmp_path):
    cfg = CampaignConfig(groups=("B-2",), n_encounters=40, seed=3, chunk_size=40, duration_s=240.0, reading="feet")
    run_campaign(cfg, tmp_path / "c", progress=False)
    meta = json.loads((tmp_path / "c" / "campaign.json").read_text())
    assert meta["config"]["reading"] == "feet" and meta["config"]["readings"]["units"] == "feet"
    from daa_sil.models.encounter_files import load_encounters

    es = load_encounters(tmp_path / "c" / "encounters.parquet")
    hmd, vmd = es.params["hmd_m"], es.params["vmd_m"]
    assert hmd.max() <= 2750 * FT and np.abs(vmd).max() <= 915 * FT
    assert hmd.max() > 0.5 * 2750 * FT  # drawn over the whole (feet) range, not squeezed
    # --resume with another reading is refused, naming the setting
    rc = main(["campaign", "run", "--out", str(tmp_path / "c"), "--resume", "--reading", "extended", "--no-progress"])
    assert rc == 2


def test_whole_encounter_counts_and_no_hold_reading(tmp_path):
    """Whole-encounter counts contain the active-phase ones; without 'hold' fewer commands arrive."""
    base = dict(groups=("ID-2",), n_encounters=60, seed=8, chunk_size=60, duration_s=240.0)
    run_campaign(CampaignConfig(**base, reading="extended"), tmp_path / "hold", progress=False)
    run_campaign(CampaignConfig(**base, reading="no-hold"), tmp_path / "nohold", progress=False)
    a = read_results(tmp_path / "hold", "encounters")
    b = read_results(tmp_path / "nohold", "encounters")
    col = lambda t, k: np.asarray(t.column(k).to_numpy())  # noqa: E731
    assert np.all(col(a, "n_pilot_received_whole") >= col(a, "n_pilot_exec") + col(a, "n_blend") + col(a, "n_daa_override"))
    assert np.all(col(a, "n_pilot_exec_whole") >= col(a, "n_pilot_exec"))
    assert np.all(col(a, "n_pilot_exec_whole") <= col(a, "n_pilot_received_whole"))
    assert col(a, "n_pilot_received_whole").sum() > col(a, "n_pilot_received").sum()  # arrivals outside the phase
    assert col(b, "n_pilot_received_whole").sum() < col(a, "n_pilot_received_whole").sum()


def test_ic1_wait_time_under_both_rules(tmp_path):
    """IC-1's "wait time 5 s": under the threshold rule any constant >= W_T (4 s) gives identical runs;
    under the countdown rule (reading paper-countdown) 5 s and 50 s differ."""
    from dataclasses import replace

    from daa_sil.config.groups import group_spec

    ic1 = group_spec("IC-1")
    ic = (ic1, ic1.with_(name="IC-1-w50", allocation=replace(ic1.allocation, constant_wait_s=50.0)))
    res = {}
    for rule in ("extended", "countdown"):
        cfg = CampaignConfig(groups=ic, n_encounters=40, seed=3, chunk_size=40, reading="extended",
                             reading_set={} if rule == "extended" else {"wait_rule": "countdown"})
        run_campaign(cfg, tmp_path / rule, progress=False)
        t = read_results(tmp_path / rule, "encounters")
        g = np.asarray(t.column("group").to_pylist())
        cols = ("n_wait", "n_no_wait", "n_blend", "n_pilot_exec", "lowc_duration_s", "dev_h_m")
        res[rule] = {name: np.stack([np.asarray(t.column(c).to_numpy())[g == name] for c in cols])
                     for name in ("IC-1", "IC-1-w50")}
        assert res[rule]["IC-1"][0].sum() > 0  # IC-1 waits
    assert np.array_equal(res["extended"]["IC-1"], res["extended"]["IC-1-w50"])
    assert not np.array_equal(res["countdown"]["IC-1"], res["countdown"]["IC-1-w50"])
    assert res["countdown"]["IC-1"][0].sum() < res["countdown"]["IC-1-w50"][0].sum()  # the 5 s budget runs out
