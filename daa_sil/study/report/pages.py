"""Campaign report: the main page (the first reading against the paper), three appendix pages, the
PNG figures and ``findings.json``.

One or more campaign directories, each one named *reading* of the paper (``campaign.json``
``config.reading`` / ``config.readings`` / ``basis``), side by side. The **main page** (``report.md``,
or ``main_name``) is the first reading against the paper: what was run and how to run it again, the
headline tally, the basis of every setting (``campaign.json`` ``basis``), every finding of the paper
(``daa_sil/data/paper_findings.yaml``) with our value, its encounter-level 95 % CI, the verdict and its
evidence, the attribution of every miss (with ``experiments``: ``experiments.json``), the signatures,
the verdict rules and the figures. The **appendices** (:mod:`daa_sil.study.report.appendix`):
``appendix-readings.md`` (every reading side by side), ``appendix-ablations.md`` (the wait map's
ablation, decision provenance, paired comparisons, per-group tables), ``appendix-provenance.md``
(sources, seeds, the paper's self-contradictions, methods). No table is wider than 12 columns.

Input of :func:`write_report`: a campaign directory or a list of them, a list of per-encounter Parquet
files, a pyarrow Table or a dict of arrays. Every file is written atomically.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import replace
from pathlib import Path
from typing import Sequence

import numpy as np

from daa_sil.config.basis import KINDS, consumed_findings
from daa_sil.files import atomic_write_text, ensure_dir, to_jsonable
from daa_sil.study.analysis.study import Study
from daa_sil.study.analysis.attribution import CAUSES, attribution_rows
from daa_sil.study.analysis.findings import APART, EMPIRICAL, NOT_TESTABLE, VERDICTS, fmt, untestable_statements
from daa_sil.study.analysis.metrics import BASELINE_GROUP, CONF
from daa_sil.study.report.appendix import (ABLATIONS, ablation_rows, ablations_page, provenance_page, readings_page,
                                           tally_lines)
from daa_sil.study.report.figures import file_slug, group_figures
from daa_sil.study.report.verdict_words import VERDICT_MEANING, basis_changes, rounded
from daa_sil.study.report.markdown import groups_in_order, markdown_table, reading_label
from daa_sil.study.analysis.report_input import Block, build_blocks
from daa_sil.study.report.signatures import SIGNATURES, our_cell, paper_cell
from daa_sil.study.analysis.stats import DEFAULT_REPLICATES, DEFAULT_SEED
from daa_sil.study.analysis.verdicts import RULES, evaluate_all
from daa_sil.study.analysis.verdicts import tally

#: the appendix pages, in the order the main page links them
APPENDICES = ("appendix-readings.md", "appendix-ablations.md", "appendix-provenance.md")
#: what each kind of basis means (the basis table's legend)
KIND_MEANING = {"text": "a quoted sentence says so", "inference": "we infer it, from a sentence or from a published "
                "number (the arithmetic is given; a number used so is never counted as a reproduction)",
                "choice": "the paper says nothing; the value is ours"}


def basis_lines(block: Block) -> list[str]:
    """The basis of every setting of the main reading, from its ``campaign.json`` (one definition:
    :mod:`daa_sil.config.basis`)."""
    rec = (block.meta or {}).get("basis")
    if not rec:
        return ["## The settings and what each rests on", "", "(no basis recorded in this campaign's campaign.json)",
                ""]
    L = ["## The settings and what each rests on", "",
         f"Every setting of {reading_label(block.reading.name)}, from `campaign.json` (`basis`). Kinds: "
         + "; ".join(f"**{k}**: {KIND_MEANING[k]}" for k in KINDS) + ". A row marked *differs* is a setting of this "
         "reading that differs from `paper`'s.", ""]
    body = []
    for r in rec:
        val = r["paper_value"] if not r.get("differs") else "*differs*: " + ", ".join(
            f"{k} = {v}" for k, v in r.get("values", {}).items())
        said = " — ".join(x for x in (r.get("quote", ""), r.get("reasoning", "")) if x)
        body.append([r["setting"], val, r["kind"], said, r.get("alternatives", "") or "–"])
    return L + [markdown_table(["setting", "value", "kind", "the paper says / our reasoning", "the other readings"],
                               body), ""]


def findings_lines(rows, label: str) -> list[str]:
    body = []
    for i, (f, outs) in enumerate(rows, 1):
        o = outs[label]
        kind = f"{f.kind} (by construction)" if f.by_construction else f.kind
        verdict = f"**{o.verdict}**" if o.verdict != NOT_TESTABLE else NOT_TESTABLE
        body.append([str(i), f.label, f.source, kind, f.paper_text(), o.text, verdict, o.evidence])
    return ["## Every finding of the paper", "",
            "Counts are per encounter (the paper's totals divided by its 10,000 encounters), changes in %. *Ours* is "
            "our value with its encounter-level 95 % CI; the evidence says how the verdict's rule (below) came out.",
            "", markdown_table(["#", "finding", "source", "kind", "Tabassum & Bai", "ours [95 % CI]", "verdict",
                                "evidence"], body), ""]


def attribution_lines(rows, label: str, experiments: "dict | None") -> list[str]:
    exps = (experiments or {}).get("experiments")
    meta = (experiments or {}).get("meta") or {}
    L = ["## Where the misses come from", "",
         "Every finding missed (not reproduced, or only its direction) belongs to one cluster, with its named cause, "
         "the experiments that test it, the commands that make them (RUNS: the runs directory; the figures: "
         "[experiments.md](experiments.md)) and what they showed. Causes: " + ", ".join(CAUSES) + ". A miss "
         "outside every cluster would show as a row *unattributed*; a cluster whose experiments found no cause "
         "says so in its row.", ""]
    body = []
    for r in attribution_rows(rows, label, exps, meta):
        body.append([r["cluster"], "; ".join(r["misses"]) or "none", ", ".join(r["causes"]) or "none found",
                     r["because"], ", ".join(f"`{e}`" for e in r["experiments"]) or "–",
                     "; then ".join(f"`{c}`" for c in r["commands"]) or "–", r["showed"] or "–"])
    return L + [markdown_table(["cluster", "misses", "cause", "in words", "experiments", "commands",
                                "what they showed"], body), ""]


#: the signatures' short names in the main page's table headers
SHORT_SIGNATURE = {"unsafe": "unsafe on arrival", "daa_per_received": "DAA / received", "received": "received / enc.",
                   "wait_per_received": "waits / received"}


def signature_lines(st: Study, label: str) -> list[str]:
    """Two tables: the signatures the paper's tables give (Tabassum & Bai's value with its arithmetic
    beside ours, a row per group) and those it does not give (ours only)."""
    groups = groups_in_order({label: st})
    given = [s for s in SIGNATURES if any(s.paper(g) is not None for g in groups)]
    rest = [s for s in SIGNATURES if s not in given]
    head = ["group"]
    for s in given:
        name = SHORT_SIGNATURE.get(s.key, s.label)
        head += [f"{name}: Tabassum & Bai", f"{name}: ours [95 % CI]"]
    body = [[g] + [c for s in given for c in (paper_cell(s, g), our_cell(st, s, g))] for g in groups]
    L = ["## Signatures: does our simulator behave like the paper's?", "",
         "Quantities the paper's tables give (Tabassum & Bai's value = its arithmetic on their totals over 10,000 "
         "encounters) or that characterise a simulator, ours with their 95 % CIs. *Unsafe on arrival* is the share "
         "of arriving commands not executed as sent, (override + blend) / (pilot + override + blend): overridden in "
         "the baselines, blended in the integrated groups. *DAA / received*: DAA allocations (no-wait decisions) per "
         "received command; *waits / received*: waits per received command; *received / enc.*: commands received "
         "per encounter.", "", markdown_table(head, body), ""]
    if rest:
        L += ["Not given by the paper (ours only; *authority* is the pilot, the waiting agent or the DAA, "
              "step by step):", "",
              markdown_table(["group"] + [s.label for s in rest], [[g] + [our_cell(st, s, g) for s in rest]
                                                                   for g in groups]), ""]
    return L


def untestable_lines() -> list[str]:
    un = untestable_statements()
    if not un:
        return []
    return (["Statements of the paper with no quantity to test (no verdict, not in the tally):", ""]
            + [f"- \"{u['claim']}\" — {u['why']}" for u in un] + [""])


def rules_lines() -> list[str]:
    L = ["## Verdict words and rules", ""]
    L += [f"- **{k}**: {v}." for k, v in VERDICT_MEANING.items()]
    L += ["", "The rules, one per kind of finding (95 % throughout; the paper's numbers are estimates with their own "
          "error, so values and changes are compared as two samples):", ""]
    L += [f"- **{k}**: {v}." for k, v in RULES.items()]
    return L + [""]


def _grouped(rows, label: str, verdicts) -> list[str]:
    """``finding (groups)`` of the rows of ``label`` whose verdict is in ``verdicts``, one entry per finding."""
    out: dict = {}
    for f, outs in rows:
        if outs[label].verdict in verdicts:
            out.setdefault(f.claim, []).append(f.group or ("pooled over " + ", ".join(f.pooled) if f.pooled else ""))
    return [f"{k} ({', '.join(g for g in v if g)})" if any(v) else k for k, v in out.items()]


def summary_lines(rows, label: str, experiments: "dict | None") -> list[str]:
    """In short: the tally in words, what is reproduced, and each cluster of misses with its cause."""

    c = tally(rows, label)
    n_emp = sum(c[v] for v in EMPIRICAL)
    nest = [f for f, _ in rows if f.nested_in or any(g.nested_in == f.id for g, _ in rows)]
    extra = sum(len(f.pooled) - 1 for f in nest)
    L = ["## In short", "",
         f"The paper states {len(rows)} findings about its results: one row per claim and group, one row per "
         f"average over groups, and one row each for the {len(nest)} nested safety claims ("
         + "; ".join(f"'{f.claim}'" for f in nest) + "), which are tested together, pooled over the groups they "
         f"cover (counted per group they would add {extra} rows: {len(rows) + extra} in all, "
         f"{len(rows) + extra - sum(1 for f, _ in rows if f.by_construction)} of them not true by construction). "
         "Every page of this "
         f"study counts these {len(rows)}. {n_emp} are empirical: we "
         f"reproduce **{c[VERDICTS[0]]}**, {c[VERDICTS[1]]} are consistent with ours without being shown, "
         f"{c[VERDICTS[2]]} hold in direction but not in size, and **{c[VERDICTS[3]]} are not reproduced**. Counted "
         "apart: " + ", ".join(f"{c[v]} {v}" for v in APART) + ".", ""]
    rep = _grouped(rows, label, (VERDICTS[0],))
    if rep:
        L += ["- **Reproduced:** " + "; ".join(rep) + "."]
    con = _grouped(rows, label, (VERDICTS[1],))
    if con:
        L += ["- **Consistent, not shown:** " + "; ".join(con) + "."]
    dirs = _grouped(rows, label, (VERDICTS[2],))
    if dirs:
        L += ["- **The direction holds, not the size:** " + "; ".join(dirs) + "."]
    for r in attribution_rows(rows, label, (experiments or {}).get("experiments")):
        if r["misses"]:
            cause = ", ".join(r["causes"]) or "none found"
            n = len(r["misses"])
            L += [f"- **Missed: {r['cluster']}** ({n} row{'s' if n > 1 else ''}). Cause: {cause} — {r['because']}."]
    return L + ["", "The table *Where the misses come from* below gives each cluster's experiment, its command and "
                "what it showed.", ""]


def render_main(blocks: Sequence[Block], studies: dict, rows, *, figures: dict, experiments: "dict | None" = None,
                notes: Sequence[str] = ()) -> str:
    """The main page's text: the first block against the paper."""
    b = blocks[0]
    st = studies[b.label]
    L = [f"# Tabassum & Bai's findings against the {reading_label(b.reading.name)} reading", "",
         f"The fast-time study of the reading {reading_label(b.reading.name)} (our implementation of the paper's "
         f"method; its settings and what each rests on are below): {st.n:,} encounters per group, groups "
         f"{', '.join(st.groups)}, campaign seed {b.seed}, results `{b.reading.source}`. Tabassum & Bai's numbers: "
         "`daa_sil/data/paper_results.yaml`; their findings: `daa_sil/data/paper_findings.yaml`.", ""]
    L += [str(x) for x in notes] + ([""] if notes else [])
    L += ["Appendices: " + ", ".join(f"[{a}]({a})" for a in APPENDICES)
          + (", [experiments.md](experiments.md)" if experiments else "") + ".", ""]
    c = tally_lines(rows, [b.label])
    L += summary_lines(rows, b.label, experiments)
    L += ["## Headline tally", "",
          f"Empirical findings only; {', '.join(APART)} are counted apart (see the rules below).", ""] + c
    L += basis_lines(b) + findings_lines(rows, b.label) + untestable_lines()
    L += attribution_lines(rows, b.label, experiments)
    L += signature_lines(st, b.label) + rules_lines()
    L += ["## Figures", ""] + [f"![{p.stem}]({p.name})" for p in figures.get(b.label, ())] + [""]
    return "\n".join(L) + "\n"


def findings_json(blocks, rows, replicates: int, seed: int, conf: float, experiments: "dict | None" = None) -> dict:
    """Machine-readable: every finding, the paper's value, each reading's outcome, tallies, attribution."""

    ref = (blocks[0].meta or {}).get("basis")
    return {"bootstrap": {"replicates": replicates, "seed": seed, "conf": conf},
            "basis": {"reading": blocks[0].label, "rows": ref,
                      "note": "the basis of every setting of the first reading; each reading's 'basis_changes' "
                              "lists its rows that differ from these (all its other rows are these)"},
            "readings": [{"label": b.label, "reading": b.reading.name, "settings": dict(b.reading.settings),
                          "source": b.reading.source, "campaign_seed": b.seed,
                          "basis_changes": basis_changes((b.meta or {}).get("basis"), ref),
                          "tally": tally(rows, b.label)} for b in blocks],
            "verdicts": {"words": list(VERDICTS), "empirical": list(EMPIRICAL), "apart": list(APART)},
            "attribution": attribution_rows(rows, blocks[0].label, (experiments or {}).get("experiments"),
                                            (experiments or {}).get("meta")),
            "findings": [{"id": f.id, "claim": f.label, "source": f.source, "kind": f.kind, "metric": f.metric,
                          "group": f.group, "pooled": list(f.pooled), "paper": f.paper_value(),
                          "paper_text": f.paper_text(),
                          "outcomes": {lab: {"verdict": o.verdict, "text": o.text, "evidence": o.evidence,
                                             "value": _finite(o.value), "lo": _finite(o.lo), "hi": _finite(o.hi)}
                                       for lab, o in outs.items()}} for f, outs in rows]}


def runs_relative(source: str, root: "str | os.PathLike") -> str:
    """``source`` as ``RUNS/<path>`` when it lies under ``root`` (else unchanged)."""
    if not source:
        return source
    try:
        return "RUNS/" + Path(source).resolve().relative_to(Path(root).resolve()).as_posix()
    except ValueError:
        return source


def _finite(x):
    return float(x) if isinstance(x, (int, float, np.floating)) and math.isfinite(x) else None


def write_report(src, out_dir: "str | os.PathLike", baseline: str = BASELINE_GROUP, conf: float = CONF, *,
                 replicates: int = DEFAULT_REPLICATES, seed: int = DEFAULT_SEED, recount: Sequence[str] = (),
                 notes: Sequence[str] = (), experiments: "dict | None" = None,
                 main_name: str = "report.md", all_figures: bool = True,
                 runs_root: "str | os.PathLike | None" = None) -> Path:
    """Compute the study of ``src`` (a campaign directory, a list of them, or one results source) and
    write the main page ``out_dir/main_name``, the appendices, ``findings.json`` and the PNG figures;
    returns the main page's path. ``experiments``: the ``experiments.json`` dictionary (the attribution
    table's figures); ``all_figures=False`` draws the figures of the first reading only; ``runs_root``: the
    pages name a campaign directory under it as ``RUNS/<its path>`` (not this machine's path).
    FileFormatError for a missing, empty or corrupt results source (nothing written)."""
    blocks = build_blocks(src, recount)
    if runs_root is not None:
        blocks = [replace(b, reading=replace(b.reading, source=runs_relative(b.reading.source, runs_root)))
                  for b in blocks]
    studies = {b.label: Study(b.enc, b.reading, dec=b.dec, replicates=replicates, seed=seed, conf=conf,
                              baseline=baseline, dt_s=float((b.meta or {}).get("dt_s") or 1.0)) for b in blocks}
    consumed = {b.label: consumed_findings((b.meta or {}).get("basis")) for b in blocks}
    rows = evaluate_all(studies, consumed)
    out = ensure_dir(out_dir)
    figures = {b.label: group_figures(studies[b.label], out, "" if i == 0 else f"-{file_slug(b.label)}")
               for i, b in enumerate(blocks) if i == 0 or all_figures}
    back = [f"Part of the study whose main page is [{main_name}]({main_name})."]
    atomic_write_text(out / APPENDICES[0], readings_page(blocks, studies, rows, figures, back + list(notes)))
    atomic_write_text(out / APPENDICES[1], ablations_page(studies, rows, back + list(notes)))
    atomic_write_text(out / APPENDICES[2], provenance_page(blocks, studies, rows, replicates=replicates, seed=seed,
                                                          conf=conf, intro=back + list(notes)))
    # one finding or reading a few lines, floats to JSON_DIGITS: the committed file stays readable and small
    atomic_write_text(out / "findings.json", json.dumps(rounded(to_jsonable(findings_json(
        blocks, rows, replicates, seed, conf, experiments))), indent=1, sort_keys=True, ensure_ascii=False) + "\n")
    return atomic_write_text(out / main_name, render_main(blocks, studies, rows, figures=figures,
                                                          experiments=experiments, notes=notes))


__all__ = ["write_report", "render_main", "findings_json", "ablation_rows", "basis_lines", "Block", "ABLATIONS",
           "APPENDICES"]
