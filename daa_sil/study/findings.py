"""The paper's findings (``daa_sil/data/paper_findings.yaml``) and the verdict rules that test them
on a :class:`daa_sil.study.analysis.Study`. Every rule can come out "no"; none has a hand-set threshold
(the only level is the report's confidence level, 95 %, used for every interval and test).

Rules, one per kind of finding (the report prints them):

* **value** -- *reproduced* when the paper's value lies inside our 95 % CI, else *not reproduced*.
* **change** (a reduction, an increase) -- *reproduced* when the paper's value lies inside our 95 %
  CI; *direction holds* when it does not, but our change has the paper's sign and our CI excludes
  no change (0); *not reproduced* otherwise.
* **zero** ("none happened") -- *reproduced* when we observe zero, with the exact upper bounds on
  the share of encounters (one-sided and the upper limit of the two-sided interval); *not
  reproduced* when we observe any (count and encounters stated).
* **bound** ("below B") -- *reproduced* when our upper 95 % CI limit is below B, else *not
  reproduced*.
* **category** (an FAA likelihood band) -- *reproduced* when our whole 95 % CI lies inside the band
  (a boundary belongs to the more frequent band), else *not reproduced*.
* **ordering** ("X has the fewest / most / more than Y") -- for each pair, a paired two-sided test
  over the encounters both groups flew at the 5 % level: exact McNemar for encounter events (LoWC),
  the paired-bootstrap 95 % CI of the difference for everything else. *reproduced* when every pair
  is significant in the stated direction (an intersection-union test: no multiplicity correction
  is needed for "all pairs hold"); *not reproduced* when any pair is significant in the opposite
  direction; *not shown* otherwise (no pair contradicts it, not every pair shows it).

A finding is *not testable* only when a group it needs was not run in a reading, or its statistic
is undefined there (e.g. a mean PI with no LoWC encounter); the reason is stated.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache
from importlib import resources

import numpy as np

from daa_sil.errors import FileFormatError
from .metrics import Estimate, faa_category, paper_results
from daa_sil.study.analysis import METRICS, Study
from daa_sil.study.counting import COUNT_SOURCES
from .stats import Sample, clopper_pearson, zero_upper_bounds

REPRODUCED = "reproduced"
DIRECTION = "direction holds"
NOT_REPRODUCED = "not reproduced"
NOT_SHOWN = "not shown"
NOT_TESTABLE = "not testable"
VERDICTS = (REPRODUCED, DIRECTION, NOT_REPRODUCED, NOT_SHOWN, NOT_TESTABLE)
KINDS = ("value", "change", "zero", "bound", "category", "ordering")

RULES = {
    "value": "reproduced if the paper's value is inside our 95 % CI; otherwise not reproduced",
    "change": "reproduced if the paper's value is inside our 95 % CI; direction holds if not, but the sign is "
              "the paper's and our CI excludes 0; otherwise not reproduced",
    "zero": "reproduced if we observe 0 (exact upper bounds on the share of encounters stated); otherwise not "
            "reproduced",
    "bound": "reproduced if our upper 95 % CI limit is below the bound; otherwise not reproduced",
    "category": "reproduced if our whole 95 % CI lies inside the band; otherwise not reproduced",
    "ordering": "each pair tested over the same encounters (exact McNemar for LoWC encounters, paired-bootstrap "
                "95 % CI of the difference otherwise, both two-sided at 5 %): reproduced if every pair is "
                "significant in the stated direction; not reproduced if any pair is significant the other way; "
                "otherwise not shown",
}

#: encounter-event metrics: orderings on these use the exact McNemar test on this per-encounter column
EVENT_COLUMNS = {"p_lowc": "lowc", "n_lowc": "lowc", "p_nmac": "nmac", "n_nmac": "nmac"}
#: how a metric's value is printed (default: 3 significant digits)
FORMATS = {"p_lowc_per_hr_paper_h": "sci", "p_lowc_per_hr": "sci", "lowc_rate_per_hr": "sci", "p_lowc": "pct",
           "exact_match": "pct", "axis_match": "pct", "neither_match": "pct", "lowc_turning_share": "pct",
           "executed_share": "pct", "map_decided_share": "pct", "in_box_share": "pct", "dev_h_mean": "f0",
           "dev_v_mean": "f1", "pi_mean": "f2", "pi_paper_mean": "f2"}


def fmt(x: "float | None", kind: str = "g3") -> str:
    """A number for the report (``–`` for undefined)."""
    if x is None or not isinstance(x, (int, float, np.floating, np.integer)) or not math.isfinite(float(x)):
        return "–"
    x = float(x)
    if kind == "sci":
        return f"{x:.2e}"
    if kind == "pct":
        return f"{100 * x:.1f} %"
    if kind == "pct2":
        return f"{100 * x:.2g} %"
    if kind == "pctv":  # already in percent
        return f"{x:+.1f} %"
    if kind == "int":
        return f"{x:,.0f}"
    if kind == "f0":
        return f"{x:,.0f}"
    if kind == "f1":
        return f"{x:,.1f}"
    if kind == "f2":
        return f"{x:.2f}"
    if x == 0:
        return "0"
    mag = math.floor(math.log10(abs(x)))
    return f"{x:.{max(0, 2 - mag)}f}" if -3 <= mag < 5 else f"{x:.2e}"


@dataclass(frozen=True)
class Finding:
    """One finding of the paper, for one group (``group``) or pooled over ``pooled`` groups."""

    id: str
    claim: str
    source: str
    kind: str
    metric: str
    group: "str | None" = None
    pooled: tuple = ()
    over: tuple = ()
    change: dict = field(default_factory=dict)
    paper: dict = field(default_factory=dict)
    bound: "float | None" = None
    category: "str | None" = None
    ordering: dict = field(default_factory=dict)

    @property
    def label(self) -> str:
        if self.group:
            return f"{self.claim} — {self.group}"
        if self.pooled and self.over:
            return f"{self.claim} — ({', '.join(self.pooled)}) vs ({', '.join(self.over)})"
        if self.pooled:
            return f"{self.claim} — ({', '.join(self.pooled)})"
        return self.claim

    @property
    def groups_needed(self) -> tuple:
        if self.kind == "ordering":
            return (self.ordering["subject"],) + tuple(self.ordering["others"])
        g = (self.group,) if self.group else tuple(self.pooled) + tuple(self.over)
        vs = self.change.get("vs")
        return g + ((vs,) if vs and self.group else ())

    @property
    def value_format(self) -> str:
        if self.kind == "change":
            return "pctv"
        return FORMATS.get(self.metric, "g3")

    # --- the paper's side -----------------------------------------------------------------------
    def paper_value(self) -> "float | None":
        """The paper's number in the unit of our statistic (None for zeros and orderings)."""
        p = self.paper
        if not p:
            return None
        if "value" in p:
            return float(p["value"])
        pr = paper_results()
        if p.get("derive") == "pooled_ratio":
            a = np.mean([_lookup(pr, p["key"], g) for g in self.pooled])
            b = np.mean([_lookup(pr, p["key"], g) for g in self.over])
            return float(100.0 * (a / b - 1.0))
        v = _lookup(pr, p["key"], self.group)
        if p.get("per_encounter"):
            v /= float(pr.get("encounters_per_group", 10000))
        return float(v) * float(p.get("scale", 1.0))

    def paper_text(self) -> str:
        if self.kind == "zero":
            return "0"
        if self.kind == "bound":
            return f"< {fmt(self.bound)}"
        if self.kind == "category":
            lo, hi = paper_results()["faa_likelihood"][self.category]
            return f"{self.category} [{lo:.0e}, {hi:.0e})"
        if self.kind == "ordering":
            o = self.ordering
            rel = {"fewest": "fewest of", "most": "most of", "more": "more than"}[o["relation"]]
            return f"{o['subject']} {rel} {', '.join(o['others'])}"
        return fmt(self.paper_value(), self.value_format)


def _lookup(pr: dict, key: str, group: "str | None") -> float:
    node = pr
    for part in key.replace("{group}", group or "").split("."):
        if not isinstance(node, dict) or part not in node:
            raise FileFormatError(f"paper_findings.yaml: paper_results.yaml has no {key!r} (for group {group})")
        node = node[part]
    return float(node)


@lru_cache(maxsize=1)
def _raw() -> dict:
    from daa_sil.config.yaml_input import load_yaml

    text = resources.files("daa_sil").joinpath("data/paper_findings.yaml").read_text(encoding="utf-8")
    return load_yaml(text, "daa_sil/data/paper_findings.yaml", "list of the paper's findings")


def load_findings() -> list[Finding]:
    """Every finding, expanded to one per group (pooled findings stay one)."""
    out = []
    for f in _raw()["findings"]:
        if f["kind"] not in KINDS:
            raise FileFormatError(f"paper_findings.yaml: {f['id']}: unknown kind {f['kind']!r}; "
                                  f"allowed: {', '.join(KINDS)}")
        if f["metric"] not in METRICS:
            raise FileFormatError(f"paper_findings.yaml: {f['id']}: unknown metric {f['metric']!r}")
        base = dict(id=f["id"], claim=f["claim"], source=f.get("source", ""), kind=f["kind"], metric=f["metric"],
                    change=dict(f.get("change", {})), paper=dict(f.get("paper", {})), bound=f.get("bound"),
                    category=f.get("category"), ordering=dict(f.get("ordering", {})))
        if "groups" in f:
            out += [Finding(**base, group=g) for g in f["groups"]]
        elif "pooled" in f:
            out.append(Finding(**base, pooled=tuple(f["pooled"]["groups"]), over=tuple(f["pooled"].get("over", ()))))
        else:
            out.append(Finding(**base))
    return out


def untestable_statements() -> list[dict]:
    return list(_raw().get("untestable", []))


# --- evaluation -------------------------------------------------------------------------------------
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


def evaluate(f: Finding, st: Study) -> Outcome:
    """The verdict of finding ``f`` on study ``st`` (see the module docstring)."""
    missing = [g for g in f.groups_needed if g not in st.groups]
    if f.kind == "ordering":
        return _ordering(f, st, missing)
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
    if f.kind in ("value", "change"):
        p = f.paper_value()
        inside = est.lo <= p <= est.hi
        if inside:
            return Outcome(REPRODUCED, txt, ev, est.value, est.lo, est.hi)
        if f.kind == "change" and p != 0 and np.sign(est.value) == np.sign(p) and (est.lo > 0 or est.hi < 0):
            return Outcome(DIRECTION, txt, ev, est.value, est.lo, est.hi)
        return Outcome(NOT_REPRODUCED, txt, ev, est.value, est.lo, est.hi)
    if f.kind == "bound":
        ok = math.isfinite(est.hi) and est.hi < float(f.bound)
        return Outcome(REPRODUCED if ok else NOT_REPRODUCED, txt, ev, est.value, est.lo, est.hi)
    if f.kind == "category":
        lo_b, hi_b = paper_results()["faa_likelihood"][f.category]
        ok = est.lo >= lo_b and est.hi < hi_b
        ev = f"CI from {faa_category(est.lo)} to {faa_category(est.hi)}" + (f"; {ev}" if ev else "")
        return Outcome(REPRODUCED if ok else NOT_REPRODUCED, txt, ev, est.value, est.lo, est.hi)
    raise FileFormatError(f"finding {f.id}: unknown kind {f.kind!r}")


def _estimate(f: Finding, st: Study) -> Estimate:
    if f.kind == "change":
        ck = f.change.get("kind", "ratio")
        if f.group:
            return st.change(f.group, f.metric, f.change["vs"], ck)
        smp = st.pooled_change_sample(f.metric, f.pooled, f.over, "reduction" if ck == "reduction" else "ratio")
        return st._boot_estimate(smp, "paired bootstrap of the pooled means")
    if f.group:
        return st.estimate(f.group, f.metric)
    smp = _pooled_mean(st, f.metric, f.pooled)
    return st._boot_estimate(smp, f"mean over {', '.join(f.pooled)} (paired bootstrap)")


def _pooled_mean(st: Study, metric: str, groups) -> Sample:
    samples = [st.sample(g, metric) for g in groups]
    return sum(samples[1:], samples[0]) / len(samples)


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
    g = f.group
    e = st.per_enc[g]
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
    lo, hi = clopper_pearson(k_enc, n, st.conf)
    return Outcome(NOT_REPRODUCED, f"{fmt(k, 'int')} in {k_enc:,} of {n:,} enc. [{fmt(lo, 'pct')}, {fmt(hi, 'pct')}]",
                   f"share of encounters {fmt(k_enc / n, 'pct')} (Clopper-Pearson)", k, lo, hi)


def _ordering(f: Finding, st: Study, missing) -> Outcome:
    o = f.ordering
    subj = o["subject"]
    if subj in missing:
        return Outcome(NOT_TESTABLE, "–", f"group {subj} not in this reading")
    others = [g for g in o["others"] if g not in missing]
    if not others:
        return Outcome(NOT_TESTABLE, "–", f"none of {', '.join(o['others'])} in this reading")
    # the subject must be below (fewest) or above (most / more) every other group
    sign = -1.0 if o["relation"] == "fewest" else 1.0
    alpha = 1.0 - st.conf
    parts, status = [], []
    event = EVENT_COLUMNS.get(f.metric)
    for g in others:
        if event:
            m = st.mcnemar(subj, g, event)
            diff = m.a_only - m.b_only
            sig = m.p_value < alpha
            parts.append(f"vs {g}: {diff:+d} enc. ({m.a_only}/{m.b_only} discordant, McNemar p = {m.p_value:.2g})")
            val = float(diff)
        else:
            est = st._boot_estimate(st.change_sample(subj, f.metric, g, "difference"), "paired bootstrap difference")
            sig = math.isfinite(est.lo) and (est.lo > 0 or est.hi < 0)
            val = est.value
            parts.append(f"vs {g}: {fmt(est.value)} [{fmt(est.lo)}, {fmt(est.hi)}] per enc.")
        if not math.isfinite(val) or val == 0 or not sig:
            status.append("open")
        elif np.sign(val) == sign:
            status.append("holds")
        else:
            status.append("contradicted")
    if "contradicted" in status:
        verdict = NOT_REPRODUCED
    elif all(s == "holds" for s in status):
        verdict = REPRODUCED
    else:
        verdict = NOT_SHOWN
    ev = "; ".join(parts) + (f"; not run: {', '.join(missing)}" if missing else "")
    return Outcome(verdict, "; ".join(parts), ev)


def evaluate_all(studies: dict) -> list[tuple[Finding, dict]]:
    """``[(finding, {reading name: Outcome})]`` for every finding, over the studies of each reading."""
    return [(f, {name: evaluate(f, st) for name, st in studies.items()}) for f in load_findings()]


__all__ = ["Finding", "Outcome", "load_findings", "untestable_statements", "evaluate", "evaluate_all", "RULES",
           "VERDICTS", "KINDS", "REPRODUCED", "DIRECTION", "NOT_REPRODUCED", "NOT_SHOWN", "NOT_TESTABLE", "fmt"]
