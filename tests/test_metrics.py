"""Metrics against hand-worked tables; intervals recomputed independently with scipy."""

import math

import numpy as np
import pytest
from scipy import stats

from daa_sil.study.analysis import metrics as M
from daa_sil.study.analysis import study as A
from daa_sil.study.analysis import counting as C
from daa_sil.errors import FileFormatError, UsageError


def table(group="ID-2", n=10_000, lowc_idx=(5, 77, 901), lowc_dur=2.0, **counts):
    t = {"group": np.array([group] * n), "encounter_id": np.arange(n), "duration_s": np.full(n, 240.0),
         "lowc": np.zeros(n, bool), "nmac": np.zeros(n, bool), "lowc_duration_s": np.zeros(n), "pi": np.zeros(n),
         "dev_h_m": np.zeros(n), "dev_v_m": np.zeros(n)}
    for c in ("n_wait", "n_no_wait", "n_pilot_received", "n_pilot_exec", "n_blend", "n_blend_exact", "n_blend_axis",
              "n_daa_override"):
        t[c] = np.zeros(n, np.int64)
    t["lowc"][list(lowc_idx)] = True
    t["lowc_duration_s"][list(lowc_idx)] = lowc_dur
    for k, v in counts.items():
        t[k] = np.asarray(v)
    return t


def merge(*ts):
    return {k: np.concatenate([t[k] for t in ts]) for k in ts[0]}


def test_three_lowc_in_10000_encounters_of_240_s():
    m = M.group_metrics(table())
    hours = 10_000 * 240 / 3600  # 666.67 h
    assert m["flight_hours"] == pytest.approx(hours)
    assert m["p_lowc"].value == pytest.approx(3e-4)
    assert m["p_lowc"].lo == pytest.approx(stats.beta.ppf(0.025, 3, 9998))
    assert m["p_lowc"].hi == pytest.approx(stats.beta.ppf(0.975, 4, 9997))
    # event rate: 3 / 666.67 h = 4.5e-3 per hour, exact Poisson bounds chi2/2
    assert m["lowc_rate_per_hr"].value == pytest.approx(0.0045)
    assert m["lowc_rate_per_hr"].lo == pytest.approx(stats.chi2.ppf(0.025, 6) / 2 / hours)
    assert m["lowc_rate_per_hr"].hi == pytest.approx(stats.chi2.ppf(0.975, 8) / 2 / hours)
    # paper Eq.: 6 LoWC steps of 2.4e6 -> 2.5e-6, / 666.67 h = 3.75e-9 -> Extremely Remote
    assert m["p_lowc_per_hr"].value == pytest.approx(2.5e-6 / hours)
    assert m["p_lowc_per_hr"].value == pytest.approx(3.75e-9)
    assert m["p_lowc_per_hr"].hi == pytest.approx(stats.beta.ppf(0.975, 7, 2_400_000 - 6) / hours)
    assert M.faa_category(m["p_lowc_per_hr"].value) == "Extremely Remote"


def test_zero_counts_give_upper_bounds():
    m = M.group_metrics(table(lowc_idx=()))
    assert m["n_nmac"].value == 0 and m["p_nmac"].lo == 0
    assert m["p_nmac"].hi == pytest.approx(1 - 0.025 ** (1 / 10_000))
    assert m["p_nmac"].hi < 3.7 / 10_000 and "rule of three" in m["p_nmac"].note
    assert m["daa_override"].hi == pytest.approx(-math.log(0.025))  # Poisson k=0 upper = 3.689
    assert math.isnan(m["pi_mean"].value) and m["pi_mean"].note == "no LoWC"
    assert math.isnan(m["exact_match"].value)


def test_faa_categories_from_paper_table():
    assert M.faa_category(2.22e-7) == "Remote"
    assert M.faa_category(5e-4) == "Probable"
    assert M.faa_category(0.01) == "Frequent"
    assert M.faa_category(5e-9) == "Extremely Remote"
    assert M.faa_category(1e-10) == "Extremely Improbable"
    assert M.faa_category(1e-7) == "Remote"  # boundary goes to the more frequent band


def test_reduction_and_reception_vs_b2_by_hand():
    n = 100
    b2 = table("B-2", n, lowc_idx=(), n_no_wait=np.full(n, 9), n_pilot_received=np.full(n, 80))
    id2 = table("ID-2", n, lowc_idx=(), n_no_wait=np.r_[np.ones(50, int), np.zeros(50, int)],
                n_wait=np.full(n, 8), n_pilot_received=np.full(n, 92), n_blend=np.full(n, 5),
                n_blend_exact=np.r_[np.full(50, 4), np.full(50, 5)])
    res = M.compute_metrics(merge(b2, id2))
    r = res["ID-2"]
    assert r["no_wait"].value == 50 and res["B-2"]["no_wait"].value == 900
    assert r["no_wait_reduction_pct"].value == pytest.approx(100 * (1 - 50 / 900))
    # exact conditional interval: k=50 of 950 binomial, CP on p, RR = p/(1-p)
    lo_p, hi_p = stats.beta.ppf(0.025, 50, 901), stats.beta.ppf(0.975, 51, 900)
    assert r["no_wait_reduction_pct"].lo == pytest.approx(100 * (1 - hi_p / (1 - hi_p)))
    assert r["no_wait_reduction_pct"].hi == pytest.approx(100 * (1 - lo_p / (1 - lo_p)))
    assert r["received_change_pct"].value == pytest.approx(15.0)
    assert r["exact_match"].value == pytest.approx(450 / 500)
    assert r["exact_match"].lo == pytest.approx(stats.beta.ppf(0.025, 450, 51))
    assert "no_wait_reduction_pct" not in res["B-2"]


def test_means_use_student_t():
    t = table(n=4, lowc_idx=(0, 1), dev_h_m=np.array([1.0, 2.0, 3.0, 6.0]), pi=np.array([0.5, 1.5, 0, 0]))
    m = M.group_metrics(t)
    h = stats.t.ppf(0.975, 3) * np.std([1, 2, 3, 6], ddof=1) / 2
    assert m["dev_h_mean"].value == 3.0 and m["dev_h_mean"].hi == pytest.approx(3.0 + h)
    assert m["pi_mean"].value == 1.0 and m["pi_max"].value == 1.5


def test_errors_are_clear():
    t = table(n=3, lowc_idx=())
    with pytest.raises(UsageError, match="no encounters"):
        M.group_metrics(t, "B-1")
    bad = dict(t)
    bad.pop("pi")
    with pytest.raises(FileFormatError, match="pi"):
        M.compute_metrics(bad)
    with pytest.raises(UsageError):
        M.compute_metrics([1, 2, 3])


def test_exact_match_is_over_blends_of_a_pilot_maneuver():
    """100 blends, 40 of them of a pilot maneuver (the rest blend "hold"), 30 exact + 6 axis-only."""
    n = 100
    cnt = {c: np.zeros(n, np.int64) for c in ("n_blend", "n_blend_intent", "n_blend_exact", "n_blend_axis")}
    cnt["n_blend"][:] = 1
    cnt["n_blend_intent"][:40] = 1
    cnt["n_blend_exact"][:30] = 1
    cnt["n_blend_axis"][30:36] = 1
    m = M.group_metrics(table(n=n, lowc_idx=(), **cnt))
    assert m["exact_match"].value == pytest.approx(0.75)
    assert m["exact_match"].lo == pytest.approx(stats.beta.ppf(0.025, 30, 11))
    assert m["axis_match"].value == pytest.approx(0.15)
    assert m["blend_intent_share"].value == pytest.approx(0.40)
    # a table without the column (older results) falls back to all blends, and says so
    del cnt["n_blend_intent"]
    m = M.group_metrics(table(n=n, lowc_idx=(), **cnt))
    assert m["exact_match"].value == pytest.approx(0.30) and "all blends" in m["exact_match"].method


# --- the encounter-level study ----------------------------------------------------------------------
def _study(*ts, **kw):
    return A.Study(merge(*ts), replicates=500, seed=2, **kw)


def test_study_pairs_groups_by_encounter_id_not_row_order():
    """B-2 and ID-2 count the same per encounter, ID-2's rows shuffled: a paired change is exactly
    0 on every resample. Rows matched by position instead would give a spread."""
    n = 200
    rng = np.random.default_rng(0)
    k = rng.poisson(3.0, n) * (rng.random(n) < 0.3)
    b2 = table("B-2", n, lowc_idx=(), n_no_wait=k)
    perm = rng.permutation(n)
    id2 = {c: np.asarray(v)[perm] for c, v in table("ID-2", n, lowc_idx=(), n_no_wait=k).items()}
    st = _study(b2, id2)
    ch = st.change_sample("ID-2", "no_wait", "B-2", "ratio")
    assert ch.value == 0 and np.all(ch.reps == 0)
    # the same data positionally mismatched is not degenerate (the oracle can fail)
    id2_bad = dict(id2, encounter_id=np.arange(n))
    assert np.ptp(_study(b2, id2_bad).change_sample("ID-2", "no_wait", "B-2").reps) > 0


def test_study_means_use_each_groups_own_encounters():
    b2 = table("B-2", 100, lowc_idx=(), n_no_wait=np.full(100, 4))
    part = {c: np.asarray(v)[:60] for c, v in table("ID-2", 100, lowc_idx=(), n_no_wait=np.full(100, 1)).items()}
    st = _study(b2, part)
    assert st.n == 100 and st.n_encounters("ID-2") == 60
    assert st.estimate("ID-2", "no_wait").value == pytest.approx(1.0)
    assert st.change("ID-2", "no_wait", kind="reduction").value == pytest.approx(75.0)
    assert st.mcnemar("ID-2", "B-2").n == 60  # paired tests only over encounters both flew


def test_counting_readings_pick_columns():
    n = 10
    t = table("ID-2", n, lowc_idx=(), n_pilot_received=np.full(n, 10), n_pilot_exec=np.full(n, 1),
              n_blend=np.full(n, 6), n_daa_override=np.full(n, 3))
    got = {r: _study(t, reading=C.CountingRules("x", {"received": r})).estimate("ID-2", "received").value
           for r in ("arrived", "pilot+blend", "executed")}
    assert got == {"arrived": 10.0, "pilot+blend": 7.0, "executed": 1.0}
    direct = C.CountingRules("y", {"columns": {"received": ["n_blend", "n_daa_override"]}})
    assert _study(t, reading=direct).estimate("ID-2", "received").value == 9.0
    with pytest.raises(UsageError, match="allowed: window=active"):
        _study(t, reading=C.CountingRules("z", {"received": "arrived", "window": "season"}))
    with pytest.raises(FileFormatError, match="n_pilot_received_whole"):  # whole-encounter columns missing
        _study(t, reading=C.CountingRules("w", {"received": "arrived", "window": "whole"}))
    whole = table("ID-2", n, lowc_idx=(), n_pilot_received=np.full(n, 10), n_pilot_exec=np.full(n, 1),
                  n_blend=np.full(n, 6), n_daa_override=np.full(n, 3), n_pilot_received_whole=np.full(n, 25),
                  n_pilot_exec_whole=np.full(n, 14))
    got = {r: _study(whole, reading=C.CountingRules("v", {"received": r, "window": "whole"})).estimate("ID-2", "received").value
           for r in ("arrived", "pilot+blend", "executed")}
    assert got == {"arrived": 25.0, "pilot+blend": 20.0, "executed": 14.0}


def test_zero_counts_get_an_exact_bound_on_the_mean():
    """0 overrides in 500 encounters of 240 steps: share of encounters <= 1 - 0.025^(1/500), and no
    encounter can count more than 240, so the mean per encounter is at most 240 times that."""
    st = _study(table("ID-2", 500, lowc_idx=()))
    e = st.estimate("ID-2", "daa_override")
    assert e.value == 0 and e.lo == 0
    assert e.hi == pytest.approx(240 * (1 - 0.025 ** (1 / 500)))
    e = st.estimate("ID-2", "n_nmac")
    assert e.value == 0 and e.hi == pytest.approx(500 * stats.beta.ppf(0.975, 1, 500))


def test_lowc_per_hour_three_ways():
    """3 LoWC encounters of 2 s among 10,000 x 240 s: P(LoWC) = 6 / 2.4e6 = 2.5e-6; the paper's Eq.
    at 666.67 h = 3.75e-9; the rate 3 / 666.67 h = 4.5e-3 per hour with Clopper-Pearson x 15/h."""
    st = _study(table())
    assert st.estimate("ID-2", "p_lowc_step").value == pytest.approx(2.5e-6)
    assert st.estimate("ID-2", "p_lowc_per_hr").value == pytest.approx(3.75e-9)
    assert st.estimate("ID-2", "p_lowc_per_hr_paper_h").value == pytest.approx(3.75e-9)
    r = st.estimate("ID-2", "lowc_rate_per_hr")
    assert r.value == pytest.approx(4.5e-3)
    assert r.hi == pytest.approx(stats.beta.ppf(0.975, 4, 9997) * 15)
    # with half the encounters the per-step risk is the same, the paper's Eq. doubles
    half = _study(table(n=5000, lowc_dur=1.0))
    assert half.estimate("ID-2", "p_lowc_step").value == pytest.approx(2.5e-6)
    assert half.estimate("ID-2", "p_lowc_per_hr").value == pytest.approx(7.5e-9)
    assert half.estimate("ID-2", "p_lowc_per_hr_paper_h").value == pytest.approx(3.75e-9)


def test_decision_provenance_by_hand():
    t = table("ID-2", 3, lowc_idx=())
    dec = {"group": np.array(["ID-2"] * 7), "encounter_id": np.array([0, 0, 0, 1, 1, 2, 2]),
           "decision": np.array(["wait", "no_wait", "blend", "wait", "no_wait", "wait", "wait"]),
           "decided_by": np.array(["map", "both", "map", "projl", None, "neither", "map"], dtype=object),
           "in_box": np.array([True, False, None, True, True, None, False], dtype=object)}
    st = _study(t, dec=dec)
    # wait/no-wait rows with a decided_by: 5 (the blend row and the None are not decisions of the map)
    assert st.sum("ID-2", "n_dec").value == 5 and st.sum("ID-2", "n_dec_map").value == 2
    assert st.estimate("ID-2", "map_decided_share").value == pytest.approx(2 / 5)
    assert st.estimate("ID-2", "map_or_both_share").value == pytest.approx(3 / 5)
    assert st.estimate("ID-2", "in_box_share").value == pytest.approx(3 / 5)
    assert not _study(t).provenance["ID-2"]


@pytest.mark.parametrize("in_box", [[True, None, False, True], [1.0, float("nan"), 0.0, 1.0]])
def test_decision_tables_from_parquet_types(in_box):
    """Dictionary-encoded decided_by with nulls, in_box as nullable bool or as 0/1 floats with nan."""
    import pyarrow as pa

    t = pa.table({"group": ["ID-2"] * 4, "encounter_id": [0, 0, 1, 5], "decision": ["wait", "no_wait", "wait", "wait"],
                  "decided_by": pa.array(["map", None, "projl", "map"]).dictionary_encode(), "in_box": in_box})
    d = C.normalise_decisions(t)
    assert d["decided_by"].tolist() == ["map", "", "projl", "map"] and d["in_box"].tolist() == [1, -1, 0, 1]
    st = _study(table("ID-2", 3, lowc_idx=()), dec=t)  # encounter 5 is not in the results: ignored
    assert st.sum("ID-2", "n_dec").value == 2 and st.sum("ID-2", "n_lookup").value == 2


def test_a_new_counting_is_one_table_entry(monkeypatch):
    """A simulator column for a new way of counting plus one COUNT_SOURCES entry is all a reading
    needs: the study, the allowed values and --recount pick it up."""
    from daa_sil.study.analysis.report_input import parse_recount

    keys, tab = C.COUNT_SOURCES["received"]
    monkeypatch.setitem(C.COUNT_SOURCES, "received",
                        (keys, {**tab, ("overridden", "active", "all", "dropped"): ("n_daa_override",)}))
    assert "overridden" in C.counting_options()["received"]
    assert parse_recount("ov:received=overridden") == ("ov", {"received": "overridden"})
    t = table("B-2", 4, lowc_idx=(), n_daa_override=np.array([1, 2, 3, 6]))
    st = _study(t, reading=C.CountingRules("ov", {"received": "overridden"}))
    assert st.estimate("B-2", "received").value == 3.0
