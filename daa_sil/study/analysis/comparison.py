"""Two samples, ours and the paper's: the statistics the verdict rules (:mod:`daa_sil.study.analysis.verdicts`)
compare the paper's numbers with.

The paper's numbers are estimates from its own 10,000 encounters per group, with their own Monte
Carlo error, which the paper does not report. We estimate it from **our** per-encounter variance at
the paper's N: a statistic whose standard error is ``se`` over our ``n`` encounters has about
``se * sqrt(n / N_paper)`` over the paper's ``N_paper`` (every statistic here is a mean or a ratio of
means over encounters, whose variance falls as 1/N). Then:

* :func:`two_sample` -- the difference ours minus the paper's, with the interval
  ``d ± z sqrt(se_ours² + se_paper²)``: the paper's value is matched when that interval includes 0
  (not when it falls inside our interval, which narrows as our N grows while the paper's error stays);
* :func:`accepted_range` -- the values an estimate of ours could take and still match the paper's
  number; a check whose pass region reaches beyond it (an FAA band two decades wide) passes values the
  paper's number rules out: it is *uninformative*;
* :func:`detectable_difference` -- the smallest difference the paper's study could detect (two-sided
  5 %, 80 % power), from the standard error of a paired difference at the paper's N: the equivalence
  margin of a "no change" claim (a study cannot call "almost the same" a difference it could not see).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.stats import norm

#: encounters per group of the paper's study (paper_results.yaml ``encounters_per_group``)
PAPER_N_DEFAULT = 10_000
#: the power of the paper's study at its detectable difference
POWER = 0.8


def n_paper() -> int:
    """Encounters per group of the paper's study (``paper_results.yaml``)."""
    from daa_sil.study.analysis.metrics import paper_results  # lazy: start-up time

    return int(paper_results().get("encounters_per_group", PAPER_N_DEFAULT))


def standard_error(reps: np.ndarray) -> float:
    """Standard error of a statistic from its bootstrap replicates (nan when fewer than two are finite)."""
    r = np.asarray(reps, float)
    r = r[np.isfinite(r)]
    return float(np.std(r, ddof=1)) if r.size > 1 else math.nan


def paper_se(se_ours: float, n_ours: float, n_paper: float = PAPER_N_DEFAULT) -> float:
    """The paper's standard error of the same statistic at its ``n_paper`` encounters (per group)."""
    if not (n_ours > 0 and n_paper > 0):
        return math.nan
    return float(se_ours) * math.sqrt(float(n_ours) / float(n_paper))


@dataclass(frozen=True)
class TwoSample:
    """Ours minus the paper's: the difference ``diff`` and its interval ``[lo, hi]``, from our standard
    error ``se_ours`` and the paper's ``se_paper`` (estimated at its N)."""

    diff: float
    lo: float
    hi: float
    se_ours: float
    se_paper: float

    @property
    def matches(self) -> bool:
        """The interval of the difference includes 0."""
        return math.isfinite(self.lo) and self.lo <= 0.0 <= self.hi

    def text(self, fmt) -> str:
        se = lambda x: fmt(x).lstrip("+")  # noqa: E731 -- a standard error carries no sign
        return (f"ours − paper {fmt(self.diff)} [{fmt(self.lo)}, {fmt(self.hi)}] (SE ours {se(self.se_ours)}, "
                f"the paper's at its N {se(self.se_paper)})")


def two_sample(value: float, se_ours: float, paper: float, n_ours: float, n_paper: float = PAPER_N_DEFAULT,
               conf: float = 0.95) -> TwoSample:
    """The difference ``value - paper`` with its ``conf`` interval, both samples' errors combined."""
    sp = paper_se(se_ours, n_ours, n_paper)
    z = float(norm.ppf(0.5 + conf / 2.0))
    half = z * math.hypot(se_ours, sp) if math.isfinite(se_ours) and math.isfinite(sp) else math.nan
    d = float(value) - float(paper)
    return TwoSample(d, d - half, d + half, float(se_ours), sp)


def accepted_range(paper: float, se_ours: float, n_ours: float, n_paper: float = PAPER_N_DEFAULT,
                   conf: float = 0.95) -> tuple[float, float]:
    """The estimates of ours that :func:`two_sample` would find matching the paper's number."""
    t = two_sample(paper, se_ours, paper, n_ours, n_paper, conf)
    return float(paper) + t.lo, float(paper) + t.hi


def wider_than(band: tuple, accepted: tuple) -> bool:
    """True when a check's pass region ``band`` (lo, hi) reaches beyond ``accepted`` on either side: it
    passes values the paper's own number rules out (an uninformative check)."""
    lo_b, hi_b = band
    lo_a, hi_a = accepted
    if not (math.isfinite(lo_a) and math.isfinite(hi_a)):
        return False
    return lo_b < lo_a or hi_b > hi_a


def detectable_difference(se_diff_ours: float, n_ours: float, n_paper: float = PAPER_N_DEFAULT,
                          conf: float = 0.95, power: float = POWER) -> float:
    """The smallest difference a paired comparison in the paper's study could detect (two-sided
    ``1 - conf``, ``power``): ``(z_{1-α/2} + z_power) * se`` of the difference at the paper's N."""
    se = paper_se(se_diff_ours, n_ours, n_paper)
    return float((norm.ppf(0.5 + conf / 2.0) + norm.ppf(power)) * se)


__all__ = ["n_paper", "standard_error", "paper_se", "TwoSample", "two_sample", "accepted_range", "wider_than",
           "detectable_difference", "PAPER_N_DEFAULT", "POWER"]
