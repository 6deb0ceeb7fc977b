"""The report's findings section: every finding of the paper with our value, its 95 % CI and the
verdict under each reading; the headline tally (empirical findings only), the checks true by
construction counted apart, and the rule behind each verdict word."""

from __future__ import annotations

from typing import Sequence

from daa_sil.study.findings import (BY_CONSTRUCTION, CONSISTENT, DIRECTION, EMPIRICAL, NOT_REPRODUCED, NOT_TESTABLE,
                                    REPRODUCED, untestable_statements)
from daa_sil.study.report_format import markdown_table
from daa_sil.study.verdicts import RULES, tally

#: what each verdict word means, whatever the kind of finding (the kinds' rules follow in the report)
VERDICT_MEANING = {
    REPRODUCED: "our data show the finding: the paper's value inside our 95 % CI, or the bound, band, ordering or "
                "equivalence shown, or no event observed",
    CONSISTENT: "our data neither show nor contradict it: a CI straddling the bound, the band's edge or the "
                "equivalence margin; events the exact test cannot tell from the paper's 0; an ordering not "
                "significant after Holm's correction",
    DIRECTION: "a change with the paper's sign and a CI excluding 0, but not the paper's size",
    NOT_REPRODUCED: "our data contradict the finding",
    BY_CONSTRUCTION: "true whatever the data (the code makes it so; why is stated); counted apart from the empirical "
                     "findings, and a failure would be a defect",
}


def findings_section(blocks: Sequence, rows) -> list[str]:
    """Markdown lines of the findings table, the tallies and the rules."""
    labels = [b.label for b in blocks]
    header = ["#", "finding", "source", "kind", "paper"]
    for lab in labels:
        header += [f"{lab}: ours [95 % CI]", f"{lab}: verdict"]
    body = []
    for i, (f, outs) in enumerate(rows, 1):
        kind = f"{f.kind} (by construction)" if f.by_construction else f.kind
        r = [str(i), f.label, f.source, kind, f.paper_text()]
        for lab in labels:
            o = outs[lab]
            verdict = f"**{o.verdict}**" if o.verdict != NOT_TESTABLE else f"{o.verdict} ({o.evidence})"
            r += [o.text, verdict]
        body.append(r)
    L = ["## Findings of the paper under each reading", "",
         "Every finding the paper states (`daa_sil/data/paper_findings.yaml`), our value with its encounter-level "
         "95 % confidence interval, and the verdict of its kind's rule (below). Counts are per encounter (the "
         "paper's totals divided by its 10,000 encounters); changes in %.", "", markdown_table(header, body), ""]
    summ = []
    for lab in labels:
        c = tally(rows, lab)
        n_emp = sum(c[v] for v in EMPIRICAL)
        summ.append([lab, str(n_emp)] + [str(c[v]) for v in EMPIRICAL] + [str(c[BY_CONSTRUCTION]),
                                                                          str(c[NOT_TESTABLE])])
    L += ["**Headline tally: empirical findings only.** Checks true by construction are counted apart; *not "
          "testable* means a group the finding needs was not run.", "",
          markdown_table(["reading", "empirical findings"] + list(EMPIRICAL) + [BY_CONSTRUCTION, NOT_TESTABLE], summ), ""]
    L += ["### Verdict words", ""]
    L += [f"- **{k}**: {v}." for k, v in VERDICT_MEANING.items()]
    L += ["- *not testable* is no verdict: a group the finding needs was not run in that reading, or its statistic "
          "is undefined there (reason given).", "",
          "### Verdict rules (one per kind of finding; 95 % throughout; the only other number, an equivalence "
          "margin, is stated with its reason)", ""]
    L += [f"- **{k}**: {v}." for k, v in RULES.items()]
    L.append("")
    un = untestable_statements()
    if un:
        L += ["Statements of the paper without a quantity to test (no verdict):", ""]
        L += [f"- \"{u['claim']}\" — {u['why']}" for u in un]
        L.append("")
    return L


__all__ = ["findings_section", "VERDICT_MEANING"]
