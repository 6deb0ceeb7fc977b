"""Campaign report: ``report.md`` + PNG figures with our values, their 95 % CIs and the paper's
published values side by side (``daa_sil/data/paper_results.yaml``).

Input (``write_report(src, out_dir)``): a campaign directory laid out as
``DIR/<group>/encounters-*.parquet`` (+ ``decisions-*.parquet``), a list of per-encounter Parquet
files, a pyarrow Table or a dict of arrays (the per-encounter table of ``docs/architecture.md``).
Metric definitions: :mod:`daa_sil.metrics`. Every file is written atomically.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Sequence

import numpy as np

from .errors import FileFormatError, UsageError
from .io import atomic_path, atomic_write_text, ensure_dir
from .metrics import (BASELINE_GROUP, CONF, Estimate, as_columns, compute_metrics, faa_category, groups_of,
                      paper_results)

FIGURES = ("fig9_allocation.png", "fig10_safety.png", "fig_exact_match.png")


def _read_parquet(path: Path):
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        return pq.read_table(path)
    except (OSError, pa.ArrowException, ValueError) as exc:
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise FileFormatError(f"{path} is not a readable Parquet file: {msg}") from None


def load_results(src) -> dict:
    """The per-encounter table of ``src`` (directory, Parquet file list, Table or dict) as columns."""
    import pyarrow as pa

    if isinstance(src, (str, os.PathLike)):
        d = Path(src)
        if not d.exists():
            raise FileFormatError(f"{d}: no such results directory")
        if d.is_file():
            files = [d]
        else:
            files = sorted(d.glob("*/encounters-*.parquet"))
            if not files:
                raise FileFormatError(f"{d} holds no <group>/encounters-*.parquet results")
    elif isinstance(src, (list, tuple)) and src and all(isinstance(s, (str, os.PathLike)) for s in src):
        files = [Path(s) for s in src]
        for f in files:
            if not f.is_file():
                raise FileFormatError(f"{f}: no such results file")
    else:
        return as_columns(src)
    tables = [_read_parquet(f) for f in files]
    try:
        table = pa.concat_tables(tables, promote_options="default")
    except (pa.ArrowException, TypeError) as exc:
        raise FileFormatError(f"result files have incompatible schemas: {str(exc).splitlines()[0]}") from None
    if table.num_rows == 0:
        raise FileFormatError(f"{src}: the result files hold no encounters")
    return as_columns(table)


# --- formatting -----------------------------------------------------------------------------------
def _num(x: float, kind: str = "g") -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "–"
    if kind == "int":
        return f"{x:,.0f}"
    if kind == "pct":
        return f"{x:.2f} %"
    if kind == "sci":
        return f"{x:.2e}"
    if kind == "f1":
        return f"{x:,.1f}"
    if kind == "f2":
        return f"{x:.2f}"
    return f"{x:.4g}"


def _ci(e: "Estimate | None", kind: str) -> str:
    if e is None:
        return "–"
    if not (math.isfinite(e.lo) or math.isfinite(e.hi)):
        return _num(e.value, kind)
    return f"{_num(e.value, kind)} [{_num(e.lo, kind)}, {_num(e.hi, kind)}]"


def _paper(section: str, group: str, key: str, kind: str = "int") -> str:
    v = paper_results().get(section, {}).get(group, {})
    v = v.get(key) if isinstance(v, dict) else None
    return "–" if v is None else _num(float(v), kind)


def _table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    out = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    out += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(out)


# --- findings -------------------------------------------------------------------------------------
INTEGRATED = ("IC-1", "ID-1", "ID-2")


def findings(res: dict) -> list[tuple[str, str, str]]:
    """The paper's stated properties checked on our results: ``[(claim, verdict, evidence)]`` with
    verdict ``holds``, ``does not hold`` or ``not checked`` (groups missing)."""
    out = []
    nm = {g: m["n_nmac"].value for g, m in res.items()}
    out.append(("0 NMAC in every group", "holds" if all(v == 0 for v in nm.values()) else "does not hold",
                ", ".join(f"{g}: {v:.0f}" for g, v in nm.items())))
    integ = [g for g in INTEGRATED if g in res]
    if integ:
        ov = {g: res[g]["daa_override"].value for g in integ}
        out.append(("0 DAA overrides in the integrated groups",
                    "holds" if all(v == 0 for v in ov.values()) else "does not hold",
                    ", ".join(f"{g}: {v:.0f}" for g, v in ov.items())))
    else:
        out.append(("0 DAA overrides in the integrated groups", "not checked", "no integrated group"))
    for claim, key, thr in (("DAA allocation (no-wait) reduced by >= 75 % vs B-2", "no_wait_reduction_pct", 75.0),
                            ("pilot-command reception up by >= 15 % vs B-2", "received_change_pct", 15.0)):
        have = [g for g in integ if key in res[g]]
        if not have:
            out.append((claim, "not checked", f"needs {BASELINE_GROUP} and an integrated group"))
            continue
        vals = {g: res[g][key].value for g in have}
        ok = all(np.isfinite(v) and v >= thr for v in vals.values())
        out.append((claim, "holds" if ok else "does not hold",
                    ", ".join(f"{g}: {_num(v, 'pct')} (CI {_num(res[g][key].lo, 'pct')}..{_num(res[g][key].hi, 'pct')})"
                              for g, v in vals.items())))
    em = [(g, res[g]["exact_match"]) for g in integ if np.isfinite(res[g]["exact_match"].value)]
    if em:
        share = lambda g: res[g]["blend_intent_share"].value if np.isfinite(res[g]["blend_intent_share"].value) else 1.0  # noqa: E731
        k = sum(res[g]["blend"].value * share(g) * e.value for g, e in em)
        n = sum(res[g]["blend"].value * share(g) for g, _ in em)
        p = k / n
        ok = any(e.lo <= 0.84 <= e.hi for _, e in em) or abs(p - 0.84) <= 0.05
        out.append(("about 84 % of blends of a pilot maneuver match its exact (axis, direction)",
                    "holds" if ok else "does not hold",
                    f"pooled {100 * p:.1f} %; " + ", ".join(f"{g}: {100 * e.value:.1f} %" for g, e in em)))
    else:
        out.append(("about 84 % of blends of a pilot maneuver match its exact (axis, direction)", "not checked",
                    "no blends of a pilot maneuver"))
    cats = {g: faa_category(m["p_lowc_per_hr"].value) for g, m in res.items()}
    out.append(("P(LoWC)/flight hour in the Remote band (paper Eq.)",
                "holds" if all(c == "Remote" for c in cats.values()) else "does not hold",
                ", ".join(f"{g}: {_num(res[g]['p_lowc_per_hr'].value, 'sci')} ({c})" for g, c in cats.items())))
    return out


# --- figures --------------------------------------------------------------------------------------
def _save(fig, path: Path) -> None:
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110, bbox_inches="tight")


def _figures(res: dict, out: Path) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    pr = paper_results()
    groups = list(res)
    x = np.arange(len(groups))
    w = 0.38

    n_enc = np.array([res[g]["n_encounters"] for g in groups], float)
    paper_n = float(pr.get("encounters_per_group", 10000))

    def err(key, per_enc=False):
        s = n_enc if per_enc else 1.0
        v = np.array([res[g][key].value for g in groups], float) / s
        lo = np.array([res[g][key].lo for g in groups], float) / s
        hi = np.array([res[g][key].hi for g in groups], float) / s
        return v, np.vstack([np.clip(v - lo, 0, None), np.clip(hi - v, 0, None)])

    def paper_vals(section, key, per_enc=False):
        v = np.array([float(pr.get(section, {}).get(g, {}).get(key, np.nan)) if g in pr.get(section, {}) else np.nan
                      for g in groups])
        return v / paper_n if per_enc else v

    paths = []
    fig, ax = plt.subplots(1, 3, figsize=(15, 4.2))
    for k, (key, col) in enumerate((("wait", "tab:orange"), ("no_wait", "tab:red"))):
        v, e = err(key, True)
        ax[0].bar(x + (k - 0.5) * w, v, w, yerr=e, color=col, label=f"ours: {key.replace('_', '-')}", capsize=3)
        ax[0].scatter(x + (k - 0.5) * w, paper_vals("waiting_status", key, True), marker="x",
                      color="k", zorder=3, label="paper" if k == 0 else None)
    ax[0].set_title("(a) wait / no-wait (allocate to DAA)")
    v, e = err("received", True)
    ax[1].bar(x, v, 0.6, yerr=e, color="tab:blue", capsize=3, label="ours")
    ax[1].scatter(x, paper_vals("pilot_command_reception", "received", True), marker="x", color="k", zorder=3,
                  label="paper")
    ax[1].set_title("(b) pilot commands received")
    bottom = np.zeros(len(groups))
    pbottom = np.zeros(len(groups))
    for key, col, pk in (("pilot_exec", "tab:green", "pilot"), ("blend", "tab:purple", "blending"),
                         ("daa_override", "tab:red", "daa_override")):
        v, _ = err(key, True)
        ax[2].bar(x - w / 2, v, w, bottom=bottom, color=col, label=f"ours: {pk}")
        ax[2].bar(x + w / 2, paper_vals("command_execution", pk, True), w, bottom=pbottom, color=col, alpha=0.45,
                  hatch="//", label=f"paper: {pk}")
        bottom = bottom + np.nan_to_num(v)
        pbottom = pbottom + np.nan_to_num(paper_vals("command_execution", pk, True))
    ax[2].set_title("(c) command execution")
    for a in ax:
        a.set_xticks(x, groups)
        a.legend(fontsize=7)
        a.set_ylabel("instances (steps) per encounter")
    p = out / FIGURES[0]
    _save(fig, p)
    plt.close(fig)
    paths.append(p)

    fig, ax = plt.subplots(1, 3, figsize=(15, 4.2))
    v, e = err("p_lowc")
    ax[0].bar(x, 100 * v, 0.6, yerr=100 * e, color="tab:red", capsize=3)
    ax[0].set_title("(a) LoWC encounters (% of encounters)")
    ax[0].set_ylabel("% of encounters")
    v, e = err("p_lowc_per_hr")
    pos = np.where(v > 0, v, np.nan)
    ax[1].bar(x, np.nan_to_num(pos), 0.6, yerr=e, color="tab:red", capsize=3, label="ours (paper Eq.)")
    ax[1].scatter(x, paper_vals("lowc_per_flight_hour", "p"), marker="x", color="k", zorder=3, label="paper")
    bands = pr["faa_likelihood"]
    for name, (lo, hi) in bands.items():
        if lo > 0:
            ax[1].axhline(lo, color="0.6", lw=0.6, ls="--")
    ax[1].set_yscale("log")
    ax[1].set_ylim(1e-10, 1e-3)
    ax[1].set_title("(b) P(LoWC) per flight hour (dashed: FAA bands)")
    ax[1].legend(fontsize=7)
    v, e = err("pi_mean")
    ax[2].bar(x - w / 2, np.nan_to_num(v), w, yerr=np.nan_to_num(e), color="tab:gray", capsize=3, label="mean PI")
    ax[2].bar(x + w / 2, np.nan_to_num([res[g]["pi_max"].value for g in groups]), w, color="k", label="max PI")
    ax[2].set_title("(c) penetration integral of LoWC encounters (s)")
    ax[2].legend(fontsize=7)
    for a in ax:
        a.set_xticks(x, groups)
    p = out / FIGURES[1]
    _save(fig, p)
    plt.close(fig)
    paths.append(p)

    fig, ax = plt.subplots(figsize=(6, 4))
    v, e = err("exact_match")
    ax.bar(x, 100 * np.nan_to_num(v), 0.6, yerr=100 * np.nan_to_num(e), color="tab:purple", capsize=3, label="ours")
    ax.axhline(pr.get("blending_exact_match_pct", 84), color="k", ls="--", label="paper (84 %)")
    ax.set_xticks(x, groups)
    ax.set_ylim(0, 105)
    ax.set_ylabel("% of blends with the pilot's (axis, direction)")
    ax.legend(fontsize=7)
    p = out / FIGURES[2]
    _save(fig, p)
    plt.close(fig)
    paths.append(p)
    return paths


# --- report ---------------------------------------------------------------------------------------
def render_markdown(res: dict, source: str = "") -> str:
    """The report text for ``compute_metrics`` output ``res``."""
    pr = paper_results()
    groups = list(res)
    L = [f"# daa-sil campaign report", ""]
    if source:
        L += [f"Results: `{source}`", ""]
    L += ["Our values with their 95 % confidence interval in brackets; the paper's published value "
          "(Tabassum & Bai, `daa_sil/data/paper_results.yaml`) next to it. Counts are per-time-step "
          "instances summed over a group's encounters. Interval methods: `daa_sil/metrics.py`.", ""]
    L += [_table(["group", "encounters", "flight hours"],
                 [[g, _num(res[g]["n_encounters"], "int"), _num(res[g]["flight_hours"], "f2")] for g in groups]), ""]

    def red(g, key):
        return _ci(res[g].get(key), "pct") if key in res[g] else "–"

    L += ["## Table 3 — waiting status (wait / no-wait = allocate to DAA)", "",
          _table(["group", "wait", "paper", "no-wait", "paper", "reduction vs B-2", "paper"],
                 [[g, _ci(res[g]["wait"], "int"), _paper("waiting_status", g, "wait"),
                   _ci(res[g]["no_wait"], "int"), _paper("waiting_status", g, "no_wait"),
                   red(g, "no_wait_reduction_pct"), _paper("waiting_status", g, "reduction_pct", "pct")]
                  for g in groups]), ""]
    L += ["## Table 4 — pilot-command reception", "",
          _table(["group", "received", "paper", "change vs B-2", "paper"],
                 [[g, _ci(res[g]["received"], "int"), _paper("pilot_command_reception", g, "received"),
                   red(g, "received_change_pct"), _paper("pilot_command_reception", g, "increase_pct", "pct")]
                  for g in groups]), ""]
    L += ["## Table 5 — command execution", "",
          _table(["group", "DAA override", "paper", "pilot", "paper", "blending", "paper"],
                 [[g, _ci(res[g]["daa_override"], "int"), _paper("command_execution", g, "daa_override"),
                   _ci(res[g]["pilot_exec"], "int"), _paper("command_execution", g, "pilot"),
                   _ci(res[g]["blend"], "int"), _paper("command_execution", g, "blending")] for g in groups]), ""]
    L += ["## Exact match among blends (paper: 84 % exact (axis, direction), 16 % axis only)", "",
          "The paper's 84 % + 16 % = 100 %: every blend it counts carries the pilot's maneuver intent. Our GCS",
          "also streams \"hold current course\" from the alert until the pilot's first maneuver; a hold has no",
          "(axis, direction), and when it is unsafe Algorithm 2 falls through to \"any\". The match rates are",
          "therefore over the blends of a pilot maneuver; the share of those among all blends is given too.", "",
          _table(["group", "exact (axis, direction) %", "axis only %", "paper exact %", "blends of a maneuver %"],
                 [[g, _ci(_scale(res[g]["exact_match"]), "f1"), _ci(_scale(res[g]["axis_match"]), "f1"),
                   _num(float(pr.get("blending_exact_match_pct", math.nan)), "f1"),
                   _ci(_scale(res[g]["blend_intent_share"]), "f1")] for g in groups]), "",
          f"![exact match]({FIGURES[2]})", ""]
    L += ["## Safety — LoWC and NMAC", "",
          _table(["group", "LoWC encounters", "P(LoWC) per encounter", "NMAC encounters", "P(NMAC) per encounter",
                  "paper NMAC"],
                 [[g, _ci(res[g]["n_lowc"], "int"), _ci(res[g]["p_lowc"], "sci"), _ci(res[g]["n_nmac"], "int"),
                   _ci(res[g]["p_nmac"], "sci"), _num(float(pr.get("nmac", {}).get("all_groups", math.nan)), "int")]
                  for g in groups]), ""]
    L += ["## Table 7 — P(LoWC) per flight hour and FAA likelihood", "",
          "Paper Eq.: P(LoWC)/flight hr = (fraction of time steps in LoWC) / (total flight hours). "
          "The event rate (LoWC encounters per flight hour) is given for comparison.", "",
          _table(["group", "P(LoWC)/flight hr (paper Eq.)", "FAA", "paper", "paper FAA", "LoWC encounters/flight hr", "FAA"],
                 [[g, _ci(res[g]["p_lowc_per_hr"], "sci"), faa_category(res[g]["p_lowc_per_hr"].value),
                   _paper("lowc_per_flight_hour", g, "p", "sci"),
                   str(pr.get("lowc_per_flight_hour", {}).get(g, {}).get("category", "–")),
                   _ci(res[g]["lowc_rate_per_hr"], "sci"), faa_category(res[g]["lowc_rate_per_hr"].value)]
                  for g in groups]), ""]
    L += ["## Penetration integral of LoWC encounters (paper: mean < 1, max 3.79 in ID-1)", "",
          _table(["group", "mean PI (s)", "max PI (s)"],
                 [[g, _ci(res[g]["pi_mean"], "f2"), _num(res[g]["pi_max"].value, "f2")] for g in groups]), ""]
    L += ["## Table 8 — mean trajectory deviation", "",
          _table(["group", "horizontal (m)", "paper", "vertical (m)", "paper"],
                 [[g, _ci(res[g]["dev_h_mean"], "f1"), _paper("trajectory_deviation_m", g, "horizontal"),
                   _ci(res[g]["dev_v_mean"], "f1"), _paper("trajectory_deviation_m", g, "vertical")]
                  for g in groups]), ""]
    L += ["## Figures", "", f"![Fig. 9 analogue: allocation, reception, execution]({FIGURES[0]})", "",
          f"![Fig. 10 analogue: LoWC, P(LoWC)/hr, PI]({FIGURES[1]})", ""]
    L += ["## Findings — the paper's stated properties on our results", ""]
    for claim, verdict, ev in findings(res):
        L.append(f"- **{verdict.upper()}**: {claim} — {ev}")
    L.append("")
    return "\n".join(L)


def _scale(e: Estimate) -> Estimate:
    return Estimate(100 * e.value, 100 * e.lo, 100 * e.hi, e.method, e.note)


def write_report(src, out_dir: "str | os.PathLike", baseline: str = BASELINE_GROUP, conf: float = CONF) -> Path:
    """Compute the metrics of ``src`` and write ``out_dir/report.md`` plus the PNG figures
    (:data:`FIGURES`); returns the report path. FileFormatError for a missing, empty or corrupt
    results source."""
    cols = load_results(src)
    if not cols or len(next(iter(cols.values()))) == 0:
        raise FileFormatError(f"{src if isinstance(src, (str, os.PathLike)) else 'results'}: no encounters")
    res = compute_metrics(cols, baseline=baseline, conf=conf)
    out = ensure_dir(out_dir)
    _figures(res, out)
    text = render_markdown(res, str(src) if isinstance(src, (str, os.PathLike)) else "")
    return atomic_write_text(out / "report.md", text)


__all__ = ["write_report", "load_results", "render_markdown", "findings", "FIGURES"]
