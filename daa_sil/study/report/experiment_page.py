"""The experiments page (``experiments.md``) from ``experiments.json``
(:func:`daa_sil.study.analysis.experiment_suite.analyse`): per experiment what it tests, the runs and the command,
every label's values with their 95 % CIs, and the paired differences."""

from __future__ import annotations

from daa_sil.study.analysis.findings import FORMATS, fmt
from daa_sil.study.report.markdown import markdown_table

#: how each metric is named on the page
METRIC_LABELS = {
    "alert_share_1": "any alert", "alert_share_2": "corrective alert", "alert_share_3": "warning alert",
    "p_lowc": "LoWC encounters", "p_lowc_step": "time in LoWC", "lowc_s_per_hr": "LoWC s per flight hour",
    "maneuvered_share": "left the plan", "dev_h_mean": "horiz. dev. (max), m", "dev_v_mean": "vert. dev. (max), m",
    "dev_h_tmean_mean": "horiz. dev. (time mean), m", "dev_v_tmean_mean": "vert. dev. (time mean), m",
    "dev_xtrack_mean": "cross-track (max), m", "dev_h_end_mean": "horiz. dev. at T, m",
    "dev_h_maneuvered_mean": "horiz. dev. of those that left, m", "unsafe_share": "unsafe on arrival",
    "no_wait": "DAA allocations / enc.", "wait": "waits / enc.", "received": "received / enc.",
    "blend": "blends / enc.", "daa_override": "overrides / enc.", "pilot_exec": "executed as sent / enc.",
    "exact_match": "exact (axis, dir.)", "axis_match": "axis only", "neither_match": "neither",
    "switches_per_active": "authority switches / active enc.", "map_decided_share": "decided by the map",
    "in_box_share": "lookups in the box",
}
#: number formats beyond :data:`daa_sil.study.analysis.findings.FORMATS`
EXTRA_FORMATS = {"alert_share_1": "pct", "alert_share_2": "pct", "alert_share_3": "pct", "maneuvered_share": "pct",
                 "p_lowc_step": "sci", "dev_h_tmean_mean": "f0", "dev_xtrack_mean": "f0", "dev_h_end_mean": "f0",
                 "dev_h_maneuvered_mean": "f0", "dev_v_tmean_mean": "f1"}


def metric_format(metric: str) -> str:
    return EXTRA_FORMATS.get(metric, FORMATS.get(metric, "g3"))


def cell(r: "dict | None", metric: str) -> str:
    """``value [lo, hi]`` of a row (– when absent)."""
    if r is None or r.get("value") is None:
        return "–"
    k = metric_format(metric)
    if r.get("lo") is None or r.get("hi") is None:
        return fmt(r["value"], k)
    return f"{fmt(r['value'], k)} [{fmt(r['lo'], k)}, {fmt(r['hi'], k)}]"


def pivot(rows: list, max_metrics: int = 9) -> list[str]:
    """A labels x metrics table (at most ``max_metrics`` metrics a table, so no table passes 12
    columns)."""
    labels = list(dict.fromkeys(r["label"] for r in rows))
    metrics = list(dict.fromkeys(r["metric"] for r in rows))
    by = {(r["label"], r["metric"]): r for r in rows}
    out = []
    for i in range(0, len(metrics), max_metrics):
        ms = metrics[i:i + max_metrics]
        body = [[lab] + [cell(by.get((lab, m)), m) for m in ms] for lab in labels]
        out += [markdown_table(["run / group"] + [METRIC_LABELS.get(m, m) for m in ms], body), ""]
    return out


def _lowc_table(groups: dict) -> list[str]:
    def q(x):
        return "–" if not x else f"{x[1]:.0f} ({x[0]:.0f}–{x[2]:.0f})"

    def pct(x):
        return "–" if x is None else f"{100 * x:.0f} %"

    body = []
    for g, d in groups.items():
        if not d.get("n_lowc"):
            body.append([g, "0"] + ["–"] * 8)
            continue
        a = d["authority_at_onset"]
        body.append([g, f"{d['n_lowc']} ({d['n_replayed']} replayed, {pct(d['replay_matches'])} again)",
                     " / ".join(pct(a.get(k)) for k in ("pilot", "daa", "waiting")), q(d["from_alert1_s"]),
                     q(d["from_alert2_s"]), pct(d["maneuver_before_onset"]), q(d["maneuver_after_alert2_s"]),
                     pct(d["turning_before_onset"]), q(d["turn_to_onset_s"]),
                     f"{d['pi_gt_max']} ({d['pi_gt_max_turning']} turning, {d['pi_gt_max_daa_at_onset']} DAA)"])
    return [markdown_table(["group", "LoWC encounters", "authority at onset: pilot / DAA / waiting",
                            "s from the first alert (median, IQR)", "s from the corrective alert",
                            "a pilot maneuver arrived before", "s from the corrective alert to it",
                            "intruder turning before onset", "s from the turn's start", "PI > 3.79"], body), ""]


def _blend_table(groups: dict) -> list[str]:
    body = []
    for g, d in groups.items():
        mr, hr = d["maneuver_by_rule"], d["hold_by_rule"]
        tot = max(d["maneuver_blends"], 1)
        rules = " / ".join(f"{r} {100 * n / tot:.0f} %" for r, n in mr.items() if n)
        fa = d["failed_exact_asked"]
        fa = sorted(fa.items(), key=lambda kv: -kv[1]) if isinstance(fa, dict) else fa  # (an older file: a mapping)
        asked = ", ".join(f"{k} {v}" for k, v in list(fa)[:4]) or "–"
        body.append([g, str(d["blends"]), str(d["maneuver_blends"]), rules or "–", str(d["hold_blends"]),
                     " / ".join(f"{r} {n}" for r, n in hr.items() if n) or "–", asked])
    return [markdown_table(["group", "blends", "of a maneuver", "found by (maneuvers)", "of a 'hold'",
                            "found by ('hold')", "missed searches asked for"], body), ""]


#: the axes of a flown command, in the order the page prints them
AXES = ("none", "horizontal", "vertical", "speed")


def _axes_table(groups: dict) -> list[str]:
    body = []
    for g, kinds in groups.items():
        for kind, k in kinds.items():
            tot = k["n"] or 1
            unsafe = "–" if k.get("unsafe") is None else f"{100 * k['unsafe'] / tot:.1f} %"
            body.append([g, kind, f"{k['n']:,}"] + [f"{100 * k['axes'].get(a, 0) / tot:.0f} %" for a in AXES]
                        + [unsafe])
    return [markdown_table(["group", "flown instead of the command", "executions", "course kept", "a turn",
                            "a climb or descent", "a speed change", "itself unsafe (SM ≤ 0)"], body), ""]


def experiments_page(res: dict) -> str:
    """The Markdown page of an ``experiments.json`` dictionary."""
    meta = res.get("meta", {})
    L = ["# Experiments: why the paper reading misses the paper where it does", "",
         "Single-factor experiments on the same encounters (one campaign seed: every run draws the same encounter "
         "set, so the groups of several runs compare encounter by encounter, with a paired bootstrap). "
         f"Campaign seed {meta.get('seed')}; {meta.get('n_small', 0):,} encounters per group, {meta.get('n_large', 0):,} for "
         "the rare-event runs (severity, feet); values with their encounter-level 95 % CIs.", "",
         f"Run again: `{meta.get('command', '')}` (RUNS: the directory where `docs/results/regenerate.py` ran the "
         "readings on the same seed; it runs this command too).", ""]
    if meta.get("missing"):
        L += [f"Not run here (their experiments are left out): {', '.join(sorted(set(meta['missing'])))}.", ""]
    for key, e in res.get("experiments", {}).items():
        L += [f"## {e['title']}", "", f"{e['why'][0].upper()}{e['why'][1:]}. Runs: "
              + ", ".join(f"`{r}`" for r in e.get("runs", ())) + (f"; {e['n']:,} encounters compared." if e.get("n")
                                                                  else "."), ""]
        if key == "lowc":
            L += _lowc_table(e["groups"])
            continue
        if key == "blend_searches":
            L += _blend_table(e["groups"])
            continue
        if key == "exec_axes":
            L += _axes_table(e["groups"])
            continue
        L += pivot(e.get("rows", []))
        if e.get("diffs"):
            L += ["Paired differences (over the same encounters):", ""]
            L += pivot([{**d, "label": f"{d['label']} − {d['ref']}"} for d in e["diffs"]])
    return "\n".join(L) + "\n"


__all__ = ["experiments_page", "pivot", "cell", "METRIC_LABELS", "metric_format"]
