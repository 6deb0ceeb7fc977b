"""Campaign report: ``report.md`` + ``findings.json`` + PNG figures. One or more campaign
directories, each one named *reading* of the paper (``campaign.json`` ``config.reading`` and
``config.readings``; missing = ``default``), side by side: every finding of the paper
(``daa_sil/data/paper_findings.yaml``) with our value, its encounter-level 95 % CI and a verdict
under each reading (:mod:`daa_sil.study.findings`), then the per-group tables, the paired comparisons,
the ablation of the wait map, decision provenance, PI and P(LoWC), and the methods.

Input of :func:`write_report`: a campaign directory or a list of them (``DIR/<group>/encounters-*.parquet``
+ ``decisions-*.parquet`` + ``campaign.json``), a list of per-encounter Parquet files, a pyarrow
Table or a dict of arrays. Statistics: :mod:`daa_sil.study.metrics` / :mod:`daa_sil.study.stats`. Every file
is written atomically.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Sequence

import numpy as np

from daa_sil.errors import FileFormatError, UsageError
from .findings import fmt
from .verdicts import evaluate_all, finding_sample
from daa_sil.files import atomic_write_text, ensure_dir
from .metrics import BASELINE_GROUP, CONF, compute_metrics
from daa_sil.study.analysis import Study
from daa_sil.study.counting import COUNTING_DEFAULTS, COUNTING_HELP, counting_options
from .stats import DEFAULT_REPLICATES, DEFAULT_SEED, independent_difference
from daa_sil.study.report_input import Block, build_blocks
from daa_sil.study.report_figures import group_figures, file_slug
from daa_sil.study.report_format import GROUP_TABLES, groups_in_order, group_cell, estimate_text, markdown_table
from daa_sil.study.report_findings import findings_section
from daa_sil.study.paper_checks import inconsistency_section
from daa_sil.study.signatures import signature_section

#: the wait-map ablation: (group with the map and ProjL, ablation group, what the difference measures)
ABLATIONS = (("ID-2", "ID-2-projl", "what the map adds to ProjL (ID-2 minus ID-2-projl)"),
             ("ID-2", "ID-2-map", "what ProjL adds to the map (ID-2 minus ID-2-map)"))






# --- sections --------------------------------------------------------------------------------------
def _sources(blocks: Sequence[Block], studies: dict) -> list[str]:
    rows = []
    for b in blocks:
        st = studies[b.label]
        rows.append([f"**{b.label}**", f"`{b.reading.source}`" if b.reading.source else "(table)",
                     "–" if b.seed is None else str(b.seed), f"{st.n:,}", ", ".join(st.groups),
                     (b.meta or {}).get("preset") or "–", b.reading.describe()])
    L = ["## Readings and sources", "",
         markdown_table(["reading", "results", "campaign seed", "encounters", "groups", "preset", "settings"], rows), ""]
    L += ["Counting settings (the same simulation can be counted several ways; `--recount` adds a reading):", ""]
    for k, opts in counting_options().items():
        helps = COUNTING_HELP.get(k, {})
        L.append(f"- `{k}` (default `{COUNTING_DEFAULTS.get(k, '–')}`): "
                 + "; ".join(f"`{o}` = {helps.get(o, 'see daa_sil/study/counting.py COUNT_SOURCES')}" for o in opts))
    L.append("")
    return L


def _group_tables(studies: dict) -> list[str]:
    groups = groups_in_order(studies)
    labels = list(studies)
    L = ["## Per-group tables", "",
         "Value [95 % CI] per reading; counts per encounter with the total in brackets. Zeros carry exact "
         "upper bounds on the share of encounters instead of an interval.", ""]
    for title, items in GROUP_TABLES:
        L += [f"### {title}", ""]
        for label, metric, kind, paper_fn, total in items:
            rows = []
            for g in groups:
                pv = paper_fn(g) if paper_fn else None
                if isinstance(pv, str):
                    r = [g, pv]
                else:
                    r = [g, fmt(pv, kind) if pv is not None and math.isfinite(pv) else "–"]
                r += [group_cell(studies[lab], g, metric, kind, total) for lab in labels]
                rows.append(r)
            L += [f"**{label}**", "", markdown_table(["group", "paper"] + labels, rows), ""]
        if title.startswith("Penetration"):
            rows = [[g] + [fmt(studies[lab].pi_max(g), "f2") if g in studies[lab].groups else "–" for lab in labels]
                    for g in groups]
            L += ["**maximum PI (preset's constants; the paper: 3.79 in ID-1)**", "",
                  markdown_table(["group"] + labels, rows), ""]
    return L


def _paired_section(studies: dict) -> list[str]:
    L = ["## Paired comparisons with B-2 over the same encounters", "",
         "LoWC encounters: exact McNemar test on the encounters where exactly one of the two groups lost well clear; "
         "ΔP(LoWC) with its paired-bootstrap 95 % CI.", ""]
    for lab, st in studies.items():
        if st.baseline not in st.groups:
            L += [f"*{lab}*: no B-2 group, no comparison.", ""]
            continue
        rows = []
        for g in st.groups:
            if g == st.baseline:
                continue
            m = st.mcnemar(g, st.baseline)
            d = st._boot_estimate(st.change_sample(g, "p_lowc", st.baseline, "difference"), "paired bootstrap")
            rows.append([g, f"{m.a_only} / {m.b_only}", f"{m.p_value:.3g}", estimate_text(d, "pct")])
        L += [f"*{lab}*", "", markdown_table(["group", f"LoWC only in group / only in {st.baseline}", "McNemar p",
                                      "ΔP(LoWC) [95 % CI]"], rows), ""]
    return L


ABLATION_METRICS = (("DAA allocations (no-wait) per encounter", "no_wait", "g3"),
                    ("pilot commands received per encounter", "received", "g3"),
                    ("P(LoWC) per encounter", "p_lowc", "pct"),
                    ("mean PI, paper's Eq. constants (s)", "pi_paper_mean", "f2"),
                    ("mean PI, preset's constants (s)", "pi_mean", "f2"))


def ablation_rows(st: Study, full: str, abl: str) -> list[dict]:
    """The ablation of ``abl`` against ``full`` over the same encounters: per metric the two values
    and the paired difference ``full - abl`` with its CI (McNemar for LoWC encounters)."""
    out = []
    for label, metric, kind in ABLATION_METRICS:
        if not (st.available(full, metric) and st.available(abl, metric)):
            continue
        d = st._boot_estimate(st.change_sample(full, metric, abl, "difference"), "paired bootstrap")
        row = {"label": label, "metric": metric, "kind": kind, "full": st.estimate(full, metric),
               "ablation": st.estimate(abl, metric), "diff": d}
        if metric == "p_lowc":
            m = st.mcnemar(full, abl)
            row["mcnemar"] = m
            row["measurable"] = m.p_value < 1.0 - st.conf
        else:
            row["measurable"] = math.isfinite(d.lo) and (d.lo > 0 or d.hi < 0)
        out.append(row)
    return out


def _ablation_section(studies: dict) -> list[str]:
    L = ["## Ablation: what the wait map adds", ""]
    any_ = False
    for lab, st in studies.items():
        for full, abl, what in ABLATIONS:
            if full not in st.groups or abl not in st.groups:
                continue
            any_ = True
            rows = ablation_rows(st, full, abl)
            body = []
            for r in rows:
                m = r.get("mcnemar")
                test = (f"McNemar {m.a_only}/{m.b_only} discordant, p = {m.p_value:.3g}" if m else "paired bootstrap")
                body.append([r["label"], estimate_text(r["full"], r["kind"]), estimate_text(r["ablation"], r["kind"]),
                             estimate_text(r["diff"], r["kind"]), test, "yes" if r["measurable"] else "no"])
            L += [f"### {lab}: {what}", "",
                  markdown_table(["metric", full, abl, f"{full} − {abl} [95 % CI]", "test", "measurable?"], body), ""]
            nothing = [r for r in rows if not r["measurable"]]
            why = ""
            if st.provenance.get(full):
                why = (f" In {full} the map decided {group_cell(st, full, 'map_decided_share', 'pct', False)} of the "
                       f"wait/no-wait decisions (the rest would be the same with \"always wait\"), and "
                       f"{group_cell(st, full, 'in_box_share', 'pct', False)} of its lookups fell inside the map's box.")
            if rows and len(nothing) == len(rows):
                L += [f"**The difference is not measurable on any metric**: every paired 95 % CI of {full} − {abl} "
                      f"includes 0 (and McNemar p ≥ 0.05 for LoWC encounters) over {st.n:,} encounters. "
                      + ("The map adds nothing measurable to ProjL here." if abl.endswith("projl") else
                         "ProjL adds nothing measurable to the map here.") + why, ""]
            else:
                yes = ", ".join(r["label"] for r in rows if r["measurable"])
                no = ", ".join(r["label"] for r in nothing) or "none"
                L += [f"Measurable differences: {yes}. Not measurable (CI includes 0): {no}.{why}", ""]
    if not any_:
        L += ["No ablation groups in these results (run `ID-2-projl` and/or `ID-2-map` beside `ID-2`).", ""]
    return L


def _provenance_section(studies: dict) -> list[str]:
    L = ["## Decision provenance", "",
         "Share of wait/no-wait decisions the map decided (`decided_by = map`: the decision would differ with "
         "the map replaced by \"always wait\"), the share where map and ProjL both said no-wait, and the share of "
         "wait-map lookups inside the map's box; encounter-level 95 % CIs (ratio estimators). In groups without a "
         "map the same test applies to the group's wait function: B-1/B-2 wait w = 0 s (below W_T, so every decision "
         "they take as no-wait without ProjL counts as decided by it), IC-1 waits a constant 5 s (at or above W_T: "
         "never differs from \"always wait\"), ID-2-projl always waits. Only the ID groups read a map.", ""]
    for lab, st in studies.items():
        have = [g for g in st.groups if st.provenance.get(g)]
        if not have:
            L += [f"*{lab}*: skipped — the decision tables carry no `decided_by` / `in_box` columns.", ""]
            continue
        rows = []
        for g in have:
            rows.append([g, group_cell(st, g, "map_decided_share", "pct", False),
                         group_cell(st, g, "map_or_both_share", "pct", False), group_cell(st, g, "in_box_share", "pct", False),
                         fmt(st.sum(g, "n_dec").value, "int") if st.has(g, "n_dec") else "–",
                         fmt(st.sum(g, "n_lookup").value, "int") if st.has(g, "n_lookup") else "–"])
        L += [f"*{lab}*", "", markdown_table(["group", "decided by the wait function (map)", "map or both", "lookups inside the box",
                                      "decisions", "lookups"], rows), ""]
    return L


def _seed_section(blocks, studies, rows) -> list[str]:
    """Readings run on more than one campaign seed: do the seeds agree within CIs?"""
    by_name: dict = {}
    for b in blocks:
        by_name.setdefault((b.reading.name, json.dumps(b.reading.settings, sort_keys=True, default=str)), []).append(b)
    # only different seeds: one seed's smaller run is the first encounters of its larger one, not an
    # independent sample, so an independent-bootstrap difference would not mean anything there
    pairs = [(v[0], w) for v in by_name.values() if len(v) > 1 for w in v[1:] if w.seed != v[0].seed]
    if not pairs:
        return []
    L = ["## Agreement between campaign seeds", "",
         "The same reading on different encounter sets: the seeds agree on a finding when the 95 % CI of the "
         "difference of the two estimates (independent bootstraps, percentile interval) includes 0.", ""]
    for a, b in pairs:
        sa, sb = studies[a.label], studies[b.label]
        body, disagree = [], 0
        for f, _ in rows:
            if f.kind in ("ordering", "zero") or any(g not in sa.groups or g not in sb.groups for g in f.groups_needed):
                continue
            try:
                xa, xb = finding_sample(f, sa), finding_sample(f, sb)
            except (UsageError, KeyError):
                continue
            d = independent_difference(xa, xb, sa.boot.seed)
            lo, hi = d.interval(sa.conf)
            if not math.isfinite(d.value):
                continue
            ok = lo <= 0 <= hi
            disagree += not ok
            k = f.value_format
            body.append([f.label, fmt(xa.value, k), fmt(xb.value, k),
                         f"{fmt(d.value, k)} [{fmt(lo, k)}, {fmt(hi, k)}]", "yes" if ok else "**no**"])
        L += [f"### {a.label} vs {b.label}", "", markdown_table(["finding", a.label, b.label, "difference [95 % CI]", "agree?"],
                                                          body), "",
              f"{len(body) - disagree} of {len(body)} findings agree within the CI; {disagree} do not.", ""]
    return L


def _width_section(blocks, studies) -> list[str]:
    """Encounter-level interval widths against the old per-step (Poisson/Clopper-Pearson) ones."""
    b = blocks[0]
    st = studies[b.label]
    try:
        old = compute_metrics(b.enc, baseline=st.baseline, conf=st.conf)
    except (UsageError, FileFormatError):
        return []
    rows = []
    for g in st.groups:
        r = [g]
        n_g = st.n_encounters(g)
        for key, old_key, scale in (("no_wait", "no_wait", n_g), ("received", "received", n_g),
                                    ("exact_match", "exact_match", 1.0), ("p_lowc_per_hr", "p_lowc_per_hr", 1.0)):
            new = st.estimate(g, key)
            o = old[g].get(old_key)
            wn = (new.hi - new.lo) * scale
            wo = (o.hi - o.lo) if o is not None else math.nan
            r.append(f"{wn / wo:.1f}×" if wo and math.isfinite(wn) and math.isfinite(wo) and wo > 0 else "–")
        rows.append(r)
    return ["### Interval widths: encounter-level vs the old per-step intervals", "",
            f"Width of our 95 % CI divided by the width of the per-step interval the report used before ({b.label}): "
            "counts (Garwood Poisson), exact match (Clopper-Pearson over blends), P(LoWC)/flight hour (Clopper-Pearson "
            "over steps). Values above 1 mean the per-step interval was too narrow.", "",
            markdown_table(["group", "no-wait", "received", "exact match", "P(LoWC)/flight hr"], rows), ""]


def _methods(blocks, studies, replicates: int, seed: int, conf: float) -> list[str]:
    st = next(iter(studies.values()))
    L = ["## Methods", "",
         f"- **Intervals**: {100 * conf:.0f} % throughout. Encounter-level (cluster) bootstrap, {replicates:,} "
         f"replicates, bootstrap seed {seed} (reproducible: `--replicates {replicates} --bootstrap-seed {seed}`), "
         "BCa intervals (bias-corrected and accelerated, acceleration from the leave-one-encounter-out jackknife). "
         "The same resampling weights are applied to every group of a campaign (the groups fly the same "
         "encounter ids), so changes and differences between groups are paired. Encounter proportions (LoWC, NMAC, "
         "turning share) use Clopper-Pearson; zeros get the exact upper bounds 1 − α^(1/n) (one-sided) and "
         "1 − (α/2)^(1/n) (upper limit of the two-sided interval). Code: `daa_sil/study/stats.py`, `daa_sil/study/metrics.py`, `daa_sil/study/analysis.py`.",
         "- **P(LoWC) per flight hour**: the paper's Eq. P(LoWC)/(total flight hours) divides a per-step "
         "probability by the campaign's size, so the same per-step risk gives a 10× smaller value with 10× more "
         "encounters; it is not a rate. It is compared with the paper's Table 7 at the paper's 666.67 flight hours. "
         "The rate is the number of LoWC encounters per flight hour (Clopper-Pearson on the encounters, scaled).",
         "- **PI**: integrated on the continuous segment between two steps over the exact LoWC interval the LoWC "
         "detector finds (`daa_sil/geometry/wellclear.py: segment_penetration`, midpoint rule with 16 nodes on the "
         "interval), with the paper's Eq. constants (4000 ft / 450 ft / 35 s; column `pi_paper`) and with the "
         "preset's (column `pi`). A LoWC of positive duration cannot get PI = 0 (the per-group table counts any).",
         "- **Counts**: per encounter over the counting window of the reading; a reading's counting settings select "
         "the per-encounter columns (`daa_sil/study/counting.py: COUNT_SOURCES`).", ""]
    notes = [f"- {lab}: {n}" for lab, s in studies.items() for n in s.notes]
    if notes:
        L += ["Notes:", ""] + notes + [""]
    L += _width_section(blocks, studies)
    return L




# --- report ---------------------------------------------------------------------------------------
def render_markdown(blocks: Sequence[Block], studies: dict, rows, *, replicates: int, seed: int, conf: float,
                    figures: dict, notes: Sequence[str] = ()) -> str:
    """The report text (see the module docstring); ``notes`` are paragraphs printed after the intro."""
    L = ["# daa-sil campaign report", "",
         "Tabassum & Bai's findings against our fast-time study, one column block per named reading of the "
         "paper, with encounter-level 95 % confidence intervals and a verdict rule that can fail. Paper values: "
         "`daa_sil/data/paper_results.yaml`.", ""]
    for note in notes:
        L += [str(note), ""]
    L += _sources(blocks, studies)
    L += findings_section(blocks, rows)
    L += signature_section(studies)
    L += inconsistency_section(studies)
    L += _ablation_section(studies)
    L += _provenance_section(studies)
    L += _paired_section(studies)
    L += _group_tables(studies)
    L += _seed_section(blocks, studies, rows)
    L += ["## Figures", ""]
    for lab, paths in figures.items():
        L += [f"*{lab}*", ""] + [f"![{p.stem}]({p.name})" for p in paths] + [""]
    L += _methods(blocks, studies, replicates, seed, conf)
    return "\n".join(L)


def findings_json(blocks, rows, replicates: int, seed: int, conf: float) -> dict:
    """Machine-readable findings: every finding, the paper's value and each reading's outcome."""
    return {"bootstrap": {"replicates": replicates, "seed": seed, "conf": conf},
            "readings": [{"label": b.label, "reading": b.reading.name, "settings": dict(b.reading.settings),
                          "source": b.reading.source, "campaign_seed": b.seed} for b in blocks],
            "findings": [{"id": f.id, "claim": f.label, "source": f.source, "kind": f.kind, "metric": f.metric,
                          "group": f.group, "paper": f.paper_value(), "paper_text": f.paper_text(),
                          "outcomes": {lab: {"verdict": o.verdict, "text": o.text, "evidence": o.evidence,
                                             "value": _finite(o.value), "lo": _finite(o.lo), "hi": _finite(o.hi)}
                                       for lab, o in outs.items()}} for f, outs in rows]}


def _finite(x):
    return float(x) if isinstance(x, (int, float, np.floating)) and math.isfinite(x) else None


def write_report(src, out_dir: "str | os.PathLike", baseline: str = BASELINE_GROUP, conf: float = CONF, *,
                 replicates: int = DEFAULT_REPLICATES, seed: int = DEFAULT_SEED, recount: Sequence[str] = (),
                 notes: Sequence[str] = ()) -> Path:
    """Compute the study of ``src`` (a campaign directory, a list of them, or one results source)
    and write ``out_dir/report.md``, ``out_dir/findings.json`` and the PNG figures; returns the report
    path. FileFormatError for a missing, empty or corrupt results source (nothing is written)."""
    blocks = build_blocks(src, recount)
    studies = {b.label: Study(b.enc, b.reading, dec=b.dec, replicates=replicates, seed=seed, conf=conf,
                              baseline=baseline, dt_s=float((b.meta or {}).get("dt_s") or 1.0)) for b in blocks}
    rows = evaluate_all(studies)
    out = ensure_dir(out_dir)
    figures = {}
    for i, b in enumerate(blocks):
        figures[b.label] = group_figures(studies[b.label], out, "" if i == 0 else f"-{file_slug(b.label)}")
    text = render_markdown(blocks, studies, rows, replicates=replicates, seed=seed, conf=conf, figures=figures,
                           notes=notes)
    from daa_sil.files import atomic_write_json

    atomic_write_json(out / "findings.json", findings_json(blocks, rows, replicates, seed, conf))
    return atomic_write_text(out / "report.md", text)


__all__ = ["write_report", "load_results", "load_block", "build_blocks", "render_markdown", "findings_json",
           "ablation_rows", "parse_recount", "Block", "FIGURES", "ABLATIONS"]
