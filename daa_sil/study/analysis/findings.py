"""The paper's findings (``daa_sil/data/paper_findings.yaml``) as data: :class:`Finding` (what the
paper states, its value in the unit of our statistic) and the verdict words. The rules that give a
verdict on our runs are in :mod:`daa_sil.study.analysis.verdicts`.

The verdict words, everywhere (the report prints each rule):

* **reproduced** -- our data show the paper's finding: our value and the paper's agree as two samples
  (the interval of their difference, with the paper's error estimated at its N, includes 0), or the
  bound, band, ordering (at the paper's size where it gives one) or equivalence is shown, or zero
  observed;
* **consistent (not shown)** -- our data do not contradict the finding but do not show it either
  (a CI straddling the bound, the band's edge or the equivalence margin; a count the exact test
  cannot tell from the paper's 0; an ordering not significant after Holm's correction);
* **direction holds** -- a change with the paper's sign, our CI excluding 0, but not the paper's size;
  or an ordering that holds at a size the paper's numbers rule out;
* **not reproduced** -- our data contradict the finding;
* **by construction** -- a check the code makes true whatever the data (counted apart from the
  empirical findings; if it ever fails, it is *not reproduced*: a defect);
* **uninformative** -- a check whose pass region holds values the paper's own number for the same
  statistic rules out (the FAA 'Remote' band, two decades wide): passing it shows nothing, so it is
  counted apart (failing it is still *not reproduced*);
* **nested** -- a claim implied by another that is tested with it (one claim, counted once: under the
  other);
* **input** -- a published number a setting of the reading was inferred from (``daa_sil.config.basis``):
  agreeing with it is no reproduction, so it is counted apart.

*not testable* is no verdict: a group the finding needs was not run, or its statistic is undefined.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache
from importlib import resources

import numpy as np

from daa_sil.errors import FileFormatError
from daa_sil.study.analysis.study import METRICS
from daa_sil.study.analysis.metrics import paper_results

REPRODUCED = "reproduced"
CONSISTENT = "consistent (not shown)"
DIRECTION = "direction holds"
NOT_REPRODUCED = "not reproduced"
BY_CONSTRUCTION = "by construction"
UNINFORMATIVE = "uninformative"
NESTED = "nested"
INPUT = "input"
#: the verdict words, in the report's order
VERDICTS = (REPRODUCED, CONSISTENT, DIRECTION, NOT_REPRODUCED, BY_CONSTRUCTION, UNINFORMATIVE, NESTED, INPUT)
#: the verdicts counted apart from the empirical findings
APART = (BY_CONSTRUCTION, UNINFORMATIVE, NESTED, INPUT)
#: the empirical verdicts: the headline tally counts only these
EMPIRICAL = (REPRODUCED, CONSISTENT, DIRECTION, NOT_REPRODUCED)
#: no verdict: a group the finding needs was not run, or its statistic is undefined
NOT_TESTABLE = "not testable"
KINDS = ("value", "change", "equivalence", "zero", "bound", "category", "ordering")

#: encounter-event metrics: orderings on these use the exact McNemar test on this per-encounter column
EVENT_COLUMNS = {"p_lowc": "lowc", "n_lowc": "lowc", "p_nmac": "nmac", "n_nmac": "nmac"}
#: how a metric's value is printed (default: 3 significant digits)
FORMATS = {"p_lowc_per_hr_paper_h": "sci", "p_lowc_per_hr": "sci", "lowc_rate_per_hr": "sci", "p_lowc": "pct",
           "exact_match": "pct", "axis_match": "pct", "neither_match": "pct", "lowc_turning_share": "pct",
           "executed_share": "pct", "map_decided_share": "pct", "in_box_share": "pct", "dev_h_mean": "f0",
           "dev_v_mean": "f1", "pi_mean": "f2", "pi_paper_mean": "f2", "unsafe_share": "pctd",
           "active_share": "pct", "lowc_duration_mean": "f1", "lowc_s_per_hr": "g3"}


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
    if kind == "pctd":  # two decimals
        return f"{100 * x:.2f} %"
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
    #: why the check is true by construction ("" = an empirical finding)
    by_construction: str = ""
    #: equivalence margin of a "no change" claim (in the statistic's unit, or None when the rule
    #: ``detectable`` computes it) and its reason
    margin: "float | None" = None
    margin_reason: str = ""
    #: ``detectable``: the margin is the smallest difference the paper's study could detect
    margin_rule: str = ""
    #: an ordering's size: where the paper's tables give both groups' values (``key``, ``per_encounter``)
    size: dict = field(default_factory=dict)
    #: a band that summarises another finding's number (its id): the band is judged against it
    summarises: str = ""
    #: the id of the claim that implies this one (tested with it)
    nested_in: str = ""

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
        if self.kind in ("change", "equivalence"):
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
        if self.kind == "equivalence":
            return "no change (± the paper's detectable difference)" if self.margin_rule else \
                f"no change (±{self.margin:g} %)"
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


def paper_group_value(spec: dict, group: str) -> float:
    """The paper's number of ``group`` for a ``{key, per_encounter, scale}`` spec (an ordering's size)."""
    pr = paper_results()
    v = _lookup(pr, spec["key"], group)
    if spec.get("per_encounter"):
        v /= float(pr.get("encounters_per_group", 10000))
    return float(v) * float(spec.get("scale", 1.0))


def _lookup(pr: dict, key: str, group: "str | None") -> float:
    node = pr
    for part in key.replace("{group}", group or "").split("."):
        if not isinstance(node, dict) or part not in node:
            raise FileFormatError(f"paper_findings.yaml: paper_results.yaml has no {key!r} (for group {group})")
        node = node[part]
    return float(node)


@lru_cache(maxsize=1)
def _raw() -> dict:
    from daa_sil.config.yaml_input import load_yaml  # lazy: start-up time

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
        margin = f.get("margin")
        detectable = margin == "detectable"
        if f["kind"] == "equivalence" and not ((detectable or (isinstance(margin, (int, float)) and margin > 0))
                                                and f.get("margin_reason")):
            raise FileFormatError(f"paper_findings.yaml: {f['id']}: an equivalence needs a margin (> 0, or "
                                  f"'detectable') and its reason")
        base = dict(id=f["id"], claim=f["claim"], source=f.get("source", ""), kind=f["kind"], metric=f["metric"],
                    change=dict(f.get("change", {})), paper=dict(f.get("paper", {})), bound=f.get("bound"),
                    category=f.get("category"), ordering=dict(f.get("ordering", {})),
                    by_construction=str(f.get("by_construction", "") or ""),
                    margin=None if detectable or margin is None else float(margin),
                    margin_reason=str(f.get("margin_reason", "") or ""), margin_rule="detectable" if detectable else "",
                    size=dict(f.get("size", {})), summarises=str(f.get("summarises", "") or ""),
                    nested_in=str(f.get("nested_in", "") or ""))
        if "groups" in f:
            out += [Finding(**base, group=g) for g in f["groups"]]
        elif "pooled" in f:
            out.append(Finding(**base, pooled=tuple(f["pooled"]["groups"]), over=tuple(f["pooled"].get("over", ()))))
        else:
            out.append(Finding(**base))
    return out


def untestable_statements() -> list[dict]:
    return list(_raw().get("untestable", []))


__all__ = ["Finding", "load_findings", "untestable_statements", "VERDICTS", "EMPIRICAL", "APART", "KINDS", "REPRODUCED",
           "CONSISTENT", "DIRECTION", "NOT_REPRODUCED", "BY_CONSTRUCTION", "UNINFORMATIVE", "NESTED", "INPUT",
           "NOT_TESTABLE", "EVENT_COLUMNS", "fmt", "paper_group_value"]
