"""What each verdict word of the report means, whatever the kind of finding (the kinds' rules are
:data:`daa_sil.study.analysis.verdicts.RULES`; the report prints both), and the compact form of ``findings.json``."""

from __future__ import annotations

import json
import math

from daa_sil.study.analysis.findings import (BY_CONSTRUCTION, CONSISTENT, DIRECTION, INPUT, NESTED, NOT_REPRODUCED, REPRODUCED,
                                    UNINFORMATIVE)

#: what each verdict word means; the first four are the empirical verdicts of the headline tally, the
#: others are counted apart
VERDICT_MEANING = {
    REPRODUCED: "our data show the finding: our value and the paper's agree as two samples (the interval of the "
                "difference includes 0), or the bound, band, ordering or equivalence is shown, or no event is "
                "observed",
    CONSISTENT: "our data neither show nor contradict it: a CI straddling the bound, the band's edge or the "
                "equivalence margin; events the exact test cannot tell from the paper's 0; an ordering not "
                "significant after Holm's correction",
    DIRECTION: "a change or an ordering with the paper's sign, significant, but not the paper's size",
    NOT_REPRODUCED: "our data contradict the finding",
    BY_CONSTRUCTION: "true whatever the data (the code makes it so; why is stated); counted apart from the empirical "
                     "findings, and a failure would be a defect",
    UNINFORMATIVE: "a check that values the paper's own number rules out would also pass (an FAA band two decades "
                   "wide); counted apart, whatever it shows, unless it fails",
    NESTED: "a claim implied by another (no PI above 10 when the maximum is 3.79) and tested with it: counted once, "
            "under the other",
    INPUT: "a published number a setting of the reading was inferred from (campaign.json 'basis'), which our data "
           "match: never a reproduction, so counted apart (missed anyway, it counts as not reproduced)",
}

#: significant digits a float keeps in ``findings.json`` (the pages print three; integers stay exact)
JSON_DIGITS = 6


def rounded(x):
    """``x`` (JSON-able) with every non-integral float kept to :data:`JSON_DIGITS` significant digits."""
    if isinstance(x, float):
        return x if x.is_integer() or not math.isfinite(x) else float(f"{x:.{JSON_DIGITS}g}")
    if isinstance(x, dict):
        return {k: rounded(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [rounded(v) for v in x]
    return x


def basis_changes(basis: "list | None", reference: "list | None") -> "list | None":
    """The rows of a reading's ``basis`` that differ from the reference reading's (the full rows; the
    others are the reference's, stored once): None without a basis."""
    if basis is None:
        return None
    ref = {json.dumps(r, sort_keys=True) for r in reference or ()}
    return [r for r in basis if json.dumps(r, sort_keys=True) not in ref]


__all__ = ["VERDICT_MEANING", "JSON_DIGITS", "rounded", "basis_changes"]
