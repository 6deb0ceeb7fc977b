"""Each verdict word from hand-made findings on hand-made studies: reproduced, consistent (not shown),
direction holds, not reproduced, by construction, uninformative, nested and input, with the rules that
separate them (two samples for values, exact zero test, TOST against a margin, Holm across the pairs of
one table, bounds and bands straddled, a band wider than the paper's own number allows, a relation at
another size)."""

from dataclasses import replace

import numpy as np
import pytest

from daa_sil.study.analysis import findings as F
from daa_sil.study.analysis import verdicts as V
from daa_sil.study.analysis.study import Study

N = 2000


def group(name, n=N, **cols):
    t = {"group": np.array([name] * n), "encounter_id": np.arange(n), "duration_s": np.full(n, 240.0),
         "lowc": np.zeros(n, bool), "nmac": np.zeros(n, bool), "lowc_duration_s": np.zeros(n), "pi": np.zeros(n),
         "pi_paper": np.zeros(n), "dev_h_m": np.full(n, 100.0), "dev_v_m": np.full(n, 10.0),
         "intruder_turns": np.zeros(n, bool)}
    for c in ("n_wait", "n_no_wait", "n_pilot_received", "n_pilot_exec", "n_blend", "n_blend_exact", "n_blend_axis",
              "n_blend_intent", "n_daa_override", "n_stale", "n_link_lost"):
        t[c] = np.zeros(n, np.int64)
    t.update({k: np.asarray(v) for k, v in cols.items()})
    return t


def study(*groups):
    cols = {k: np.concatenate([g[k] for g in groups]) for k in groups[0]}
    return Study(cols, replicates=1000, seed=5)


def finding(**kw):
    base = dict(id="hand-made", claim="a hand-made finding", source="table X", kind="value", metric="no_wait")
    return F.Finding(**{**base, **kw})


def test_zero_claims_use_fishers_exact_test_against_the_papers_0_of_10000():
    f = finding(kind="zero", metric="n_nmac", group="ID-2")
    assert V.evaluate(f, study(group("ID-2"))).verdict == F.REPRODUCED
    one = np.zeros(N, bool)
    one[700] = True
    o = V.evaluate(f, study(group("ID-2", nmac=one, lowc=one)))
    # 1 of 2,000 against 0 of 10,000: the one event falls in our 2,000 of 12,000 encounters with
    # probability 2,000 / 12,000, the only table as extreme: two-sided p = 0.17
    assert o.verdict == F.CONSISTENT and "p = 0.17" in o.evidence and "1 of 2,000" in o.evidence
    two = np.zeros(N, bool)
    two[[3, 700]] = True
    # 2 of 2,000: p = C(2000, 2) / C(12000, 2) = 0.028 < 0.05
    o = V.evaluate(f, study(group("ID-2", nmac=two, lowc=two)))
    assert o.verdict == F.NOT_REPRODUCED and f"p = {2000 * 1999 / (12000 * 11999):.2g}" in o.evidence
    assert V.zero_test(2, 10000, 10000, 0.05)[0] == pytest.approx(0.5, abs=1e-4)  # the 2 vs 0 in 10,000
    assert V.zero_test(0, 10000, 10000, 0.05)[1] == 6  # the smallest count the test can tell from 0
    many = np.zeros(N, bool)
    many[:12] = True
    assert V.evaluate(f, study(group("ID-2", nmac=many, lowc=many))).verdict == F.NOT_REPRODUCED


def _paired(ratio, noise=0.0, seed=1):
    """B-2 and IC-1 deviations per encounter (mean 160 m): IC-1 = ratio x B-2 + N(0, noise) m."""
    rng = np.random.default_rng(seed)
    base = rng.gamma(2.0, 80.0, N)
    return study(group("B-2", dev_h_m=base), group("IC-1", dev_h_m=base * ratio + rng.normal(0.0, noise, N)))


@pytest.mark.parametrize("ratio, noise, verdict", [
    (1.0005, 0.0, F.REPRODUCED),       # +0.05 % exactly: the 90 % CI inside +-0.3 %
    (1.0, 30.0, F.CONSISTENT),         # no change on average, but a CI wider than the margin
    (1.05, 0.0, F.NOT_REPRODUCED),     # +5 %: the whole CI outside the margin
])
def test_no_change_claims_are_a_tost_against_the_stated_margin(ratio, noise, verdict):
    f = finding(kind="equivalence", metric="dev_h_mean", group="IC-1", change={"kind": "ratio", "vs": "B-2"},
                margin=0.3, margin_reason="hand-made")
    o = V.evaluate(f, _paired(ratio, noise))
    assert o.verdict == verdict, o
    if verdict == F.CONSISTENT:
        assert o.lo < 0.3 and o.hi > -0.3 and o.hi - o.lo > 0.6


@pytest.mark.parametrize("ratio, verdict", [(1 - 0.882, F.REPRODUCED), (0.5, F.DIRECTION), (1.3, F.NOT_REPRODUCED)])
def test_change_rule_gives_reproduced_direction_and_not_reproduced(ratio, verdict):
    rng = np.random.default_rng(1)
    base = rng.poisson(40.0, N) * (rng.random(N) < 0.2) * 100  # x 100: rounding below moves nothing
    st = study(group("B-2", n_no_wait=base), group("ID-2", n_no_wait=np.rint(base * ratio).astype(int)))
    f = finding(kind="change", group="ID-2", change={"kind": "reduction", "vs": "B-2"}, paper={"value": 88.2})
    assert V.evaluate(f, st).verdict == verdict


def test_a_bound_or_a_band_straddled_is_consistent_not_shown():
    rng = np.random.default_rng(4)
    lowc = np.arange(N) < 60
    pi = np.where(lowc, rng.exponential(0.95, N), 0.0)
    o = V.evaluate(finding(kind="bound", metric="pi_paper_mean", group="ID-2", bound=1.0),
                   study(group("ID-2", lowc=lowc, pi_paper=pi, lowc_duration_s=lowc * 3.0)))
    assert o.lo < 1.0 <= o.hi and o.verdict == F.CONSISTENT
    # P(LoWC) per step around 1.5e-2 / 666.67 h = 2.2e-5/h: a CI across the Probable / Remote edge (1e-5)
    dur = np.where(lowc, rng.exponential(3.6 * 240 * 0.0025 / 0.03, N), 0.0)
    f = finding(kind="category", metric="p_lowc_per_hr_paper_h", group="ID-2", category="Remote")
    o = V.evaluate(f, study(group("ID-2", lowc=lowc, lowc_duration_s=dur)))
    assert o.lo < 1e-5 <= o.hi and o.verdict == F.CONSISTENT, o


def _lowc(n_enc):
    x = np.zeros(N, bool)
    x[:n_enc] = True
    return x


def test_orderings_of_one_table_are_holm_corrected_together():
    """ID-2 has 0 LoWC encounters; the others 6 each (McNemar p = 2 x 0.5^6 = 0.031 per pair, significant
    alone): corrected over the 3 pairs (Holm: 3 x 0.031 = 0.094) the ordering is consistent (not shown)."""
    f = finding(kind="ordering", metric="p_lowc", ordering={"subject": "ID-2", "relation": "fewest",
                                                            "others": ["B-1", "B-2", "IC-1"]})
    st = study(*(group(g, lowc=_lowc(6)) for g in ("B-1", "B-2", "IC-1")), group("ID-2"))
    raw = [p["p"] for p in V.ordering_pairs(f, st)]
    assert raw == pytest.approx([2 * 0.5 ** 6] * 3)
    assert V.holm(raw) == pytest.approx([3 * 2 * 0.5 ** 6] * 3)
    o = V.evaluate(f, st)
    assert o.verdict == F.CONSISTENT and "Holm 0.094" in o.text
    st = study(*(group(g, lowc=_lowc(12)) for g in ("B-1", "B-2", "IC-1")), group("ID-2"))
    assert V.evaluate(f, st).verdict == F.REPRODUCED
    st = study(*(group(g) for g in ("B-1", "B-2", "IC-1")), group("ID-2", lowc=_lowc(12)))
    assert V.evaluate(f, st).verdict == F.NOT_REPRODUCED
    # Holm is step-down: the smallest p is multiplied by m, the next by m - 1, never below the previous
    assert list(V.holm([0.01, 0.04, 0.03])) == pytest.approx([0.03, 0.06, 0.06])


def test_by_construction_is_counted_apart_and_a_failure_is_a_defect():
    f = finding(kind="zero", metric="daa_override", group="ID-2", by_construction="blending replaces override")
    o = V.evaluate(f, study(group("ID-2")))
    assert o.verdict == F.BY_CONSTRUCTION and "blending replaces override" in o.evidence
    bad = np.zeros(N, np.int64)
    bad[:20] = 3
    o = V.evaluate(f, study(group("ID-2", n_daa_override=bad)))
    assert o.verdict == F.NOT_REPRODUCED and "a defect" in o.evidence
    # the headline tally counts only the empirical verdicts
    rows = [(f, {"r": V.evaluate(f, study(group("ID-2")))}),
            (replace(f, by_construction="", id="emp"), {"r": V.evaluate(replace(f, by_construction=""),
                                                                        study(group("ID-2")))})]
    c = V.tally(rows, "r")
    assert c[F.BY_CONSTRUCTION] == 1 and sum(c[v] for v in F.EMPIRICAL) == 1


def test_verdict_words_are_exactly_these():
    assert F.VERDICTS == ("reproduced", "consistent (not shown)", "direction holds", "not reproduced",
                          "by construction", "uninformative", "nested", "input")
    assert F.APART == ("by construction", "uninformative", "nested", "input")


def test_a_value_is_compared_as_two_samples_not_against_our_interval():
    """10,000 encounters of ours, the paper's 10,000: the difference's standard error is sqrt(2) times
    ours. A paper value 1.3 z-errors from ours lies outside our CI (the old rule: not reproduced) but
    inside the two-sample interval (reproduced); at 1.5 it is outside both."""
    n = 10_000
    rng = np.random.default_rng(3)
    x = rng.poisson(8.0, n)
    st = Study(group("B-1", n=n, n_no_wait=x), replicates=2000, seed=5)
    se = x.std(ddof=1) / np.sqrt(n)  # the hand-worked standard error of a mean
    z = 1.959964
    for k, verdict in ((1.3, F.REPRODUCED), (1.5, F.NOT_REPRODUCED)):
        f = finding(kind="value", group="B-1", paper={"value": float(x.mean() + k * z * se)})
        o = V.evaluate(f, st)
        assert not (o.lo <= f.paper_value() <= o.hi)  # outside our own interval either way
        assert o.verdict == verdict, (k, o)
        assert "the paper's at its N" in o.evidence


def _remote(factor, n=N):
    """LoWC durations giving a P(LoWC)/h of ``factor`` x the paper's ID-2 value (2.81e-7 at 666.67 h)."""
    rng = np.random.default_rng(9)
    lowc = np.arange(n) < 40
    share = 2.81e-7 * 666.67 * factor  # the fraction of time in LoWC
    dur = np.where(lowc, rng.exponential(1.0, n), 0.0)
    dur *= share * 240.0 * n / dur.sum()
    return study(group("ID-2", n=n, lowc=lowc, lowc_duration_s=dur))


def test_a_remote_style_band_is_uninformative_and_not_counted_as_reproduced():
    """P(LoWC)/h at 7x the paper's ID-2 value still lies in the FAA 'Remote' band (1e-7 .. 1e-5): the
    band passes values the paper's own number rules out, so the pass is counted apart, not as a
    reproduction. Far outside the band (Frequent) it is still a miss."""
    band = finding(kind="category", metric="p_lowc_per_hr_paper_h", group="ID-2", category="Remote",
                   summarises="p-lowc-hr")
    value = finding(id="p-lowc-hr", kind="value", metric="p_lowc_per_hr_paper_h", group="ID-2",
                    paper={"key": "lowc_per_flight_hour.{group}.p"})
    st = _remote(7.0)
    o = V.evaluate(band, st)
    assert 1e-7 <= o.lo and o.hi < 1e-5  # inside the band: the old rule said reproduced
    assert o.verdict == F.UNINFORMATIVE and "rules out" in o.evidence
    assert V.evaluate(value, st).verdict == F.NOT_REPRODUCED  # the number itself is missed
    c = V.tally([(band, {"r": o})], "r")
    assert c[F.REPRODUCED] == 0 and c[F.UNINFORMATIVE] == 1 and sum(c[v] for v in F.EMPIRICAL) == 0
    assert V.evaluate(band, _remote(1e4)).verdict == F.NOT_REPRODUCED  # 2.8e-3/h: outside the band, a miss
    # without a number it summarises, a band is judged as before
    assert V.evaluate(replace(band, summarises=""), st).verdict == F.REPRODUCED


def test_a_relation_at_another_size_is_direction_holds():
    """'IC-1 has a slightly higher number of reception than ID-2': the paper's tables give
    (924,574 - 921,993) / 10,000 = 0.258 per encounter. At 8.8 per encounter the relation holds at
    34 times that size: direction holds. At 0.26 it is reproduced."""
    f = finding(kind="ordering", metric="received", ordering={"subject": "IC-1", "relation": "more",
                                                              "others": ["ID-2"]},
                size={"key": "pilot_command_reception.{group}.received", "per_encounter": True})
    base = np.full(N, 90)
    for extra, verdict in ((np.full(N, 9) - (np.arange(N) % 5 == 0), F.DIRECTION),
                           ((np.arange(N) % 100 < 26).astype(int), F.REPRODUCED)):
        st = study(group("IC-1", n_pilot_received=base + extra), group("ID-2", n_pilot_received=base))
        o = V.evaluate(f, st)
        assert o.verdict == verdict, o
    assert "not the paper's size" in V.evaluate(f, study(group("IC-1", n_pilot_received=base + 9),
                                                         group("ID-2", n_pilot_received=base))).evidence


def test_the_tost_margin_is_the_papers_detectable_difference():
    """The margin of 'almost the same' is the smallest paired difference the paper's 10,000 encounters
    could detect (two-sided 5 %, 80 % power): (1.96 + 0.84) x SE at N = 10,000, here from the
    delta method on the per-encounter deviations, computed by hand."""
    rng = np.random.default_rng(1)
    b = rng.gamma(2.0, 80.0, N)
    a = b * 1.0 + rng.normal(0.0, 40.0, N)
    st = study(group("B-2", dev_h_m=b), group("IC-1", dev_h_m=a))
    f = finding(kind="equivalence", metric="dev_h_mean", group="IC-1", change={"kind": "ratio", "vs": "B-2"},
                margin_rule="detectable", margin_reason="hand-made")
    m, _ = V.equivalence_margin(f, st)
    r = a.mean() / b.mean()
    se_ratio = np.sqrt(np.var(a - r * b, ddof=1) / N) / b.mean() * 100.0  # % (delta method)
    assert m == pytest.approx((1.959964 + 0.841621) * se_ratio * np.sqrt(N / 10_000), rel=0.1)
    o = V.evaluate(f, st)
    assert f"±{m:.2f} %" in o.evidence


def _all_groups(**per_group):
    return study(*(group(g, **per_group.get(g, {})) for g in ("B-1", "B-2", "IC-1", "ID-1", "ID-2")))


def test_nested_claims_are_tested_together_and_inputs_counted_apart():
    """'The maximum PI is 3.79' (pooled over the five groups) implies 'no PI > 10': one claim, counted
    once. A number a setting was inferred from is input when we match it, a miss when we do not."""
    lowc = np.zeros(N, bool)
    lowc[:3] = True
    pi = np.where(lowc, 12.0, 0.0)  # three LoWCs above 10 in ID-1
    st = _all_groups(**{"ID-1": dict(lowc=lowc, pi=pi, lowc_duration_s=lowc * 5.0)})
    rows = V.evaluate_all({"r": st}, consumed={"r": {("received", "B-1")}})
    got = {(f.id, f.group): o for f, outs in rows for o in [outs["r"]]}
    assert got[("pi-max", None)].verdict in (F.CONSISTENT, F.NOT_REPRODUCED)
    assert "3 in 3 of 10,000 enc." in got[("pi-max", None)].text  # pooled: 5 x 2,000 encounters
    sev = got[("pi-severe", None)]
    assert sev.verdict == F.NESTED and "tested with it" in sev.evidence
    # B-1 receives nothing here: the inference from its 79.5 commands per encounter missed anyway -> a miss
    miss = got[("received", "B-1")]
    assert miss.verdict == F.NOT_REPRODUCED and "inferred" in miss.evidence and "misses" in miss.evidence
    c = V.tally(rows, "r")
    assert c[F.NESTED] == 1 and c[F.INPUT] == 0
    # B-1 receiving about the paper's 79.5 per encounter: the number the setting came from is input, not a
    # reproduction (the same data without the inference reproduce it)
    rng = np.random.default_rng(3)
    got_b1 = rng.poisson(79.5, N)
    st = _all_groups(**{"B-1": dict(n_pilot_received=got_b1, n_pilot_exec=got_b1)})
    f = next(f for f in F.load_findings() if f.id == "received" and f.group == "B-1")
    assert V.evaluate(f, st).verdict == F.REPRODUCED
    rows = V.evaluate_all({"r": st}, consumed={"r": {("received", "B-1")}})
    inp = next(outs["r"] for f, outs in rows if (f.id, f.group) == ("received", "B-1"))
    assert inp.verdict == F.INPUT and "not a reproduction" in inp.evidence and V.tally(rows, "r")[F.INPUT] == 1
