"""Signatures of the simulator: a few quantities that show whether our simulator behaves like the
paper's, whatever a reading's counting, each beside the paper's value computed from its tables
with the arithmetic shown.

Per group (the paper's tables are totals over 10,000 encounters; ``paper_results.yaml``):

* **unsafe on arrival** -- the share of arriving pilot commands the agent did not execute as sent:
  (DAA override + blending) / (pilot + DAA override + blending), the command-execution table's
  columns (overrides in the baselines, blends in the integrated groups; the other is 0);
* **DAA allocations per received command** -- no-wait decisions (the DAA given authority while no
  command is fresh; the waiting-status table) / commands received (the reception table);
* **commands received per encounter** -- the reception table / 10,000;
* **waits per received command** -- the waiting-status table's waits / received;
* **share of encounters ever active** and **mean active steps of those**: not given by the paper;
* **authority switches per active encounter**: how often the authority changes between the pilot, the
  waiting agent and the DAA from one step to the next (from the decision table): not given by the paper.

Ours use the reading's counting (:mod:`daa_sil.study.analysis.counting`): the same arithmetic on our counts.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Mapping

from daa_sil.study.analysis.metrics import paper_results


@dataclass(frozen=True)
class Signature:
    """One signature: its ``key``, a ``label``, the :data:`daa_sil.study.analysis.study.METRICS` entry that
    computes ours, its value format and ``paper(group) -> (value, arithmetic) | None``."""

    key: str
    label: str
    metric: str
    kind: str
    paper: Callable[[str], "tuple[float, str] | None"]


def _n(x: float) -> str:
    return f"{x:,.0f}"


def _tab(section: str, group: str, key: str) -> "float | None":
    v = paper_results().get(section, {}).get(group)
    return float(v[key]) if isinstance(v, dict) and key in v else None


def _unsafe(group: str):
    ov, pi, bl = (_tab("command_execution", group, k) for k in ("daa_override", "pilot", "blending"))
    if None in (ov, pi, bl):
        return None
    return (ov + bl) / (pi + ov + bl), f"({_n(ov)} + {_n(bl)}) / ({_n(pi)} + {_n(ov)} + {_n(bl)})"


def _per_received(section: str, key: str):
    def f(group: str):
        a, r = _tab(section, group, key), _tab("pilot_command_reception", group, "received")
        return None if a is None or r is None else (a / r, f"{_n(a)} / {_n(r)}")
    return f


def _received(group: str):
    r = _tab("pilot_command_reception", group, "received")
    n = float(paper_results().get("encounters_per_group", 10000))
    return None if r is None else (r / n, f"{_n(r)} / {_n(n)}")


def _not_given(group: str):
    return None


SIGNATURES = (
    Signature("unsafe", "unsafe on arrival (override + blend) / (pilot + override + blend)", "unsafe_share", "pctd",
              _unsafe),
    Signature("daa_per_received", "DAA allocations without a command per received command", "no_wait_per_received",
              "g3", _per_received("waiting_status", "no_wait")),
    Signature("received", "commands received per encounter", "received", "g3", _received),
    Signature("wait_per_received", "waits per received command", "wait_per_received", "g3",
              _per_received("waiting_status", "wait")),
    Signature("active", "share of encounters ever active", "active_share", "pct", _not_given),
    Signature("active_steps", "mean active steps of an active encounter", "active_steps_mean", "g3", _not_given),
    Signature("switches", "authority switches per active encounter (pilot, waiting, DAA)", "switches_per_active", "g3",
              _not_given),
)


def paper_cell(sig: Signature, group: str) -> str:
    """The paper's value with its arithmetic, or why there is none."""
    from daa_sil.study.analysis.findings import fmt  # lazy: start-up time

    p = sig.paper(group)
    if p is None:
        return "not given" if sig.paper is _not_given else "–"
    return f"{fmt(p[0], sig.kind)} = {p[1]}"


def our_cell(st, sig: Signature, group: str) -> str:
    """Our value [95 % CI] on a :class:`daa_sil.study.analysis.study.Study`."""
    from daa_sil.study.report.markdown import estimate_text  # lazy: start-up time

    if group not in st.groups or not st.available(group, sig.metric):
        return "–"
    return estimate_text(st.estimate(group, sig.metric), sig.kind)


def signature_section(studies: Mapping) -> list[str]:
    """The report section: one table per group, the paper's value (with arithmetic) and each reading's."""
    from daa_sil.study.report.markdown import groups_in_order, markdown_table  # lazy: start-up time

    labels = list(studies)
    L = ["## Signatures: does our simulator behave like the paper's?", "",
         "Quantities any reading can be compared on, each beside the paper's value computed from its tables "
         "(totals over 10,000 encounters; the arithmetic is shown). Ours use each reading's counting. *Unsafe on "
         "arrival* is the share of arriving pilot commands not executed as sent (overridden in the baselines, "
         "blended in the integrated groups); *DAA allocations per received command* divides the waiting-status "
         "table's no-wait decisions by the reception table.", ""]
    for g in groups_in_order(studies):
        rows = [[s.label, paper_cell(s, g)] + [our_cell(studies[lab], s, g) for lab in labels] for s in SIGNATURES]
        if all(all(c == "–" for c in r[2:]) for r in rows):
            continue
        L += [f"**{g}**", "", markdown_table(["signature", "Tabassum & Bai = their arithmetic"] + labels, rows), ""]
    return L


def signature_table(dirs: Mapping[str, "str | Path"], replicates: int = 400) -> str:
    """A compact Markdown table (run x group x signature, value [95 % CI]) of campaign directories:
    a quick summary of a few campaign directories."""
    from daa_sil.study.analysis.study import Study  # lazy: start-up time
    from daa_sil.study.report.markdown import markdown_table  # lazy: start-up time
    from daa_sil.study.analysis.report_input import load_block  # lazy: start-up time

    rows = []
    for name, d in dirs.items():
        b = load_block(Path(d))
        st = Study(b.enc, b.reading, dec=b.dec, replicates=replicates)
        for g in st.groups:
            rows.append([name, g] + [our_cell(st, s, g) for s in SIGNATURES])
    paper = [["paper", g] + [paper_cell(s, g).split(" = ")[0] for s in SIGNATURES]
             for g in ("B-1", "B-2", "IC-1", "ID-1", "ID-2")]
    return markdown_table(["run", "group"] + [s.key for s in SIGNATURES], paper + rows)


__all__ = ["Signature", "SIGNATURES", "paper_cell", "our_cell", "signature_section", "signature_table"]
