"""Verdict rules: each finding of the paper (:mod:`daa_sil.study.analysis.findings`) tested on the study of one
reading (:class:`daa_sil.study.analysis.study.Study`). Every rule can come out "no"; no rule has a hand-set
threshold: the level is the report's (95 %) for every interval and test, and the one other number, an
equivalence margin, comes from a stated reason in ``paper_findings.yaml``.

The paper's numbers are estimates from its own 10,000 encounters per group: a value or a change is
compared as **two samples** (:mod:`daa_sil.study.analysis.comparison`), never by asking whether the paper's
number lies inside our interval (which narrows as our N grows while the paper's error stays).

The rules (:data:`RULES`, printed in the report):

* **value** -- reproduced if the 95 % interval of ours minus the paper's (the paper's standard error
  estimated from our per-encounter variance at its N) includes 0; else not reproduced.
* **change** -- reproduced as a value; direction holds if not, but our change has the paper's sign and
  our CI excludes 0; else not reproduced.
* **equivalence** ("no change") -- two one-sided tests (TOST) at 5 % against the margin: reproduced if
  our 90 % CI lies inside ±margin; not reproduced if our 95 % CI lies wholly outside it; else
  consistent (not shown). The margin is the paper's minimum detectable difference (a study cannot
  call "almost the same" a difference it could not see), or a number with its reason.
* **zero** ("none happened") -- reproduced if we observe none (exact upper bounds stated); else our
  encounters with one, k of n, against the paper's 0 of its 10,000 per group (pooled findings: over
  all their groups) by Fisher's exact two-sided test: consistent (not shown) if p >= 0.05, not
  reproduced if p < 0.05.
* **bound** ("below B") -- reproduced if our upper 95 % limit is below B; not reproduced if our value
  exceeds B by more than the two samples' combined error (the paper's value below B is an estimate
  too); else consistent (not shown).
* **category** (an FAA likelihood band) -- reproduced if our whole CI lies in the band; not reproduced if
  it lies wholly outside; else consistent (not shown). A band that summarises a number the paper
  gives (``summarises``) and holds values the two-sample test of that number rejects is
  **uninformative**: a pass or a straddle is counted apart, a failure still counts.
* **ordering** ("X has the fewest / most / more than Y") -- each pair tested over the encounters both
  groups flew (exact McNemar for encounter events, a paired-bootstrap test of the difference
  otherwise), the p-values of all pairs of all orderings from one table or figure corrected together
  by Holm's method: reproduced if every pair is significant in the stated direction; not reproduced if
  any is significant the other way; else consistent (not shown). Where the paper's tables give both
  groups' values (``size``), a relation that holds is reproduced only at the paper's size (the two
  samples' difference test); at another size it is *direction holds*.
* **nested** -- a claim implied by another (``nested_in``) is tested with it: one claim, counted once,
  under the other.
* **input** -- a number a setting of the reading was inferred from (``campaign.json`` ``basis``) is
  never a reproduction: counted apart when the reading matches it (or is consistent with it), and
  *not reproduced* when the reading misses it anyway (a miss is never hidden as input).
* **by construction** -- a finding marked ``by_construction`` in ``paper_findings.yaml`` (with why):
  its kind's rule is applied; if it holds the verdict is *by construction* (counted apart from the
  empirical findings), if not *not reproduced* (the construction has a defect).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.stats import fisher_exact

from daa_sil.errors import FileFormatError
from daa_sil.study.analysis.study import Study
from daa_sil.study.analysis.counting import COUNT_SOURCES
from daa_sil.study.analysis.comparison import (accepted_range, detectable_difference, n_paper, standard_error, two_sample,
                                     wider_than)
from daa_sil.study.analysis.findings import (BY_CONSTRUCTION, CONSISTENT, DIRECTION, EVENT_COLUMNS, INPUT, NESTED,
                                    NOT_REPRODUCED, NOT_TESTABLE, REPRODUCED, UNINFORMATIVE, Finding, fmt,
                                    load_findings)
from daa_sil.study.analysis.outcome import Outcome
from daa_sil.study.analysis.verdict_orderings import bootstrap_p, holm, ordering, ordering_pairs
from daa_sil.study.analysis.metrics import Estimate, faa_category, paper_results
from daa_sil.study.analysis.stats import Sample, clopper_pearson, zero_upper_bounds
from daa_sil.study.analysis.findings import VERDICTS

RULES = {
    "value": "two samples: reproduced if the 95 % interval of ours minus the paper's (the paper's standard error "
             "estimated from our per-encounter variance at its N) includes 0; otherwise not reproduced",
    "change": "as a value; direction holds if not, but the sign is the paper's and our CI excludes 0; otherwise not "
              "reproduced",
    "equivalence": "two one-sided tests at 5 % against the margin: reproduced if our 90 % CI lies inside ±margin; not "
                   "reproduced if our 95 % CI lies wholly outside it; otherwise consistent (not shown). The margin is "
                   "the paper's minimum detectable difference (two-sided 5 %, 80 % power, from our paired "
                   "per-encounter differences at its N): 'almost the same' cannot mean less than its study could see",
    "zero": "reproduced if we observe none (exact upper bounds stated); otherwise Fisher's exact two-sided test of our "
            "k of n encounters against the paper's 0 of 10,000 per group (pooled over a pooled finding's groups): "
            "consistent (not shown) if p ≥ 0.05, not reproduced if p < 0.05 (with N = 10,000 the test cannot tell "
            "rates below a few in 10⁴ from 0; counts shown)",
    "bound": "reproduced if our upper 95 % limit is below the bound; not reproduced if our value exceeds it by more "
             "than the two samples' combined 95 % error; otherwise consistent (not shown)",
    "category": "reproduced if our whole 95 % CI lies inside the band; not reproduced if it lies wholly outside; "
                "otherwise consistent (not shown). A band that holds values the two-sample test of the number it "
                "summarises rejects is uninformative: a pass or a straddle is counted apart",
    "ordering": "each pair over the same encounters (exact McNemar for LoWC / NMAC encounters, paired-bootstrap test "
                "of the difference otherwise), the p-values of all pairs of the orderings of one table or figure "
                "Holm-corrected together: reproduced if every pair is significant in the stated direction; not "
                "reproduced if any is significant the other way; otherwise consistent (not shown). Where the paper "
                "gives both values, a relation that holds at another size (two samples) is direction holds",
    "nested": "a claim implied by another is tested with it: one claim, counted once under the other",
    "input": "a number a setting of the reading was inferred from is never a reproduction: counted apart when we "
             "match it (or are consistent with it), not reproduced when we miss it anyway",
    "by construction": "a check the code makes true whatever the data (why: in paper_findings.yaml): its kind's "
                       "rule is applied; by construction if it holds (counted apart from the empirical findings), "
                       "not reproduced if it fails (a defect)",
}


# --- statistics the rules need --------------------------------------------------------------------
def zero_test(k: int, n: int, n_paper: int, alpha: float) -> tuple[float, int]:
    """Fisher's exact two-sided p-value of k of n against 0 of ``n_paper``, and the smallest k that
    would give p < ``alpha`` (the test's reach)."""
    p = float(fisher_exact([[k, n - k], [0, n_paper]])[1]) if k else 1.0
    k_min = 1
    while k_min <= n and float(fisher_exact([[k_min, n - k_min], [0, n_paper]])[1]) >= alpha:
        k_min += 1
    return p, k_min


# --- one finding --------------------------------------------------------------------------------
def evaluate(f: Finding, st: Study, holm_p: "dict | None" = None) -> Outcome:
    """The verdict of finding ``f`` on study ``st``. ``holm_p`` maps ``(finding id, pair group)`` to a
    Holm-adjusted p-value (:func:`evaluate_all` corrects the orderings of one table together); without
    it an ordering is corrected over its own pairs."""
    out = _evaluate(f, st, holm_p)
    if not f.by_construction or out.verdict == NOT_TESTABLE:
        return out
    if out.verdict == REPRODUCED:
        return Outcome(BY_CONSTRUCTION, out.text, f"true by construction: {f.by_construction}; {out.evidence}",
                       out.value, out.lo, out.hi)
    return Outcome(NOT_REPRODUCED, out.text, f"true by construction ({f.by_construction}), yet it failed: a defect; "
                   f"{out.evidence}", out.value, out.lo, out.hi)


def _n_ours(f: Finding, st: Study) -> float:
    """Our encounters per group behind finding ``f`` (the paper's N is per group too)."""
    groups = (f.group,) if f.group else tuple(f.pooled)
    return float(min(st.n_encounters(g) for g in groups))


def _two_sample(f: Finding, st: Study, est: Estimate):
    """Ours minus the paper's value of ``f`` as two samples (:func:`daa_sil.study.analysis.comparison.two_sample`)."""
    se = standard_error(finding_sample(f, st).reps)
    return two_sample(est.value, se, f.paper_value(), _n_ours(f, st), n_paper(), st.conf)


def _evaluate(f: Finding, st: Study, holm_p) -> Outcome:
    missing = [g for g in f.groups_needed if g not in st.groups]
    if f.kind == "ordering":
        return ordering(f, st, missing, holm_p)
    if missing:
        return Outcome(NOT_TESTABLE, "–", f"group(s) {', '.join(missing)} not in this reading")
    if not all(st.available(g, f.metric) for g in f.groups_needed):
        return Outcome(NOT_TESTABLE, "–", f"{f.metric} not in these results")
    if f.kind == "zero":
        return _zero(f, st)
    est = _estimate(f, st)
    if not math.isfinite(est.value):
        return Outcome(NOT_TESTABLE, "–", est.note or "undefined on these results")
    txt = _ci_text(est, f.value_format)
    ev = est.note
    res = dict(value=est.value, lo=est.lo, hi=est.hi)
    if f.kind in ("value", "change"):
        p = f.paper_value()
        two = _two_sample(f, st, est)
        ev = "; ".join(x for x in (two.text(lambda x: fmt(x, f.value_format)), ev) if x)
        if two.matches:
            return Outcome(REPRODUCED, txt, ev, **res)
        if f.kind == "change" and p != 0 and np.sign(est.value) == np.sign(p) and (est.lo > 0 or est.hi < 0):
            return Outcome(DIRECTION, txt, ev, **res)
        return Outcome(NOT_REPRODUCED, txt, ev, **res)
    if f.kind == "equivalence":
        return _equivalence(f, st, est, txt)
    if f.kind == "bound":
        b = float(f.bound)
        se = standard_error(finding_sample(f, st).reps)
        over = two_sample(est.value, se, b, _n_ours(f, st), n_paper(), st.conf)  # ours minus the bound
        ev = "; ".join(x for x in (f"ours − the bound {fmt(over.diff)}, lower two-sample limit {fmt(over.lo)}", ev) if x)
        verdict = REPRODUCED if est.hi < b else (NOT_REPRODUCED if over.lo > 0 else CONSISTENT)
        return Outcome(verdict, txt, ev, **res)
    if f.kind == "category":
        return _category(f, st, est, txt, ev, res)
    raise FileFormatError(f"finding {f.id}: unknown kind {f.kind!r}")


def _category(f: Finding, st: Study, est: Estimate, txt: str, ev: str, res: dict) -> Outcome:
    lo_b, hi_b = paper_results()["faa_likelihood"][f.category]
    inside = est.lo >= lo_b and est.hi < hi_b
    outside = est.hi < lo_b or est.lo >= hi_b
    ev = f"CI from {faa_category(est.lo)} to {faa_category(est.hi)}" + (f"; {ev}" if ev else "")
    verdict = REPRODUCED if inside else (NOT_REPRODUCED if outside else CONSISTENT)
    if f.summarises and verdict != NOT_REPRODUCED:
        ref = next((g for g in load_findings() if g.id == f.summarises and g.group == f.group), None)
        if ref is not None and ref.paper_value() is not None:
            se = standard_error(finding_sample(f, st).reps)
            acc = accepted_range(ref.paper_value(), se, _n_ours(f, st), n_paper(), st.conf)
            if wider_than((lo_b, hi_b), acc):
                k = FORMATS_SCI
                return Outcome(UNINFORMATIVE, txt,
                               f"the band [{fmt(lo_b, k)}, {fmt(hi_b, k)}) holds values the paper's own number "
                               f"({fmt(ref.paper_value(), k)}, finding {ref.id}) rules out: estimates of ours from "
                               f"{fmt(acc[0], k)} to {fmt(acc[1], k)} match it; {verdict} here shows nothing; {ev}",
                               **res)
    return Outcome(verdict, txt, ev, **res)


FORMATS_SCI = "sci"


def _change_sample(f: Finding, st: Study) -> Sample:
    ck = f.change.get("kind", "ratio")
    if f.group:
        return st.change_sample(f.group, f.metric, f.change["vs"], ck)
    return st.pooled_change_sample(f.metric, f.pooled, f.over, "reduction" if ck == "reduction" else "ratio")


def finding_sample(f: Finding, st: Study) -> Sample:
    """The resampled statistic a (non-zero, non-ordering) finding is judged on."""
    if f.kind in ("change", "equivalence"):
        return _change_sample(f, st)
    if f.group:
        return st.sample(f.group, f.metric)
    samples = [st.sample(g, f.metric) for g in f.pooled]
    return sum(samples[1:], samples[0]) / len(samples)


def _estimate(f: Finding, st: Study) -> Estimate:
    if f.kind in ("change", "equivalence"):
        what = (f"paired bootstrap ({f.group} vs {f.change['vs']})" if f.group
                else "paired bootstrap of the pooled means")
        return st._boot_estimate(_change_sample(f, st), what)
    if f.group:
        return st.estimate(f.group, f.metric)
    return st._boot_estimate(finding_sample(f, st), f"mean over {', '.join(f.pooled)} (paired bootstrap)")


def equivalence_margin(f: Finding, st: Study) -> tuple[float, str]:
    """The margin of an equivalence finding (in its unit, %) and its reason: the number stated, or the
    paper's minimum detectable difference from our paired change at its N (``margin_rule``)."""
    if not f.margin_rule:
        return float(f.margin), f.margin_reason
    smp = _change_sample(f, st)
    m = detectable_difference(standard_error(smp.reps), _n_ours(f, st), n_paper(), st.conf)
    return m, f"{f.margin_reason}: {fmt(m, 'f2')} %"


def _equivalence(f: Finding, st: Study, est: Estimate, txt: str) -> Outcome:
    m, reason = equivalence_margin(f, st)
    lo90, hi90 = _change_sample(f, st).interval(1.0 - 2.0 * (1.0 - st.conf))
    res = dict(value=est.value, lo=est.lo, hi=est.hi)
    ev = f"90 % CI [{fmt(lo90, 'pctv')}, {fmt(hi90, 'pctv')}] against the margin ±{fmt(m, 'f2')} % ({reason})"
    if not math.isfinite(m):
        return Outcome(NOT_TESTABLE, txt, "no margin: the change's standard error is undefined")
    if -m < lo90 and hi90 < m:
        return Outcome(REPRODUCED, txt, "equivalent (TOST): " + ev, **res)
    if est.lo >= m or est.hi <= -m:
        return Outcome(NOT_REPRODUCED, txt, "95 % CI wholly outside the margin: " + ev, **res)
    return Outcome(CONSISTENT, txt, "equivalence not shown: " + ev, **res)


def _ci_text(est: Estimate, kind: str) -> str:
    if math.isfinite(est.lo) and math.isfinite(est.hi):
        return f"{fmt(est.value, kind)} [{fmt(est.lo, kind)}, {fmt(est.hi, kind)}]"
    return f"{fmt(est.value, kind)}"


def _zero_column(metric: str) -> str:
    if metric in COUNT_SOURCES or metric == "blend_neither":
        return metric
    if metric.startswith("n_"):
        return metric[2:]
    raise FileFormatError(f"a zero finding needs a count metric, got {metric!r}")


def _zero(f: Finding, st: Study) -> Outcome:
    col = _zero_column(f.metric)
    groups = (f.group,) if f.group else tuple(f.pooled)
    k = k_enc = n = 0
    for g in groups:
        e = st.per_enc[g]
        ok = e["present"] > 0
        k += float(e[col][ok].sum())
        n += int(ok.sum())
        k_enc += int(np.count_nonzero(e[col][ok] > 0))
    over = f" over {', '.join(groups)}" if len(groups) > 1 else ""
    if k == 0:
        one, two = zero_upper_bounds(n, st.conf)
        return Outcome(REPRODUCED,
                       f"0 of {n:,} enc.{over} (share ≤ {fmt(one, 'pct2')} one-sided, ≤ {fmt(two, 'pct2')} two-sided)",
                       f"exact upper bounds on the share of encounters with one: {one:.3g} (one-sided "
                       f"{100 * st.conf:.0f} %), {two:.3g} (upper limit of the two-sided interval)",
                       0.0, 0.0, two)
    n_p = n_paper() * len(groups)
    alpha = 1.0 - st.conf
    p, k_min = zero_test(k_enc, n, n_p, alpha)
    lo, hi = clopper_pearson(k_enc, n, st.conf)
    verdict = NOT_REPRODUCED if p < alpha else CONSISTENT
    return Outcome(verdict, f"{fmt(k, 'int')} in {k_enc:,} of {n:,} enc.{over} [{fmt(lo, 'pct')}, {fmt(hi, 'pct')}]",
                   f"{k_enc} of {n:,} encounters vs the paper's 0 of {n_p:,}: Fisher's exact two-sided p = "
                   f"{p:.2g}; the test reaches p < {alpha:g} only from {k_min} encounters (Clopper-Pearson interval of "
                   f"our share in brackets)", float(k), lo, hi)


def evaluate_all(studies: dict, consumed: "dict | None" = None) -> list[tuple[Finding, dict]]:
    """``[(finding, {reading label: Outcome})]`` for every finding; the ordering pairs of one source
    (table or figure) are Holm-corrected together within each reading. ``consumed`` maps a reading
    label to the ``(finding id, group)`` its settings were inferred from (:func:`daa_sil.config.basis.
    consumed_findings`): those are *input* (*not reproduced* when missed anyway). A finding
    ``nested_in`` another takes the verdict *nested* (its own outcome in the evidence)."""
    found = load_findings()
    rows = [(f, {}) for f in found]
    for label, st in studies.items():
        families: dict = {}
        for f in found:
            if f.kind == "ordering" and f.ordering["subject"] in st.groups:
                for p in ordering_pairs(f, st):
                    families.setdefault(f.source, []).append(((f.id, p["group"]), p["p"]))
        holm_p = {}
        for fam in families.values():
            holm_p.update(dict(zip([k for k, _ in fam], holm([p for _, p in fam]))))
        used = (consumed or {}).get(label, set())
        for f, outs in rows:
            o = evaluate(f, st, holm_p if f.kind == "ordering" else None)
            if (f.id, f.group) in used and o.verdict in (REPRODUCED, CONSISTENT):
                o = Outcome(INPUT, o.text, f"a setting of this reading was inferred from this number (campaign.json "
                            f"'basis'): not a reproduction; by the rule it would be {o.verdict}; {o.evidence}",
                            o.value, o.lo, o.hi)
            elif (f.id, f.group) in used and o.verdict in (DIRECTION, NOT_REPRODUCED):
                o = Outcome(NOT_REPRODUCED, o.text, f"a setting of this reading was inferred from this number "
                            f"(campaign.json 'basis'), and the reading still misses it: a miss; {o.evidence}",
                            o.value, o.lo, o.hi)
            outs[label] = o
        for f, outs in rows:
            if f.nested_in and outs[label].verdict != NOT_TESTABLE:
                o = outs[label]
                parent = next((pf for pf, po in rows if pf.id == f.nested_in and not pf.group), None)
                pv = parent and rows[[r[0] for r in rows].index(parent)][1][label].verdict
                outs[label] = Outcome(NESTED, o.text, f"implied by '{f.nested_in}' and tested with it ({pv}); on its "
                                      f"own: {o.verdict}; {o.evidence}", o.value, o.lo, o.hi)
    return rows


def tally(rows, label: str) -> dict:
    """Verdict counts of one reading: ``{verdict: n}`` over the findings with a verdict (the
    headline counts only the empirical verdicts; :data:`daa_sil.study.analysis.findings.EMPIRICAL`)."""

    return {v: sum(1 for _, o in rows if o[label].verdict == v) for v in VERDICTS + (NOT_TESTABLE,)}


__all__ = ["RULES", "Outcome", "evaluate", "evaluate_all", "ordering_pairs", "finding_sample", "holm", "bootstrap_p",
           "zero_test", "tally", "equivalence_margin", "n_paper"]
