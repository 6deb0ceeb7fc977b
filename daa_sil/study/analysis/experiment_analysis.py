"""The figures of the experiments (:mod:`daa_sil.study.campaign.experiments`): one dictionary, written as
``experiments.json`` and read by the experiments page and the attribution table.

Every comparison is paired: the runs of one campaign seed fly the same encounter set, so the groups
of several campaigns are joined by encounter id into one :class:`~daa_sil.study.analysis.study.Study`
(:func:`combined_study`) and compared with its paired bootstrap. Each experiment is
``{"title", "why", "runs", "rows": [{label, metric, value, lo, hi}], "diffs": [...], ...}``; values of
undefined statistics are None.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Sequence

import numpy as np

from daa_sil.errors import FileFormatError
from daa_sil.study.analysis.study import Study
from daa_sil.study.analysis.counting import DECISION_COLUMNS, CountingRules
from daa_sil.study.analysis.metrics import as_columns

#: the paper reading's counting (every comparison below counts alike)
PAPER_COUNTING = {"window": "whole", "received": "pilot+blend", "blends": "all", "superseded": "fate"}


def _finite(x) -> "float | None":
    return float(x) if isinstance(x, (int, float, np.floating, np.integer)) and math.isfinite(float(x)) else None


def load_part(d: Path, group: str, label: str) -> tuple[dict, "object | None"]:
    """The per-encounter columns (and decision provenance columns) of ``group`` in campaign ``d``,
    relabelled ``label``."""
    import pyarrow as pa  # lazy: start-up time
    import pyarrow.compute as pc  # lazy: start-up time

    from daa_sil.study.campaign.files import read_results  # lazy: start-up time

    enc = read_results(d, "encounters", [group])
    enc = enc.set_column(enc.column_names.index("group"), "group", pa.array([label] * enc.num_rows, pa.string()))
    dec = None
    try:
        t = read_results(d, "decisions", [group])
        t = t.select([c for c in DECISION_COLUMNS if c in t.column_names])
        dec = t.set_column(t.column_names.index("group"), "group", pc.cast(pa.array([label] * t.num_rows), pa.string()))
    except FileFormatError:
        pass
    return as_columns(enc), dec


def combined_study(parts: Sequence[tuple], counting: "dict | None" = None, replicates: int = 1000) -> Study:
    """One study of ``parts`` ``(label, campaign dir, group)`` on the encounter ids all of them flew
    (the first encounters of one seed), counted by ``counting`` (default the paper's)."""
    import pyarrow as pa  # lazy: start-up time

    loaded = [load_part(Path(d), g, lab) for lab, d, g in parts]
    common = set.intersection(*(set(np.asarray(e["encounter_id"]).tolist()) for e, _ in loaded))
    cols = set.intersection(*(set(e) for e, _ in loaded))
    enc = {c: np.concatenate([np.asarray(e[c])[np.isin(e["encounter_id"], list(common))] for e, _ in loaded])
           for c in cols}
    decs = [x for _, x in loaded if x is not None]
    dec = None
    if len(decs) == len(loaded):
        names = set.intersection(*(set(x.column_names) for x in decs))
        dec = pa.concat_tables([x.select(sorted(names)) for x in decs])
    rules = CountingRules("experiment", dict(counting or PAPER_COUNTING))
    return Study(enc, rules, dec=dec, replicates=replicates)


def metric_rows(st: Study, metrics: Sequence[str]) -> list[dict]:
    """Every label's value [95 % CI] of every metric available."""
    out = []
    for g in st.groups:
        for m in metrics:
            if not st.available(g, m):
                continue
            e = st.estimate(g, m)
            out.append({"label": g, "metric": m, "value": _finite(e.value), "lo": _finite(e.lo), "hi": _finite(e.hi)})
    return out


def diff_rows(st: Study, pairs: Sequence[tuple], metrics: Sequence[str]) -> list[dict]:
    """Paired differences ``label - ref`` for each ``(label, ref)`` of ``pairs``, every metric, with
    their 95 % CIs."""
    out = []
    for g, ref in pairs:
        if g not in st.groups or ref not in st.groups:
            continue
        for m in metrics:
            if not (st.available(g, m) and st.available(ref, m)):
                continue
            d = st._boot_estimate(st.change_sample(g, m, ref, "difference"), "paired bootstrap")
            out.append({"label": g, "ref": ref, "metric": m, "value": _finite(d.value), "lo": _finite(d.lo),
                        "hi": _finite(d.hi)})
    return out


def value(exp: dict, label: str, metric: str, key: str = "value") -> "float | None":
    """One figure of an experiment's rows (None when absent)."""
    for r in exp.get("rows", ()):
        if r["label"] == label and r["metric"] == metric:
            return r[key]
    return None


def diff(exp: dict, label: str, metric: str, key: str = "value") -> "float | None":
    """One paired difference of an experiment (None when absent)."""
    for r in exp.get("diffs", ()):
        if r["label"] == label and r["metric"] == metric:
            return r[key]
    return None


def compare(parts: Sequence[tuple], metrics: Sequence[str], ref: "str | None" = None, counting=None,
            replicates: int = 1000, pairs: "Sequence[tuple] | None" = None) -> dict:
    """``{"n", "rows", "diffs"}`` of ``parts`` (see :func:`combined_study`): the differences of ``pairs``
    ``(label, ref)``, default every label against ``ref`` (default the first label)."""
    st = combined_study(parts, counting, replicates)
    if pairs is None:
        r = ref or parts[0][0]
        pairs = [(lab, r) for lab, _, _ in parts if lab != r]
    return {"n": st.n, "rows": metric_rows(st, metrics), "diffs": diff_rows(st, pairs, metrics)}


__all__ = ["PAPER_COUNTING", "load_part", "combined_study", "metric_rows", "diff_rows", "compare", "value", "diff"]
