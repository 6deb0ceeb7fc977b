"""The ordering rule of the verdicts (:mod:`daa_sil.study.analysis.verdicts`): "X has the fewest / most / more than
Y", each pair over the encounters both groups flew, Holm-corrected per source, and -- where the paper
gives both values -- at the paper's size."""

from __future__ import annotations

import math

import numpy as np

from daa_sil.study.analysis.study import Study
from daa_sil.study.analysis.comparison import n_paper, standard_error, two_sample
from daa_sil.study.analysis.findings import (CONSISTENT, DIRECTION, EVENT_COLUMNS, NOT_REPRODUCED, NOT_TESTABLE, REPRODUCED,
                                    Finding, fmt, paper_group_value)
from daa_sil.study.analysis.outcome import Outcome
from daa_sil.study.analysis.stats import Sample


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


def ordering(f: Finding, st: Study, missing, holm_p) -> Outcome:
    """The verdict of an ordering finding (``holm_p``: Holm-adjusted p-values by ``(id, pair group)``)."""
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
    if verdict == REPRODUCED and f.size:  # the relation holds: at the paper's size?
        for p in pairs:
            paper_d = paper_group_value(f.size, o["subject"]) - paper_group_value(f.size, p["group"])
            smp = st.change_sample(o["subject"], f.metric, p["group"], "difference")
            n_o = float(min(st.n_encounters(o["subject"]), st.n_encounters(p["group"])))
            two = two_sample(smp.value, standard_error(smp.reps), paper_d, n_o, n_paper(), st.conf)
            parts.append(f"vs {p['group']} at the paper's size {fmt(paper_d)} per enc.: "
                         + two.text(lambda x: fmt(x)))
            if not two.matches:
                verdict = DIRECTION
                parts.append(f"the relation holds at {fmt(smp.value)} per encounter against the paper's "
                             f"{fmt(paper_d)} ({fmt(smp.value / paper_d if paper_d else math.nan)}×): not the "
                             f"paper's size")
    ev = "; ".join(parts) + (f"; not run: {', '.join(missing)}" if missing else "")
    return Outcome(verdict, "; ".join(parts), ev)




__all__ = ["holm", "bootstrap_p", "ordering_pairs", "ordering"]
