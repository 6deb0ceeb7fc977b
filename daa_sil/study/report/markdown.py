"""Markdown formatting of the report: tables, an estimate with its interval, the paper's published
value beside ours, and the per-group table layout (:data:`GROUP_TABLES`)."""

from __future__ import annotations

import math
from typing import Sequence

from daa_sil.study.analysis.study import Study
from daa_sil.study.analysis.counting import paper_setup
from daa_sil.study.analysis.findings import fmt
from daa_sil.study.analysis.metrics import PAPER_FLIGHT_HOURS, Estimate, paper_results
from daa_sil.study.analysis.metrics import GROUP_ORDER


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    """A Markdown table of ``rows`` under ``header`` (a ``|`` inside a cell becomes ``/``)."""
    out = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    out += ["| " + " | ".join(str(c).replace("|", "/") for c in r) + " |" for r in rows]
    return "\n".join(out)


#: the widest table a page prints (columns)
MAX_COLUMNS = 12


def wide_table(fixed: Sequence[str], rows: Sequence[Sequence[str]], names: Sequence[str],
               cells: Sequence[Sequence[str]], max_columns: int = MAX_COLUMNS) -> list[str]:
    """Markdown lines of a table of ``fixed`` columns (``rows``) and one column per entry of ``names``
    (``cells[j][i]``: column j, row i), split into tables of at most ``max_columns`` columns, each
    repeating the fixed columns."""
    per = max(1, max_columns - len(fixed))
    out: list[str] = []
    for a in range(0, max(len(names), 1), per):
        ns = list(names[a:a + per])
        body = [list(r) + [cells[a + j][i] for j in range(len(ns))] for i, r in enumerate(rows)]
        out += [markdown_table(list(fixed) + ns, body), ""]
    return out


def reading_label(label: str) -> str:
    """A reading's column name: in code font, so the reading called ``paper`` never reads as the paper."""
    return f"`{label}`"


def estimate_text(e: Estimate, kind: str = "g3") -> str:
    """An estimate as text, ``value [lo, hi]`` in the number format ``kind`` (a note when it has one; – when undefined)."""
    if e is None or not math.isfinite(e.value):
        return "–" if e is None or e.note in ("", "undefined on these results") else f"– ({e.note})"
    if math.isfinite(e.lo) and math.isfinite(e.hi):
        txt = f"{fmt(e.value, kind)} [{fmt(e.lo, kind)}, {fmt(e.hi, kind)}]"
        return f"{txt} ({e.note})" if e.method == "exact binomial bound" else txt
    if e.note:
        return f"{fmt(e.value, kind)} ({e.note})"
    return fmt(e.value, kind)


def _paper_group(section: str, key: str, per_enc: bool = False):
    def f(g):
        v = paper_results().get(section, {}).get(g, {})
        v = v.get(key) if isinstance(v, dict) else None
        if v is None:
            return None
        return float(v) / (float(paper_results().get("encounters_per_group", 10000)) if per_enc else 1.0)
    return f


def _paper_if(text: str):
    """The paper's statement (text) for its five groups."""
    return lambda g: text if paper_setup(g) else None


# (label, metric or ("change", metric, kind), value format, paper value fn(group) -> number | text | None,
#  show the total)
GROUP_TABLES = (
    ("Table 3 — waiting status (per encounter; paper: its total / 10,000)", (
        ("wait decisions", "wait", "g3", _paper_group("waiting_status", "wait", True), True),
        ("no-wait decisions (allocate to DAA)", "no_wait", "g3", _paper_group("waiting_status", "no_wait", True), True),
        ("no-wait reduction vs B-2", ("change", "no_wait", "reduction"), "pctv",
         _paper_group("waiting_status", "reduction_pct"), False))),
    ("Table 4 — pilot-command reception", (
        ("pilot commands received", "received", "g3", _paper_group("pilot_command_reception", "received", True), True),
        ("reception change vs B-2", ("change", "received", "ratio"), "pctv",
         _paper_group("pilot_command_reception", "increase_pct"), False),
        ("share of received executed as sent", "executed_share", "pct",
         lambda g: (_paper_group("command_execution", "pilot")(g) or math.nan)
         / (_paper_group("pilot_command_reception", "received")(g) or math.nan), False))),
    ("Table 5 — command execution", (
        ("DAA overrides", "daa_override", "g3", _paper_group("command_execution", "daa_override", True), True),
        ("pilot commands executed as sent", "pilot_exec", "g3", _paper_group("command_execution", "pilot", True), True),
        ("blended commands", "blend", "g3", _paper_group("command_execution", "blending", True), True))),
    ("Blending — (axis, direction) match among blends of a pilot maneuver", (
        ("exact (axis, direction)", "exact_match", "pct", lambda g: 0.84 if paper_setup(g) == "integrated" else None,
         False),
        ("axis only", "axis_match", "pct", lambda g: 0.16 if paper_setup(g) == "integrated" else None, False),
        ("neither", "neither_match", "pct", lambda g: 0.0 if paper_setup(g) == "integrated" else None, False),
        ("blends of a pilot maneuver among all blends", "blend_intent_share", "pct", None, False))),
    ("Safety — LoWC and NMAC encounters", (
        ("LoWC encounters", "n_lowc", "int", None, False),
        ("P(LoWC) per encounter", "p_lowc", "pct", None, False),
        ("NMAC encounters", "n_nmac", "int", lambda g: 0.0 if paper_setup(g) else None, False),
        ("LoWC encounters with a turning intruder", "lowc_turning_share", "pct", _paper_if("98 % on average"), False))),
    ("Table 7 — P(LoWC) per flight hour", (
        ("P(LoWC) = time in LoWC / flight time", "p_lowc_step", "sci",
         lambda g: (_paper_group("lowc_per_flight_hour", "p")(g) or math.nan) * PAPER_FLIGHT_HOURS, False),
        ("paper Eq. at this campaign's flight hours (shrinks as 1/N)", "p_lowc_per_hr", "sci",
         _paper_group("lowc_per_flight_hour", "p"), False),
        ("paper Eq. at the paper's 666.67 flight hours", "p_lowc_per_hr_paper_h", "sci",
         _paper_group("lowc_per_flight_hour", "p"), False),
        ("LoWC encounters per flight hour (a rate)", "lowc_rate_per_hr", "sci", None, False))),
    ("Penetration integral of LoWC encounters (s)", (
        ("mean PI, paper's Eq. constants (4000 ft / 450 ft / 35 s)", "pi_paper_mean", "f2", _paper_if("< 1"), False),
        ("mean PI, the preset's constants", "pi_mean", "f2", None, False),
        ("LoWC encounters with PI > 3.79 (the paper's maximum)", "n_lowc_pi_gt_max", "int", _paper_if("0"), False),
        ("LoWC encounters with PI > 10 (significant)", "n_lowc_pi_significant", "int", _paper_if("0"), False),
        ("LoWC encounters of positive duration with PI = 0", "n_lowc_pi_zero", "int", None, False))),
    ("Table 8 — mean trajectory deviation (m)", (
        ("horizontal", "dev_h_mean", "f0", _paper_group("trajectory_deviation_m", "horizontal"), False),
        ("vertical", "dev_v_mean", "f1", _paper_group("trajectory_deviation_m", "vertical"), False))),
)


def group_cell(st: Study, g: str, metric, kind: str, total: bool) -> str:
    """The report's cell of ``metric`` for group ``g``: its estimate, or its change from the baseline when ``metric``
    is a tuple; with ``total``, the sum over encounters too."""
    if g not in st.groups:
        return "–"
    if isinstance(metric, tuple):
        _, m, ck = metric
        if g == st.baseline or st.baseline not in st.groups:
            return "–"
        return estimate_text(st.change(g, m, kind=ck), kind)
    if not st.available(g, metric):
        return "– (not in these results)"
    e = st.estimate(g, metric)
    txt = estimate_text(e, kind)
    if total and math.isfinite(e.value) and e.value != 0:
        txt += f" (total {fmt(st.sum(g, metric).value, 'int')})"
    return txt


def groups_in_order(studies: dict) -> list[str]:
    """Every group of the ``studies``, the paper's groups first in the paper's order."""
    seen = []
    for st in studies.values():
        for g in st.groups:
            if g not in seen:
                seen.append(g)

    return [g for g in GROUP_ORDER if g in seen] + [g for g in seen if g not in GROUP_ORDER]
