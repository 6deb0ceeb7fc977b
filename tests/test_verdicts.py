"""Each verdict word from hand-made findings on hand-made studies: reproduced, consistent (not shown),
direction holds, not reproduced and by construction, with the rules that separate them (exact zero
test, TOST against a margin, Holm across the pairs of one table, bounds and bands straddled)."""

from dataclasses import replace

import numpy as np
import pytest

from daa_sil.study import findings as F
from daa_sil.study import verdicts as V
from daa_sil.study.analysis import Study

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


def test_verdict_words_are_exactly_the_five():
    assert F.VERDICTS == ("reproduced", "consistent (not shown)", "direction holds", "not reproduced",
                          "by construction")
