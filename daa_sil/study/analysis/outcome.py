"""One finding's outcome under one reading (:class:`Outcome`): the verdict (:mod:`daa_sil.study.analysis.findings`
words), our value and interval as text and numbers, and the evidence for the verdict."""

from __future__ import annotations

import math
from dataclasses import dataclass


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


__all__ = ["Outcome"]
