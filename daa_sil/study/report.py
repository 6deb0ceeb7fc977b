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
from .findings import NOT_TESTABLE, RULES, VERDICTS, evaluate_all, fmt, untestable_statements
from daa_sil.files import atomic_write_text, ensure_dir
from .metrics import BASELINE_GROUP, CONF, compute_metrics
from daa_sil.study.analysis import Study
from daa_sil.study.counting import COUNTING_DEFAULTS, COUNTING_HELP, counting_options
from .stats import DEFAULT_REPLICATES, DEFAULT_SEED, independent_difference
from daa_sil.study.report_input import Block, build_blocks
from daa_sil.study.report_figures import _figures, _slug
from daa_sil.study.report_format import GROUP_TABLES, _all_groups, _cell, _ci, _table

#: the wait-map ablation: (group with the map and ProjL, ablation group, what the difference measures)
ABLATIONS = (("ID-2", "ID-2-projl", "what the map adds to ProjL (ID-2 minus ID-2-projl)"),
             ("ID-2", "ID-2-map", "what ProjL adds to the map (ID-2 minus ID-2-map)"))




def _concat(tables, what):
    import pyarrow as pa

    try:
        return pa.concat_tables(tables, promote_options="default")
    except (pa.ArrowException, TypeError) as exc:
        raise FileFormatError(f"{what} have incompatible schemas: {str(exc).splitlines()[0]}") from None


def load_results(src) -> dict:
    """The per-encounter table of ``src`` (directory, Parquet file list, Table or dict) as columns."""
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
    table = _concat([_read_parquet(f) for f in files], "result files")
    if table.num_rows == 0:
        raise FileFormatError(f"{src}: the result files hold no encounters")
    return as_columns(table)


def load_decisions(d: Path):
    """The decision tables of directory ``d`` restricted to the provenance columns, or None when
    there are none or they carry neither ``decided_by`` nor ``in_box``."""
    import pyarrow.parquet as pq

    files = sorted(Path(d).glob("*/decisions-*.parquet"))
    if not files:
        return None
    try:
        names = pq.read_schema(files[0]).names
    except Exception as exc:  # noqa: BLE001 -- pyarrow raises several types for a bad footer
        raise FileFormatError(f"{files[0]} is not a readable Parquet file: {str(exc).splitlines()[0]}") from None
    if not any(c in names for c in ("decided_by", "in_box")):
        return None
    cols = [c for c in DECISION_COLUMNS if c in names]
    return _concat([_read_parquet(f, cols) for f in files], "decision files")


@dataclass(frozen=True)
class Block:
    """One column block of the report: a reading and its results."""

    label: str
    reading: Reading
    enc: dict
    dec: object = None
    meta: "dict | None" = None

    @property
    def seed(self):
        return (self.meta or {}).get("seed")

    @property
    def n_config(self):
        return (self.meta or {}).get("n_encounters")


def load_block(src) -> Block:
    """A reading from a campaign directory (or, for old callers, any :func:`load_results` source)."""
    meta = {}
    dec = None
    name, settings, source = "default", {}, ""
    if isinstance(src, (str, os.PathLike)) and Path(src).is_dir():
        d = Path(src)
        source = str(d)
        if (d / "campaign.json").is_file():
            from .campaign import load_campaign_json

            cj = load_campaign_json(d)
            cfg = cj.get("config", {})
            name = str(cfg.get("reading") or "default")
            settings = cfg.get("readings") or {}
            if not isinstance(settings, dict):
                raise FileFormatError(f"{d / 'campaign.json'}: config.readings must be a mapping, got "
                                      f"{type(settings).__name__}")
            meta = {"seed": cfg.get("seed", cj.get("seed")), "n_encounters": cfg.get("n_encounters"),
                    "preset": cfg.get("preset", cj.get("preset")), "groups": cfg.get("groups"),
                    "status": cj.get("status"), "seeds": cfg.get("seeds"), "dt_s": cfg.get("dt_s")}
        dec = load_decisions(d)
    enc = load_results(src)
    if not enc or len(next(iter(enc.values()))) == 0:
        raise FileFormatError(f"{src if isinstance(src, (str, os.PathLike)) else 'results'}: no encounters")
    return Block(name, Reading(name, dict(settings), source), enc, dec, meta)


def parse_recount(text: str) -> tuple[str, dict]:
    """``NAME:key=value[,key=value]`` -> (name, counting settings); UsageError naming what is allowed."""
    if ":" not in text:
        raise UsageError(f"--recount expects NAME:key=value[,key=value], got {text!r}")
    name, _, body = text.partition(":")
    name = name.strip()
    if not name:
        raise UsageError(f"--recount {text!r}: the name before ':' is empty")
    out = {}
    options = counting_options()
    for item in filter(None, (p.strip() for p in body.split(","))):
        k, eq, v = item.partition("=")
        k, v = k.strip(), v.strip()
        if not eq or k not in options:
            raise UsageError(f"--recount {text!r}: {item!r} is not a counting setting; allowed keys: "
                             f"{', '.join(options)}")
        if v not in options[k]:
            raise UsageError(f"--recount {text!r}: {k}={v!r} is not allowed; {k} is one of "
                             f"{', '.join(options[k])}")
        out[k] = v
    if not out:
        raise UsageError(f"--recount {text!r}: no setting given")
    return name, out


def build_blocks(sources, recount: Sequence[str] = ()) -> list[Block]:
    """One block per source, labelled by reading name (``(seed S)`` and ``#k`` added on clashes), plus
    one derived block per source and ``--recount`` entry (same results, other counting)."""
    srcs = list(sources) if isinstance(sources, (list, tuple)) and sources and all(
        isinstance(s, (str, os.PathLike)) and Path(s).is_dir() for s in sources) else [sources]
    blocks = [load_block(s) for s in srcs]
    derived = []
    for spec in recount:
        name, settings = parse_recount(spec)
        for b in blocks:
            st = {**b.reading.settings, **settings}
            if st == b.reading.settings:  # the source already counts this way: nothing to add
                continue
            how = ", ".join(f"{k}={v}" for k, v in settings.items())
            st["description"] = f"{b.reading.settings.get('description', b.reading.name)}; recounted with {how}"
            derived.append(replace(b, label=f"{b.label}+{name}", reading=Reading(f"{b.reading.name}+{name}", st,
                                                                              b.reading.source)))
    blocks += derived
    labels = [b.label for b in blocks]
    out = []
    for b in blocks:
        lab = b.label
        if labels.count(lab) > 1 and b.seed is not None:
            lab = f"{lab} (seed {b.seed})"
        k = 2
        base = lab
        while lab in [o.label for o in out]:
            lab = f"{base} #{k}"
            k += 1
        out.append(replace(b, label=lab))
    return out


# --- formatting -------------------------------------------------------------------------------------
def _table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    out = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    out += ["| " + " | ".join(str(c).replace("|", "/") for c in r) + " |" for r in rows]
    return "\n".join(out)


def _ci(e: Estimate, kind: str = "g3") -> str:
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


def _cell(st: Study, g: str, metric, kind: str, total: bool) -> str:
    if g not in st.groups:
        return "–"
    if isinstance(metric, tuple):
        _, m, ck = metric
        if g == st.baseline or st.baseline not in st.groups:
            return "–"
        return _ci(st.change(g, m, kind=ck), kind)
    if not st.available(g, metric):
        return "– (not in these results)"
    e = st.estimate(g, metric)
    txt = _ci(e, kind)
    if total and math.isfinite(e.value) and e.value != 0:
        txt += f" (total {fmt(st.sum(g, metric).value, 'int')})"
    return txt


def _all_groups(studies: dict) -> list[str]:
    seen = []
    for st in studies.values():
        for g in st.groups:
            if g not in seen:
                seen.append(g)
    from .metrics import GROUP_ORDER

    return [g for g in GROUP_ORDER if g in seen] + [g for g in seen if g not in GROUP_ORDER]


# --- sections --------------------------------------------------------------------------------------
def _sources(blocks: Sequence[Block], studies: dict) -> list[str]:
    rows = []
    for b in blocks:
        st = studies[b.label]
        rows.append([f"**{b.label}**", f"`{b.reading.source}`" if b.reading.source else "(table)",
                     "–" if b.seed is None else str(b.seed), f"{st.n:,}", ", ".join(st.groups),
                     (b.meta or {}).get("preset") or "–", b.reading.describe()])
    L = ["## Readings and sources", "",
         _table(["reading", "results", "campaign seed", "encounters", "groups", "preset", "settings"], rows), ""]
    L += ["Counting settings (the same simulation can be counted several ways; `--recount` adds a reading):", ""]
    for k, opts in counting_options().items():
        helps = COUNTING_HELP.get(k, {})
        L.append(f"- `{k}` (default `{COUNTING_DEFAULTS.get(k, '–')}`): "
                 + "; ".join(f"`{o}` = {helps.get(o, 'see daa_sil/study/counting.py COUNT_SOURCES')}" for o in opts))
    L.append("")
    return L


def _findings_section(blocks, rows) -> list[str]:
    labels = [b.label for b in blocks]
    header = ["#", "finding", "source", "kind", "paper"]
    for lab in labels:
        header += [f"{lab}: ours [95 % CI]", f"{lab}: verdict"]
    body = []
    for i, (f, outs) in enumerate(rows, 1):
        r = [str(i), f.label, f.source, f.kind, f.paper_text()]
        for lab in labels:
            o = outs[lab]
            verdict = f"**{o.verdict}**" if o.verdict != NOT_TESTABLE else f"{o.verdict} ({o.evidence})"
            r += [o.text, verdict]
        body.append(r)
    L = ["## Findings of the paper under each reading", "",
         "Every finding the paper states (`daa_sil/data/paper_findings.yaml`), our value with its encounter-level "
         "95 % confidence interval, and the verdict of its kind's rule (below). Counts are per encounter (the "
         "paper's totals divided by its 10,000 encounters); changes in %.", "", _table(header, body), ""]
    summ = []
    for lab in labels:
        c = {v: sum(1 for _, o in rows if o[lab].verdict == v) for v in VERDICTS}
        summ.append([lab] + [str(c[v]) for v in VERDICTS])
    L += ["Verdicts per reading:", "", _table(["reading"] + list(VERDICTS), summ), ""]
    L += ["### Verdict rules (one per kind of finding; 95 % throughout, no other threshold)", ""]
    L += [f"- **{k}**: {v}." for k, v in RULES.items()]
    L += ["- **not testable**: only when a group the finding needs was not run in that reading, or its statistic "
          "is undefined there (reason given).", ""]
    un = untestable_statements()
    if un:
        L += ["Statements of the paper without a quantity to test (no verdict):", ""]
        L += [f"- \"{u['claim']}\" — {u['why']}" for u in un]
        L.append("")
    return L


def _group_tables(studies: dict) -> list[str]:
    groups = _all_groups(studies)
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
                r += [_cell(studies[lab], g, metric, kind, total) for lab in labels]
                rows.append(r)
            L += [f"**{label}**", "", _table(["group", "paper"] + labels, rows), ""]
        if title.startswith("Penetration"):
            rows = [[g] + [fmt(studies[lab].pi_max(g), "f2") if g in studies[lab].groups else "–" for lab in labels]
                    for g in groups]
            L += ["**maximum PI (preset's constants; the paper: 3.79 in ID-1)**", "",
                  _table(["group"] + labels, rows), ""]
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
            rows.append([g, f"{m.a_only} / {m.b_only}", f"{m.p_value:.3g}", _ci(d, "pct")])
        L += [f"*{lab}*", "", _table(["group", f"LoWC only in group / only in {st.baseline}", "McNemar p",
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
                body.append([r["label"], _ci(r["full"], r["kind"]), _ci(r["ablation"], r["kind"]),
                             _ci(r["diff"], r["kind"]), test, "yes" if r["measurable"] else "no"])
            L += [f"### {lab}: {what}", "",
                  _table(["metric", full, abl, f"{full} − {abl} [95 % CI]", "test", "measurable?"], body), ""]
            nothing = [r for r in rows if not r["measurable"]]
            why = ""
            if st.provenance.get(full):
                why = (f" In {full} the map decided {_cell(st, full, 'map_decided_share', 'pct', False)} of the "
                       f"wait/no-wait decisions (the rest would be the same with \"always wait\"), and "
                       f"{_cell(st, full, 'in_box_share', 'pct', False)} of its lookups fell inside the map's box.")
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
            rows.append([g, _cell(st, g, "map_decided_share", "pct", False),
                         _cell(st, g, "map_or_both_share", "pct", False), _cell(st, g, "in_box_share", "pct", False),
                         fmt(st.sum(g, "n_dec").value, "int") if st.has(g, "n_dec") else "–",
                         fmt(st.sum(g, "n_lookup").value, "int") if st.has(g, "n_lookup") else "–"])
        L += [f"*{lab}*", "", _table(["group", "decided by the wait function (map)", "map or both", "lookups inside the box",
                                      "decisions", "lookups"], rows), ""]
    return L


def _seed_section(blocks, studies, rows) -> list[str]:
    """Readings run on more than one campaign seed: do the seeds agree within CIs?"""
    by_name: dict = {}
    for b in blocks:
        by_name.setdefault((b.reading.name, json.dumps(b.reading.settings, sort_keys=True, default=str)), []).append(b)
    pairs = [(v[0], w) for v in by_name.values() if len(v) > 1 for w in v[1:]]
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
                xa, xb = _finding_sample(f, sa), _finding_sample(f, sb)
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
        L += [f"### {a.label} vs {b.label}", "", _table(["finding", a.label, b.label, "difference [95 % CI]", "agree?"],
                                                          body), "",
              f"{len(body) - disagree} of {len(body)} findings agree within the CI; {disagree} do not.", ""]
    return L


def _finding_sample(f, st: Study):
    from .findings import _pooled_mean

    if f.kind == "change":
        ck = f.change.get("kind", "ratio")
        if f.group:
            return st.change_sample(f.group, f.metric, f.change["vs"], ck)
        return st.pooled_change_sample(f.metric, f.pooled, f.over, "reduction" if ck == "reduction" else "ratio")
    if f.group:
        return st.sample(f.group, f.metric)
    return _pooled_mean(st, f.metric, f.pooled)


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
            _table(["group", "no-wait", "received", "exact match", "P(LoWC)/flight hr"], rows), ""]


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
    L += _findings_section(blocks, rows)
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
        figures[b.label] = _figures(studies[b.label], out, "" if i == 0 else f"-{_slug(b.label)}")
    text = render_markdown(blocks, studies, rows, replicates=replicates, seed=seed, conf=conf, figures=figures,
                           notes=notes)
    from daa_sil.files import atomic_write_json

    atomic_write_json(out / "findings.json", findings_json(blocks, rows, replicates, seed, conf))
    return atomic_write_text(out / "report.md", text)


__all__ = ["write_report", "load_results", "load_block", "build_blocks", "render_markdown", "findings_json",
           "ablation_rows", "parse_recount", "Block", "FIGURES", "ABLATIONS"]
