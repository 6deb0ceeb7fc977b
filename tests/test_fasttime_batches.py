"""Fast-time batches: several groups and chunks in one batch give each part exactly the results it has
alone; the DAA is called once a step on all the rows of the batch that need it (each row gets what it
gets alone: tests/test_batch_invariance.py); the display bands the states it shows; the lean step and
the slot rings change nothing."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import daa_sil.agent.step as agent_mod
import daa_sil.study.simulation.fasttime as ft
from daa_sil.config.groups import policy_for_group
from daa_sil.config.groups import group_spec
from daa_sil.daa import DaaConfig, compute_bands
from daa_sil.daa.config import AXIS_HORIZONTAL, AXIS_VERTICAL
from daa_sil.geometry.kinematics import AircraftState
from daa_sil.models.encounters import sample_encounters
from daa_sil.models.latency import Constant, TruncatedGaussian
from daa_sil.study.campaign.compare import compare_tables
from daa_sil.study.simulation.fasttime import SimPart, simulate, simulate_parts

N = 30


def _assert_tables_equal(a, b):
    assert a.schema.equals(b.schema)
    diffs = compare_tables("t", a, b)  # bit for bit, NaN == NaN, lists element-wise
    assert not diffs, diffs


@pytest.fixture(scope="module")
def encs():
    return sample_encounters(2 * N, seed=21, preset="paper")


@pytest.fixture(scope="module")
def family():
    from daa_sil.study.campaign.run import campaign_family
    from daa_sil.study.campaign.config import CampaignConfig

    return campaign_family(CampaignConfig(groups=("ID-2",)))


def _parts(encs):
    a, b = encs.subset(np.arange(N)), encs.subset(np.arange(N, 2 * N))
    gauss = TruncatedGaussian(5.0, 3.0)
    return [SimPart(a, policy_for_group("B-1"), Constant(4.0), Constant(4.0), group="B-1"),
            SimPart(a, policy_for_group("ID-2"), gauss, gauss, group="ID-2"),
            SimPart(b, policy_for_group("IC-1"), Constant(5.0), Constant(2.0), group="IC-1"),
            SimPart(b, policy_for_group("ID-2-projl"), gauss, Constant(4.0), group="ID-2-projl")]


def test_a_batch_of_groups_and_chunks_gives_each_part_its_own_results(encs, family):
    parts = _parts(encs)
    batched = simulate_parts(parts, wait_family=family)
    for p, (enc, dec) in zip(parts, batched):
        alone = simulate(p.encounters, p.policy, p.latency_up, p.latency_down, wait_family=family, group=p.group)
        _assert_tables_equal(enc, alone[0])
        _assert_tables_equal(dec, alone[1])
        assert dec.num_rows > 0  # the agent was active in every part


def test_the_daa_is_called_once_a_step_on_the_rows_of_every_part(encs, family, monkeypatch):
    # record the rows (as ownship x positions) of every bands / SM call, alone and batched: the batch makes
    # one call where the parts alone make one each, on the union of their rows
    calls: list = []
    real_bands, real_sm = agent_mod.compute_bands, agent_mod.safety_metric

    def bands(own, intr, *a, **k):
        calls.append(("bands", tuple(own.x)))
        return real_bands(own, intr, *a, **k)

    def sm(own, intr, cmd, *a, **k):
        calls.append(("sm", tuple(own.x), tuple(cmd.trk)))
        return real_sm(own, intr, cmd, *a, **k)

    monkeypatch.setattr(agent_mod, "compute_bands", bands)
    monkeypatch.setattr(agent_mod, "safety_metric", sm)
    parts = _parts(encs)[:2]  # two groups of the same chunk: the same ownship positions until they act
    simulate_parts(parts, wait_family=family, duration_s=150.0)
    batched = list(calls)
    calls.clear()
    for p in parts:
        simulate(p.encounters, p.policy, p.latency_up, p.latency_down, wait_family=family, duration_s=150.0)
    alone = list(calls)
    bands_b = [c for c in batched if c[0] == "bands"]
    bands_a = [c for c in alone if c[0] == "bands"]
    assert len(bands_b) <= 150 < len(bands_a)  # at most one call a step, fewer than the parts alone make
    # every row the parts alone banded is banded in the batch (as a multiset of ownship positions)
    assert sorted(x for c in bands_b for x in c[1]) == sorted(x for c in bands_a for x in c[1])
    assert min(len(c[1]) for c in batched + alone) > 0  # nothing is computed for an empty set of rows


def test_display_bands_every_state_it_shows_in_one_call(encs, monkeypatch):
    # every pilot that sees new telemetry this step with an alert at or above alert_level_min, one call for
    # the whole batch
    import daa_sil.models.pilot_display as pd

    expected, banded = [], []
    real_refresh, real_bands = pd.PilotDisplay.refresh, pd.display_bands

    def refresh(self, rows, own, intr, alert, *a, **k):
        gated = np.flatnonzero(np.asarray(alert) >= self.alert_level_min)
        if gated.size:
            expected.append(own[gated].as_array().copy())  # the states this call must band, in order
        return real_refresh(self, rows, own, intr, alert, *a, **k)

    def bands(own, intr, cfg):
        banded.append(own.as_array().copy())
        return real_bands(own, intr, cfg)

    monkeypatch.setattr(pd.PilotDisplay, "refresh", refresh)
    monkeypatch.setattr(pd, "display_bands", bands)
    lat = Constant(4.0)
    a, b = encs.subset(np.arange(N)), encs.subset(np.arange(N, 2 * N))
    parts = [SimPart(a, policy_for_group("IC-1"), lat, lat, group="IC-1"),
             SimPart(b, policy_for_group("ID-2-projl"), lat, lat, group="ID-2-projl")]
    simulate_parts(parts, duration_s=150.0)
    assert len(expected) > 10 and len(banded) == len(expected)
    for got, want in zip(banded, expected):
        assert np.array_equal(got, want)


def test_bands_of_some_axes_equal_those_of_all_axes(encs):
    from daa_sil.geometry.kinematics import advance

    own = advance(encs.own, 0.0, 0.0, 0.0, 100.0)
    intr = advance(encs.intr, 0.0, 0.0, 0.0, 100.0)
    cfg = DaaConfig.for_preset("paper")
    full = compute_bands(own, intr, cfg)
    two = compute_bands(own, intr, cfg, axes=(AXIS_VERTICAL, AXIS_HORIZONTAL))
    assert two.gs is None and two[np.arange(3)].gs is None
    for name in ("trk", "vs"):
        a, b = getattr(full, name), getattr(two, name)
        for f in ("values", "region", "t_in", "t_out", "res_lo", "res_hi", "preferred"):
            np.testing.assert_array_equal(getattr(a, f), getattr(b, f), err_msg=f"{name}.{f}")


def test_lean_step_changes_no_result(encs):
    # with a step log the core computes geometry and the band summary; without, the same results
    sub = encs.subset(np.arange(N))
    lat = Constant(4.0)
    lean = simulate(sub, policy_for_group("ID-2-projl"), lat, lat)
    full = simulate(sub, policy_for_group("ID-2-projl"), lat, lat, record_steps=True)
    _assert_tables_equal(lean[0], full[0])
    _assert_tables_equal(lean[1], full[1])


def test_fancy_indexing_a_state_gives_independent_arrays():
    s = AircraftState(np.arange(4.0), 1.0, 2.0, 3.0, 4.0, 5.0)
    sub = s[np.array([1, 3])]
    sub.x[0] = 99.0
    view = s[1:3]
    view.x[0] = 77.0
    assert s.x.tolist() == [0.0, 1.0, 2.0, 3.0] and sub.shape == (2,) and sub.x.dtype == float


def test_a_campaign_with_group_batches_resumes_and_matches(tmp_path):
    from daa_sil.study.campaign.run import run_campaign
    from daa_sil.study.campaign.compare import compare_dirs
    from daa_sil.study.campaign.config import CampaignConfig

    cfg = CampaignConfig(groups=("B-2", "IC-1", "ID-1"), n_encounters=9, seed=5, chunk_size=3, duration_s=60.0)
    one_by_one = run_campaign(cfg, tmp_path / "units", batch_rows=3, progress=False)  # one unit per task
    batched = run_campaign(cfg, tmp_path / "batched", batch_rows=1000, progress=False)
    assert one_by_one.chunks_run == batched.chunks_run == 9
    assert compare_dirs(tmp_path / "units", tmp_path / "batched").identical
    # the group's own policy with the reading's settings on top (the default reading: paper)
    assert replace(group_spec("IC-1").policy(), **cfg.effective_reading.policy_overrides()) == cfg.policy("IC-1")


def test_parts_on_the_same_encounters_share_streams_and_equal_delay_tables_only(encs, family, monkeypatch):
    """Parts that fly the same encounters make their streams once, and those with equal delay models
    (equal, not the same object) draw one table; a different model draws its own. Every part still gets
    exactly its results alone, so a wrongly shared table (or stream) fails here."""
    a = encs.subset(np.arange(N))
    parts = [SimPart(a, policy_for_group("ID-2"), TruncatedGaussian(5.0, 3.0), TruncatedGaussian(5.0, 3.0), group="ID-2"),
             SimPart(a, policy_for_group("B-2"), TruncatedGaussian(5.0, 3.0), TruncatedGaussian(5.0, 3.0), group="B-2"),
             SimPart(a, policy_for_group("ID-1"), TruncatedGaussian(6.0, 2.0), TruncatedGaussian(5.0, 3.0), group="ID-1")]
    made = []
    real = ft.BatchedDelay

    def counted(model, seeds, *args):
        made.append((model, id(seeds)))
        return real(model, seeds, *args)

    monkeypatch.setattr(ft, "BatchedDelay", counted)
    batched = simulate_parts(parts, wait_family=family)
    # uplink: (5, 3) once, (6, 2) once; downlink: (5, 3) once, all three parts on one stream list
    assert [m for m, _ in made] == [TruncatedGaussian(5.0, 3.0), TruncatedGaussian(6.0, 2.0), TruncatedGaussian(5.0, 3.0)]
    assert len({s for _, s in made}) == 2  # the uplink streams and the downlink streams, one list each
    monkeypatch.setattr(ft, "BatchedDelay", real)
    for p, (enc, dec) in zip(parts, batched):
        alone = simulate(p.encounters, p.policy, p.latency_up, p.latency_down, wait_family=family, group=p.group)
        _assert_tables_equal(enc, alone[0])
        _assert_tables_equal(dec, alone[1])


def test_a_round_trip_draws_one_table_for_both_links(encs, family, monkeypatch):
    """Under the round-trip rule both links apply half of one draw to the uplink stream: one table for the
    two directions (per equal round trip), and the part still gets its results alone."""
    from daa_sil.models.link_rule import link_legs

    a = encs.subset(np.arange(N))
    legs = link_legs(TruncatedGaussian(10.0, 4.0), "round-trip")
    part = SimPart(a, policy_for_group("ID-2"), legs.up, legs.down, group="ID-2", link_legs=legs)
    made = []
    real = ft.BatchedDelay

    def counted(model, seeds, *args):
        made.append(model)
        return real(model, seeds, *args)

    monkeypatch.setattr(ft, "BatchedDelay", counted)
    (enc, dec), = simulate_parts([part], wait_family=family)
    assert made == [legs.up]
    monkeypatch.setattr(ft, "BatchedDelay", real)
    alone = ft.simulate(a, part.policy, legs.up, legs.down, wait_family=family, group="ID-2", link_legs=legs)
    _assert_tables_equal(enc, alone[0])
    _assert_tables_equal(dec, alone[1])
    # and against the table drawn twice, the way it was (a round trip's halves are one draw)
    monkeypatch.setattr(ft, "_stream_column", lambda streams, which, made: [[x[k] for x in st]
                                                                          for st, k in zip(streams, which)])
    twice = ft.simulate(a, part.policy, legs.up, legs.down, wait_family=family, group="ID-2", link_legs=legs)
    _assert_tables_equal(enc, twice[0])
    _assert_tables_equal(dec, twice[1])


def test_campaign_results_do_not_depend_on_chunk_size_batch_rows_or_workers(tmp_path):
    """Every column of every table, bit for bit, whatever the chunking, the rows per task and the number of
    workers. On 3e5dc69 the chunk size moved sm_pilot / sm_exec here (and, through them, decisions)."""
    from daa_sil.study.campaign.run import run_campaign
    from daa_sil.study.campaign.compare import compare_dirs
    from daa_sil.study.campaign.config import CampaignConfig

    base = dict(groups=("B-1", "IC-1", "ID-2"), n_encounters=16, seed=23, duration_s=150.0)
    runs = {"whole": (dict(chunk_size=16), dict(batch_rows=1000, workers=1)),
            "chunks": (dict(chunk_size=5), dict(batch_rows=7, workers=2)),
            "ones": (dict(chunk_size=1), dict(batch_rows=1000, workers=1))}
    for name, (cfg_kw, run_kw) in runs.items():
        run_campaign(CampaignConfig(**base, **cfg_kw), tmp_path / name, progress=False, **run_kw)
    for name in ("chunks", "ones"):
        res = compare_dirs(tmp_path / "whole", tmp_path / name)
        assert res.identical and res.columns > 100, (name, res.differences)


def test_viz_replay_gives_the_campaigns_rows_bit_for_bit(tmp_path):
    """``daa-sil viz replay`` re-simulates one encounter alone: its encounter row and its decisions (the
    step log's active steps) are the campaign's, where the encounter shared every DAA call with 15 others.
    On 3e5dc69 sm_pilot / sm_exec of the replay differed from the campaign's (checked)."""
    import pyarrow.compute as pc

    from daa_sil.commands.viz import replay_steplog
    from daa_sil.study.campaign import run as campaign
    from daa_sil.study.campaign import files as campaign_files

    cfg = campaign.CampaignConfig(groups=("IC-1",), n_encounters=16, seed=23, chunk_size=16, duration_s=150.0)
    campaign.run_campaign(cfg, tmp_path / "camp", workers=1, progress=False)
    enc = campaign_files.read_results(tmp_path / "camp", "encounters", groups=["IC-1"])
    dec = campaign_files.read_results(tmp_path / "camp", "decisions", groups=["IC-1"])
    cols = ("t", "decision", "rule", "wait_s", "projl", "sm_pilot", "sm_exec", "pilot_axis", "pilot_dir", "exec_axis",
            "exec_dir")
    checked = 0
    for eid in enc.column("encounter_id").to_pylist():
        steps, row, _ = replay_steplog(tmp_path / "camp", "IC-1", eid)
        stored = enc.filter(pc.equal(enc.column("encounter_id"), eid)).to_pylist()[0]
        for key, want in stored.items():
            got = row[key]
            assert got == want or (got != got and want != want), (eid, key, got, want)
        mine = dec.filter(pc.equal(dec.column("encounter_id"), eid))
        active = steps.filter(pc.not_equal(steps.column("decision"), "none"))
        assert active.num_rows == mine.num_rows
        for c in cols:
            _assert_tables_equal(active.select([c]), mine.select([c]))
        checked += mine.num_rows
    assert checked > 100
