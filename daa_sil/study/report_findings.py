"""What each verdict word of the report means, whatever the kind of finding (the kinds' rules are
:data:`daa_sil.study.verdicts.RULES`; the report prints both)."""

from __future__ import annotations

from daa_sil.study.findings import (BY_CONSTRUCTION, CONSISTENT, DIRECTION, INPUT, NESTED, NOT_REPRODUCED, REPRODUCED,
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

__all__ = ["VERDICT_MEANING"]
