"""Verdict rules: each finding of the paper (:mod:`daa_sil.study.findings`) tested on the study of one
reading (:class:`daa_sil.study.analysis.Study`). Every rule can come out "no"; no rule has a hand-set
threshold: the level is the report's (95 %) for every interval and test, and the one other number, an
equivalence margin, is stated with its reason in ``paper_findings.yaml``.

The rules (:data:`RULES`, printed in the report):

* **value** -- reproduced if the paper's value lies in our 95 % CI; else not reproduced.
* **change** -- reproduced if the paper's value lies in our CI; direction holds if not, but our change
  has the paper's sign and our CI excludes 0; else not reproduced.
* **equivalence** ("no change") -- two one-sided tests (TOST) at 5 % against the stated margin:
  reproduced if our 90 % CI lies inside ±margin; not reproduced if our 95 % CI lies wholly outside
  it; else consistent (not shown) (e.g. a CI containing 0 but wider than the margin).
* **zero** ("none happened") -- reproduced if we observe none (exact upper bounds stated); else our
  encounters with one, k of n, against the paper's 0 of its 10,000 by Fisher's exact two-sided test:
  consistent (not shown) if p >= 0.05, not reproduced if p < 0.05. The counts are printed, with the
  smallest k the test could tell from 0 (about 6 of 10,000: rates below a few in 10^4 cannot be told
  apart with N = 10,000).
* **bound** ("below B") -- reproduced if our upper 95 % limit is below B; not reproduced if our lower
  limit is at or above B; else consistent (not shown).
* **category** (an FAA likelihood band) -- reproduced if our whole CI lies in the band (a boundary
  belongs to the more frequent band); not reproduced if it lies wholly outside; else consistent (not
  shown).
* **ordering** ("X has the fewest / most / more than Y") -- each pair tested over the encounters both
  groups flew (exact McNemar for encounter events, a paired-bootstrap test of the difference
  otherwise), the p-values of all pairs of all orderings from one table or figure corrected together
  by Holm's method: reproduced if every pair is significant in the stated direction; not reproduced if
  any is significant the other way; else consistent (not shown).
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
from daa_sil.study.analysis import Study
from daa_sil.study.counting import COUNT_SOURCES
from daa_sil.study.findings import (BY_CONSTRUCTION, CONSISTENT, DIRECTION, EVENT_COLUMNS, NOT_REPRODUCED,
                                    NOT_TESTABLE, REPRODUCED, Finding, fmt, load_findings)
from daa_sil.study.metrics import Estimate, faa_category, paper_results
from daa_sil.study.stats import Sample, clopper_pearson, zero_upper_bounds

RULES = {
    "value": "reproduced if the paper's value is inside our 95 % CI; otherwise not reproduced",
    "change": "reproduced if the paper's value is inside our 95 % CI; direction holds if not, but the sign is "
              "the paper's and our CI excludes 0; otherwise not reproduced",
    "equivalence": "two one-sided tests at 5 % against the margin stated in paper_findings.yaml: reproduced if our "
                   "90 % CI lies inside ±margin; not reproduced if our 95 % CI lies wholly outside it; otherwise "
                   "consistent (not shown)",
    "zero": "reproduced if we observe none (exact upper bounds stated); otherwise Fisher's exact two-sided test of our "
            "k of n encounters against the paper's 0 of 10,000: consistent (not shown) if p ≥ 0.05, not reproduced if "
            "p < 0.05 (with N = 10,000 the test cannot tell rates below a few in 10⁴ from 0; counts shown)",
    "bound": "reproduced if our upper 95 % limit is below the bound; not reproduced if our lower limit is at or "
             "above it; otherwise consistent (not shown)",
    "category": "reproduced if our whole 95 % CI lies inside the band; not reproduced if it lies wholly outside; "
                "otherwise consistent (not shown)",
    "ordering": "each pair over the same encounters (exact McNemar for LoWC / NMAC encounters, paired-bootstrap test "
                "of the difference otherwise), the p-values of all pairs of the orderings of one table or figure "
                "Holm-corrected together: reproduced if every pair is significant in the stated direction; not "
                "reproduced if any is significant the other way; otherwise consistent (not shown)",
    "by construction": "a check the code makes true whatever the data (why: in paper_findings.yaml): its kind's "
                       "rule is applied; by construction if it holds (counted apart from the empirical findings), "
                       "not reproduced if it fails (a defect)",
}


@dataclass(frozen=True)
class Outcome:
    """One finding under one reading: our value and interval (as text and numbers), the verdict
    and the evidence for it."""

    verdict: str
    text: str
    evidence: str = ""
    value: float = math.nan
    lo: float = math.nan
    hi: float = math.nan

    @property
    def has_interval(self) -> bool:
        return math.isfinite(self.lo) or math.isfinite(self.hi)


# --- statistics the rules need --------------------------------------------------------------------
def holm(pvalues) -> np.ndarray:
    """Holm-adjusted p-values (step-down, monotone, capped at 1), in the input order."""
    p = np.asarray(pvalues, float)
    m = p.size
    if m == 0:
        return p
    order = np.argsort(p, kind="stable")
    adj = np.minimum(1.0, np.maximum.accumulate((m - np.arange(m)) * p[order]))
    out = np.empty(m)
    out[order] = adj
    return out


def bootstrap_p(smp: Sample) -> float:
    """Two-sided paired-bootstrap p-value of "the difference is 0": twice the smaller share of
    resamples on either side of 0 (at least 1 / (B + 1))."""
    r = smp.reps[np.isfinite(smp.reps)]
    if r.size == 0 or not math.isfinite(smp.value):
        return math.nan
    tail = min(np.count_nonzero(r <= 0), np.count_nonzero(r >= 0))
    return float(min(1.0, max(2.0 * tail / r.size, 1.0 / (r.size + 1))))


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


def _evaluate(f: Finding, st: Study, holm_p) -> Outcome:
    missing = [g for g in f.groups_needed if g not in st.groups]
    if f.kind == "ordering":
        return _ordering(f, st, missing, holm_p)
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
        if est.lo <= p <= est.hi:
            return Outcome(REPRODUCED, txt, ev, **res)
        if f.kind == "change" and p != 0 and np.sign(est.value) == np.sign(p) and (est.lo > 0 or est.hi < 0):
            return Outcome(DIRECTION, txt, ev, **res)
        return Outcome(NOT_REPRODUCED, txt, ev, **res)
    if f.kind == "equivalence":
        return _equivalence(f, st, est, txt)
    if f.kind == "bound":
        b = float(f.bound)
        verdict = REPRODUCED if est.hi < b else (NOT_REPRODUCED if est.lo >= b else CONSISTENT)
        return Outcome(verdict, txt, ev, **res)
    if f.kind == "category":
        lo_b, hi_b = paper_results()["faa_likelihood"][f.category]
        inside = est.lo >= lo_b and est.hi < hi_b
        outside = est.hi < lo_b or est.lo >= hi_b
        ev = f"CI from {faa_category(est.lo)} to {faa_category(est.hi)}" + (f"; {ev}" if ev else "")
        return Outcome(REPRODUCED if inside else (NOT_REPRODUCED if outside else CONSISTENT), txt, ev, **res)
    raise FileFormatError(f"finding {f.id}: unknown kind {f.kind!r}")


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


def _equivalence(f: Finding, st: Study, est: Estimate, txt: str) -> Outcome:
    m = float(f.margin)
    lo90, hi90 = _change_sample(f, st).interval(1.0 - 2.0 * (1.0 - st.conf))
    res = dict(value=est.value, lo=est.lo, hi=est.hi)
    ev = (f"90 % CI [{fmt(lo90, 'pctv')}, {fmt(hi90, 'pctv')}] against the margin ±{m:g} % ({f.margin_reason})")
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
    e = st.per_enc[f.group]
    ok = e["present"] > 0
    k = float(e[col][ok].sum())
    n = int(ok.sum())
    k_enc = int(np.count_nonzero(e[col][ok] > 0))
    if k == 0:
        one, two = zero_upper_bounds(n, st.conf)
        return Outcome(REPRODUCED,
                       f"0 of {n:,} enc. (share ≤ {fmt(one, 'pct2')} one-sided, ≤ {fmt(two, 'pct2')} two-sided)",
                       f"exact upper bounds on the share of encounters with one: {one:.3g} (one-sided "
                       f"{100 * st.conf:.0f} %), {two:.3g} (upper limit of the two-sided interval)",
                       0.0, 0.0, two)
    n_paper = int(paper_results().get("encounters_per_group", 10000))
    alpha = 1.0 - st.conf
    p, k_min = zero_test(k_enc, n, n_paper, alpha)
    lo, hi = clopper_pearson(k_enc, n, st.conf)
    verdict = NOT_REPRODUCED if p < alpha else CONSISTENT
    return Outcome(verdict, f"{fmt(k, 'int')} in {k_enc:,} of {n:,} enc. [{fmt(lo, 'pct')}, {fmt(hi, 'pct')}]",
                   f"{k_enc} of {n:,} encounters vs the paper's 0 of {n_paper:,}: Fisher's exact two-sided p = "
                   f"{p:.2g}; the test reaches p < {alpha:g} only from {k_min} encounters (Clopper-Pearson interval of "
                   f"our share in brackets)", float(k), lo, hi)


# --- orderings ------------------------------------------------------------------------------------
def ordering_pairs(f: Finding, st: Study) -> list[dict]:
    """Each pair of an ordering: ``{group, value (subject minus other), p, text}`` over the encounters
    both flew (groups not in the study are left out)."""
    o = f.ordering
    subj = o["subject"]
    out = []
    event = EVENT_COLUMNS.get(f.metric)
    for g in (x for x in o["others"] if x in st.groups):
        if event:
            m = st.mcnemar(subj, g, event)
            val = float(m.a_only - m.b_only)
            out.append({"group": g, "value": val, "p": float(m.p_value),
                        "text": f"vs {g}: {int(val):+d} enc. ({m.a_only}/{m.b_only} discordant, McNemar p = "
                                f"{m.p_value:.2g}"})
        else:
            smp = st.change_sample(subj, f.metric, g, "difference")
            lo, hi = smp.interval(st.conf)
            out.append({"group": g, "value": float(smp.value), "p": bootstrap_p(smp),
                        "text": f"vs {g}: {fmt(smp.value)} [{fmt(lo)}, {fmt(hi)}] per enc. (paired-bootstrap p = "
                                f"{bootstrap_p(smp):.2g}"})
    return out


def _ordering(f: Finding, st: Study, missing, holm_p) -> Outcome:
    o = f.ordering
    if o["subject"] in missing:
        return Outcome(NOT_TESTABLE, "–", f"group {o['subject']} not in this reading")
    pairs = ordering_pairs(f, st)
    if not pairs:
        return Outcome(NOT_TESTABLE, "–", f"none of {', '.join(o['others'])} in this reading")
    if holm_p is None:
        adj = holm([p["p"] for p in pairs])
        holm_p = {(f.id, p["group"]): a for p, a in zip(pairs, adj)}
    sign = -1.0 if o["relation"] == "fewest" else 1.0
    alpha = 1.0 - st.conf
    status, parts = [], []
    for p in pairs:
        a = holm_p[(f.id, p["group"])]
        parts.append(f"{p['text']}, Holm {a:.2g})")
        if not (math.isfinite(a) and a < alpha) or p["value"] == 0:
            status.append("open")
        elif np.sign(p["value"]) == sign:
            status.append("holds")
        else:
            status.append("contradicted")
    verdict = (NOT_REPRODUCED if "contradicted" in status
               else REPRODUCED if all(s == "holds" for s in status) else CONSISTENT)
    ev = "; ".join(parts) + (f"; not run: {', '.join(missing)}" if missing else "")
    return Outcome(verdict, "; ".join(parts), ev)


def evaluate_all(studies: dict) -> list[tuple[Finding, dict]]:
    """``[(finding, {reading label: Outcome})]`` for every finding; the ordering pairs of one source
    (table or figure) are Holm-corrected together within each reading."""
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
        for f, outs in rows:
            outs[label] = evaluate(f, st, holm_p if f.kind == "ordering" else None)
    return rows


def tally(rows, label: str) -> dict:
    """Verdict counts of one reading: ``{verdict: n}`` over the findings with a verdict (the
    headline counts only the empirical verdicts; :data:`daa_sil.study.findings.EMPIRICAL`)."""
    from daa_sil.study.findings import VERDICTS

    return {v: sum(1 for _, o in rows if o[label].verdict == v) for v in VERDICTS + (NOT_TESTABLE,)}


__all__ = ["RULES", "Outcome", "evaluate", "evaluate_all", "ordering_pairs", "finding_sample", "holm", "bootstrap_p",
           "zero_test", "tally"]
