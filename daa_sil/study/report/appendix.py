"""The report's appendix pages: the readings side by side (``appendix-readings.md``), the ablation of the
wait map, decision provenance and the paired comparisons (``appendix-ablations.md``), and the sources,
seeds, the paper's self-contradictions and the methods (``appendix-provenance.md``). No table is wider
than :data:`daa_sil.study.report.markdown.MAX_COLUMNS` columns: wide ones are split."""

from __future__ import annotations

import json
import math
from typing import Sequence

from daa_sil.errors import FileFormatError, UsageError
from daa_sil.study.analysis.study import Study
from daa_sil.study.analysis.counting import COUNTING_DEFAULTS, COUNTING_HELP, counting_options
from daa_sil.study.analysis.findings import APART, EMPIRICAL, NOT_TESTABLE, fmt
from daa_sil.study.analysis.metrics import compute_metrics
from daa_sil.study.report.paper_checks import inconsistency_section
from daa_sil.study.report.markdown import (GROUP_TABLES, estimate_text, group_cell, groups_in_order, markdown_table,
                                         reading_label, wide_table)
from daa_sil.study.report.signatures import SIGNATURES, our_cell, paper_cell
from daa_sil.study.analysis.stats import independent_difference
from daa_sil.study.analysis.verdicts import finding_sample, tally

#: the wait-map ablation: (group with the map and ProjL, ablation group, what the difference measures)
ABLATIONS = (("ID-2", "ID-2-projl", "what the map adds to ProjL (ID-2 minus ID-2-projl)"),
             ("ID-2", "ID-2-map", "what ProjL adds to the map (ID-2 minus ID-2-map)"))


# --- appendix: readings ------------------------------------------------------------------------------
def sources_lines(blocks, studies: dict) -> list[str]:
    """The readings, their results and seeds; then each reading's settings (a list, not a wide table)."""
    rows = []
    for b in blocks:
        st = studies[b.label]
        rows.append([reading_label(b.label), f"`{b.reading.source}`" if b.reading.source else "(table)",
                     "–" if b.seed is None else str(b.seed), f"{st.n:,}", ", ".join(st.groups),
                     (b.meta or {}).get("preset") or "–"])
    L = ["## Readings and sources", "",
         markdown_table(["reading", "results", "campaign seed", "encounters", "groups", "preset"], rows), ""]
    L += ["Settings of each reading (`daa_sil/config/readings.py`; the basis of each setting of `paper`: the main "
          "page):", ""]
    for b in blocks:
        L.append(f"- {reading_label(b.label)}: {b.reading.describe()}")
    L += ["", "Counting settings (the same simulation can be counted several ways; `--recount` adds a reading):", ""]
    for k, opts in counting_options().items():
        helps = COUNTING_HELP.get(k, {})
        L.append(f"- `{k}` (default `{COUNTING_DEFAULTS.get(k, '–')}`): "
                 + "; ".join(f"`{o}` = {helps.get(o, 'see daa_sil/study/analysis/counting.py COUNT_SOURCES')}" for o in opts))
    return L + [""]


def tally_lines(rows, labels: Sequence[str]) -> list[str]:
    """The headline tally of each reading over every finding (the same set for each: ``findings``), split
    into the empirical verdicts and the ones counted apart; the two parts add up to ``findings``."""
    body = []
    for lab in labels:
        c = tally(rows, lab)
        body.append([reading_label(lab), str(len(rows)), str(sum(c[v] for v in EMPIRICAL))]
                    + [str(c[v]) for v in EMPIRICAL] + [str(c[v]) for v in APART] + [str(c[NOT_TESTABLE])])
    return [markdown_table(["reading", "findings", "empirical"] + list(EMPIRICAL) + list(APART) + [NOT_TESTABLE],
                           body), ""]


def readings_page(blocks, studies: dict, rows, figures: dict, intro: Sequence[str] = ()) -> str:
    """``appendix-readings.md``: every reading's verdicts and signatures side by side."""
    labels = [b.label for b in blocks]
    L = ["# Appendix: the readings side by side", ""] + [str(x) for x in intro] + [""]
    L += ["## Headline tally of every reading", ""] + tally_lines(rows, labels)
    L += sources_lines(blocks, studies)
    L += ["## Every finding under every reading", "",
          "Each cell: the verdict, then our value [95 % CI]. The column *Tabassum & Bai* is the published number; "
          "the reading called `paper` is a column like the others.", ""]
    fixed = ["#", "finding", "Tabassum & Bai"]
    frows = [[str(i), f.label, f.paper_text()] for i, (f, _) in enumerate(rows, 1)]
    cells = [[(f"{outs[lab].verdict}: {outs[lab].text}" if outs[lab].verdict != NOT_TESTABLE
               else f"{NOT_TESTABLE} ({outs[lab].evidence})") for _, outs in rows] for lab in labels]
    L += wide_table(fixed, frows, [reading_label(x) for x in labels], cells, max_columns=8)
    L += ["## Signatures under every reading", ""]
    for g in groups_in_order(studies):
        srows = [[s.label, paper_cell(s, g)] for s in SIGNATURES]
        scells = [[our_cell(studies[lab], s, g) for s in SIGNATURES] for lab in labels]
        if all(all(c == "–" for c in col) for col in scells):
            continue
        L += [f"**{g}**", ""] + wide_table(["signature", "Tabassum & Bai = their arithmetic"], srows,
                                            [reading_label(x) for x in labels], scells, max_columns=8)
    if len(figures) > 1:
        L += ["## Figures of the other readings", ""]
        for lab, paths in list(figures.items())[1:]:
            L += [f"*{reading_label(lab)}*", ""] + [f"![{p.stem}]({p.name})" for p in paths] + [""]
    return "\n".join(L) + "\n"


def group_table_lines(studies: dict) -> list[str]:
    groups = groups_in_order(studies)
    labels = list(studies)
    L = ["## Per-group tables", "",
         "Value [95 % CI] per reading; counts per encounter with the total in brackets. Zeros carry exact "
         "upper bounds on the share of encounters instead of an interval.", ""]
    for title, items in GROUP_TABLES:
        L += [f"### {title}", ""]
        L0, L = L, []
        for label, metric, kind, paper_fn, total in items:
            rows = []
            for g in groups:
                pv = paper_fn(g) if paper_fn else None
                if isinstance(pv, str):
                    rows.append([g, pv])
                else:
                    rows.append([g, fmt(pv, kind) if pv is not None and math.isfinite(pv) else "–"])
            cells = [[group_cell(studies[lab], g, metric, kind, total) for g in groups] for lab in labels]
            L += [f"**{label}**", ""] + wide_table(["group", "Tabassum & Bai"], rows,
                                                   [reading_label(x) for x in labels], cells, max_columns=8)
        if title.startswith("Penetration"):
            cells = [[fmt(studies[lab].pi_max(g), "f2") if g in studies[lab].groups else "–" for g in groups]
                     for lab in labels]
            L += ["**maximum PI (preset's constants; the paper: 3.79 in ID-1)**", ""]
            L += wide_table(["group"], [[g] for g in groups], [reading_label(x) for x in labels], cells)
        L = L0 + collapsed(f"{title}: every reading", L)
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


def collapsed(summary: str, lines: Sequence[str]) -> list[str]:
    """``lines`` (Markdown) inside a collapsed block titled ``summary`` (HTML details, as GitHub renders)."""
    return ["<details>", f"<summary>{summary}</summary>", ""] + list(lines) + ["</details>", ""]


def _ablation_detail(lab: str, st: Study, full: str, abl: str, what: str, rows: list) -> list[str]:
    body = []
    for r in rows:
        m = r.get("mcnemar")
        test = (f"McNemar {m.a_only}/{m.b_only} discordant, p = {m.p_value:.3g}" if m else "paired bootstrap")
        body.append([r["label"], estimate_text(r["full"], r["kind"]), estimate_text(r["ablation"], r["kind"]),
                     estimate_text(r["diff"], r["kind"]), test, "yes" if r["measurable"] else "no"])
    L = [f"#### {lab}: {what}", "",
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
    return L


def ablation_lines(studies: dict) -> list[str]:
    """Per ablation, one summary row per reading (the paired differences, bold where measurable), then
    each reading's table with both groups' values and the tests, collapsed."""
    L = ["## Ablation: what the wait map adds", "",
         "Per ablation, one row per reading: the paired difference over the same encounters [95 % CI], in "
         "**bold** where it is measurable (the CI excludes 0; for LoWC encounters McNemar p < 0.05). Each "
         "reading's table, with both groups' values and the test, is collapsed below its summary.", ""]
    any_ = False
    for full, abl, what in ABLATIONS:
        summary, detail = [], []
        for lab, st in studies.items():
            if full not in st.groups or abl not in st.groups:
                continue
            rows = ablation_rows(st, full, abl)
            by = {r["metric"]: r for r in rows}
            cells = []
            for _, metric, kind in ABLATION_METRICS:
                r = by.get(metric)
                txt = estimate_text(r["diff"], r["kind"]) if r else "–"
                cells.append(f"**{txt}**" if r and r["measurable"] else txt)
            summary.append([reading_label(lab)] + cells)
            detail += _ablation_detail(lab, st, full, abl, what, rows)
        if not summary:
            continue
        any_ = True
        L += [f"### {what[0].upper()}{what[1:]}", "",
              markdown_table(["reading"] + [f"Δ {label}" for label, _, _ in ABLATION_METRICS], summary), ""]
        L += collapsed(f"{what}: each reading's values and tests", detail)
    if not any_:
        L += ["No ablation groups in these results (run `ID-2-projl` and/or `ID-2-map` beside `ID-2`).", ""]
    return L


def provenance_lines(studies: dict) -> list[str]:
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


def paired_lines(studies: dict) -> list[str]:
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


def ablations_page(studies: dict, rows, intro: Sequence[str] = ()) -> str:
    """``appendix-ablations.md``: the wait map's ablation, decision provenance, the paired comparisons with
    B-2 and the per-group tables of every reading."""
    L = ["# Appendix: ablations, decision provenance, paired comparisons, per-group tables", ""]
    L += [str(x) for x in intro] + [""]
    prov, paired = provenance_lines(studies), paired_lines(studies)
    map_rows = [[reading_label(lab), group_cell(st, "ID-2", "map_decided_share", "pct", False),
                 group_cell(st, "ID-2", "in_box_share", "pct", False)]
                for lab, st in studies.items() if st.provenance.get("ID-2")]
    L += ablation_lines(studies) + prov[:4]
    if map_rows:
        L += [markdown_table(["reading", "ID-2: decided by the map", "ID-2: lookups inside the box"], map_rows), ""]
    L += collapsed("every reading's groups", prov[4:]) + paired[:4]
    L += collapsed("every reading's groups against B-2", paired[4:]) + group_table_lines(studies)
    return "\n".join(L) + "\n"


def seed_lines(blocks, studies, rows) -> list[str]:
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
              f"{len(body) - disagree} of the {len(body)} findings compared agree within the CI; {disagree} do not "
              f"(of the {len(rows)} findings, the orderings and the zero-event claims have no difference to compare, "
              "and neither has a finding whose groups one of the two campaigns lacks).", ""]
    return L


def width_lines(blocks, studies) -> list[str]:
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


def methods_lines(blocks, studies, replicates: int, seed: int, conf: float) -> list[str]:
    st = next(iter(studies.values()))
    L = ["## Methods", "",
         f"- **Intervals**: {100 * conf:.0f} % throughout. Encounter-level (cluster) bootstrap, {replicates:,} "
         f"replicates, bootstrap seed {seed} (reproducible: `--replicates {replicates} --bootstrap-seed {seed}`), "
         "BCa intervals (bias-corrected and accelerated, acceleration from the leave-one-encounter-out jackknife). "
         "The same resampling weights are applied to every group of a campaign (the groups fly the same "
         "encounter ids), so changes and differences between groups are paired. Encounter proportions (LoWC, NMAC, "
         "turning share) use Clopper-Pearson; zeros get the exact upper bounds 1 − α^(1/n) (one-sided) and "
         "1 − (α/2)^(1/n) (upper limit of the two-sided interval). Code: `daa_sil/study/analysis/stats.py`, `daa_sil/study/analysis/metrics.py`, `daa_sil/study/analysis/study.py`.",
         "- **P(LoWC) per flight hour**: the paper's Eq. P(LoWC)/(total flight hours) divides a per-step "
         "probability by the campaign's size, so the same per-step risk gives a 10× smaller value with 10× more "
         "encounters; it is not a rate. It is compared with the paper's Table 7 at the paper's 666.67 flight hours. "
         "The rate is the number of LoWC encounters per flight hour (Clopper-Pearson on the encounters, scaled).",
         "- **PI**: integrated on the continuous segment between two steps over the exact LoWC interval the LoWC "
         "detector finds (`daa_sil/geometry/penetration.py: segment_penetration`, midpoint rule with 16 nodes on the "
         "interval), with the paper's Eq. constants (4000 ft / 450 ft / 35 s; column `pi_paper`) and with the "
         "preset's (column `pi`). A LoWC of positive duration cannot get PI = 0 (the per-group table counts any).",
         "- **Counts**: per encounter over the counting window of the reading; a reading's counting settings select "
         "the per-encounter columns (`daa_sil/study/analysis/counting.py: COUNT_SOURCES`).", ""]
    notes = [f"- {lab}: {n}" for lab, s in studies.items() for n in s.notes]
    if notes:
        L += ["Notes:", ""] + notes + [""]
    L += width_lines(blocks, studies)
    return L




def provenance_page(blocks, studies: dict, rows, *, replicates: int, seed: int, conf: float,
                    intro: Sequence[str] = ()) -> str:
    """``appendix-provenance.md``: sources and seeds, the seeds' agreement, where the paper contradicts
    itself, the methods."""
    L = ["# Appendix: provenance, the paper's self-contradictions, methods", ""] + [str(x) for x in intro] + [""]
    L += sources_lines(blocks, studies) + seed_lines(blocks, studies, rows) + inconsistency_section(studies)
    L += methods_lines(blocks, studies, replicates, seed, conf)
    return "\n".join(L) + "\n"


__all__ = ["ABLATIONS", "ABLATION_METRICS", "ablation_rows", "readings_page", "ablations_page", "provenance_page",
           "tally_lines", "sources_lines"]
