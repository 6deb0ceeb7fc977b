"""Fast-time simulator: counting identities, chunking changes nothing, the step order's delays, step log."""

import numpy as np
import pyarrow.compute as pc
import pytest

from daa_sil.config.groups import policy_for_group
from daa_sil.models.encounters import concat_encounters, sample_encounters
from daa_sil.study.simulation.fasttime import DECISION_SCHEMA, ENCOUNTER_SCHEMA, simulate
from daa_sil.models.latency import Constant, TruncatedGaussian

N = 40


@pytest.fixture(scope="module")
def encs():
    return sample_encounters(N, seed=11, preset="paper")


@pytest.fixture(scope="module")
def runs(encs):
    out = {}
    for g, lat in (("B-1", Constant(4.0)), ("IC-1", TruncatedGaussian(5.0, 3.0))):
        out[g] = simulate(encs, policy_for_group(g), lat, lat, group=g, record_steps=True)
    return out


def _col(tab, name):
    return np.asarray(tab[name].to_numpy(zero_copy_only=False))


@pytest.mark.parametrize("group", ["B-1", "IC-1"])
def test_counting_identities(runs, group):
    enc, dec, _ = runs[group]
    assert enc.schema.equals(ENCOUNTER_SCHEMA) and dec.schema.equals(DECISION_SCHEMA)
    c = {name: _col(enc, name) for name in enc.column_names if name.startswith("n_")}
    # one decision per active step, and the decisions partition the active steps
    parts = c["n_wait"] + c["n_no_wait"] + c["n_pilot_exec"] + c["n_blend"] + c["n_daa_override"] \
        + c["n_stale"] + c["n_link_lost"]
    np.testing.assert_array_equal(parts, c["n_active_steps"])
    np.testing.assert_array_equal(c["n_pilot_received"], c["n_pilot_exec"] + c["n_blend"] + c["n_daa_override"])
    assert np.all(c["n_blend_exact"] + c["n_blend_axis"] <= c["n_blend_intent"])
    assert np.all(c["n_blend_intent"] <= c["n_blend"])
    assert c["n_active_steps"].sum() > 0  # the sample does exercise the agent
    # the decision table has exactly n_active_steps rows per encounter, with the same labels
    ids, counts = np.unique(_col(dec, "encounter_id"), return_counts=True)
    per = dict(zip(ids.tolist(), counts.tolist()))
    assert [per.get(i, 0) for i in _col(enc, "encounter_id")] == c["n_active_steps"].tolist()
    labels = _col(dec, "decision")
    assert (labels == "wait").sum() == c["n_wait"].sum()
    assert (labels == "no_wait").sum() == c["n_no_wait"].sum()
    assert (labels == "blend").sum() == c["n_blend"].sum()
    assert _col(dec, "exact_match").sum() == c["n_blend_exact"].sum()
    # intent blends = blends whose pilot command carries an (axis, direction), from the decision rows
    intent = (labels == "blend") & (_col(dec, "pilot_axis") != "none")
    assert intent.sum() == c["n_blend_intent"].sum()


def test_policies_show_in_the_counts(runs):
    b1 = {k: pc.sum(runs["B-1"][0][k]).as_py() for k in ("n_wait", "n_blend", "n_daa_override")}
    ic = {k: pc.sum(runs["IC-1"][0][k]).as_py() for k in ("n_wait", "n_blend", "n_daa_override")}
    assert b1["n_wait"] == 0 and b1["n_blend"] == 0  # baseline: w = 0, blending off
    assert ic["n_daa_override"] == 0  # integrated: unsafe pilot commands are blended, never overridden
    assert ic["n_wait"] > 0


def test_chunking_changes_no_column(encs, runs):
    # the same encounters as two chunks in the other order: every column of both tables is identical, bit
    # for bit (each encounter's DAA numbers are those of a call of its own, docs/architecture.md "Fast-time
    # batches"); on 3e5dc69 sm_pilot and sm_exec moved here (the test then allowed them BISECT_DT_IN)
    a, b = encs.subset(np.arange(N // 2, N)), encs.subset(np.arange(0, N // 2))
    pol, lat = policy_for_group("IC-1"), TruncatedGaussian(5.0, 3.0)
    parts = [simulate(x, pol, lat, lat, group="IC-1") for x in (a, b)]
    whole = runs["IC-1"][0]
    order = np.argsort(np.concatenate([_col(p[0], "encounter_id") for p in parts]))
    for name in whole.column_names:
        got = np.concatenate([_col(p[0], name) for p in parts])[order]
        np.testing.assert_array_equal(got, _col(whole, name), err_msg=name)
    dec_whole = runs["IC-1"][1]
    assert dec_whole.num_rows > 0 and np.isfinite(_col(dec_whole, "sm_pilot")).any()
    for name in dec_whole.column_names:  # chunk b holds the lower encounter ids: b's rows come first
        got, want = np.concatenate([_col(parts[1][1], name), _col(parts[0][1], name)]), _col(dec_whole, name)
        np.testing.assert_array_equal(got, want, err_msg=name)  # (nan equal to nan)
    # the same encounters in one call, in another order: everything identical
    cat = concat_encounters([b, a])
    again = simulate(cat, pol, lat, lat, group="IC-1")[1]
    assert again.num_rows == runs["IC-1"][1].num_rows
    for name in again.column_names:  # decision rows are sorted by (encounter, t) whatever the input order
        np.testing.assert_array_equal(_col(again, name), _col(runs["IC-1"][1], name), err_msg=name)


def test_step_order_delays_and_step_log(encs, runs):
    enc, dec, log = runs["B-1"]
    steps = 240
    assert log.num_rows == N * steps
    ids = _col(log, "encounter_id")
    # every command the vehicle received was sent exactly 4 s earlier (constant 4 s uplink, FIFO)
    rec = _col(log, "pilot_cmd_received")
    age = _col(log, "pilot_cmd_age_s")
    assert rec.any()
    np.testing.assert_array_equal(age[rec], 4.0)
    assert np.isnan(age[~rec]).all()
    np.testing.assert_array_equal(_col(log, "delay_up_s"), 4.0)
    # the step log's per-step LoWC events aggregate to the encounter table
    lowc_any = np.zeros(N, bool)
    np.logical_or.at(lowc_any, np.searchsorted(_col(enc, "encounter_id"), ids), _col(log, "lowc"))
    np.testing.assert_array_equal(lowc_any, _col(enc, "lowc"))
    # active rows of the step log are the decision table
    active = _col(log, "decision") != "none"
    assert active.sum() == dec.num_rows
    np.testing.assert_array_equal(_col(log, "t")[active], _col(dec, "t"))


def test_pilot_sees_delayed_telemetry(encs):
    # with a 4 s downlink and a 0.2 s uplink, a command can never be received before the alert has
    # been visible at the GCS: first receipt >= first alert + 4 s (downlink) + 1 step (publish after decide)
    sub = encs.subset(np.arange(20))
    _, _, log = simulate(sub, policy_for_group("B-1"), Constant(0.2), Constant(4.0), record_steps=True)
    ids, t = _col(log, "encounter_id"), _col(log, "t")
    alert = np.array([max(a) if a else 0 for a in log["alert_level"].to_pylist()])
    rec = _col(log, "pilot_cmd_received")
    checked = 0
    for e in np.unique(ids):
        m = ids == e
        if rec[m].any():
            first_alert = t[m][alert[m] >= 2].min()
            first_rec = t[m][rec[m]].min()
            assert first_rec >= first_alert + 4.0
            checked += 1
    assert checked > 0


def test_map_policy_needs_a_family(encs):
    from daa_sil.errors import UsageError

    with pytest.raises(UsageError, match="wait_family"):
        simulate(encs.subset(np.arange(2)), policy_for_group("ID-1"), Constant(4.0), Constant(4.0))
