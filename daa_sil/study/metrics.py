"""Paper metrics (Tabassum & Bai §V, Tables 3-8) with encounter-level 95 % confidence intervals, as
pure functions of the campaign result tables (``docs/architecture.md``: one row per encounter, one
per decision; a pyarrow Table or a dict of numpy arrays).

**The study** (:class:`Study`, what the report uses). Encounters are the independent units; every
group of a campaign flies the same encounters, so the per-encounter columns of all groups are
aligned by ``encounter_id`` into one panel and resampled together (:mod:`daa_sil.study.stats`: one
cluster-bootstrap weight matrix for all groups, so every comparison between groups is paired).
Every metric is a function of per-encounter sums (:data:`METRICS`):

* counted quantities per encounter (``wait``, ``no_wait``, ``received``, ``pilot_exec``,
  ``blend``, ``daa_override``, ``stale``, ``link_lost``): sum over encounters / encounters; which
  columns a quantity is summed from is the reading's choice (:data:`COUNT_SOURCES`, below);
* step shares as ratio estimators: ``exact_match`` = exact (axis, direction) blends / blends of a
  pilot maneuver, ``axis_match``, ``neither_match``, ``blend_intent_share``, ``executed_share`` =
  pilot commands executed as sent / received;
* encounter proportions: ``p_lowc``, ``p_nmac`` (Clopper-Pearson: each encounter is one Bernoulli
  trial), ``lowc_turning_share`` (LoWC encounters with a turning intruder, Clopper-Pearson given the
  LoWC encounters);
* ``p_lowc_step`` = time in LoWC / flight time (the paper's P(LoWC)); ``p_lowc_per_hr`` = the
  paper's Eq. P(LoWC)/(total flight hours) -- **it shrinks as 1/N for the same per-step risk**, so
  ``p_lowc_per_hr_paper_h`` evaluates it at the paper's 666.67 h, the only way to compare it with the
  paper's Table 7; ``lowc_rate_per_hr`` = LoWC encounters per flight hour, a proper rate;
* ``pi_mean`` / ``pi_paper_mean``: mean PI over LoWC encounters with the preset's / the paper's
  Eq. constants (``pi`` / ``pi_paper`` columns, integrated on the LoWC segments); ``pi_max``;
* ``dev_h_mean`` / ``dev_v_mean``: mean max deviation from the unperturbed path, m;
* decision provenance (when the decision tables carry ``decided_by`` / ``in_box``):
  ``map_decided_share`` (wait/no-wait decisions with ``decided_by == "map"``: the decision would
  differ with the map replaced by "always wait"), ``in_box_share`` (lookups inside the map's box).

Changes vs the baseline group (B-2) and between any two groups are ratios/differences of the same
resampled sums (paired). Zeros get exact upper bounds (:func:`daa_sil.study.stats.zero_upper_bounds`).

**Readings** (:class:`Reading`): a campaign directory is one named reading of the paper
(``campaign.json`` ``config.reading`` / ``config.readings``, missing = ``default``). What a reading
changes in the simulation is the campaign's business; what it changes in *counting* is here, as
data: :data:`COUNT_SOURCES` maps each counted quantity and the values of the counting settings it
depends on (:data:`COUNTING_DEFAULTS`: ``received`` = ``arrived`` | ``pilot+blend`` | ``executed``,
``window`` = ``active`` | ...) to the per-encounter columns summed. A new counting (e.g. a
whole-encounter window) is a new simulator column plus one entry in that table; a reading may also
name columns directly: ``readings: {columns: {received: [n_pilot_exec, n_blend]}}``.

The **analytic** functions further down (:func:`group_metrics`, :func:`compute_metrics`) are the
old per-step intervals (Garwood / Clopper-Pearson on step counts); they ignore the clustering
of steps within encounters (too narrow, ``tests/test_stats.py``) and are kept only as the
benchmark's baseline and for the width comparison in the report.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache
from importlib import resources
from typing import Callable, Mapping, Sequence

import numpy as np
from scipy import stats

from daa_sil.errors import FileFormatError, UsageError
from .stats import (DEFAULT_REPLICATES, DEFAULT_SEED, ClusterBootstrap, Sample, clopper_pearson,
    mcnemar_exact, zero_upper_bounds)

CONF = 0.95
BASELINE_GROUP = "B-2"
GROUP_ORDER = ("B-1", "B-2", "IC-1", "ID-1", "ID-2")
FAA_ORDER = ("Frequent", "Probable", "Remote", "Extremely Remote", "Extremely Improbable")

#: columns needed from the per-encounter table
REQUIRED_COLUMNS = ("group", "encounter_id", "duration_s", "lowc", "nmac", "lowc_duration_s", "pi", "dev_h_m",
                    "dev_v_m", "n_wait", "n_no_wait", "n_pilot_received", "n_pilot_exec", "n_blend", "n_blend_exact",
                    "n_blend_axis", "n_daa_override")
_COUNT_COLUMNS = {"wait": "n_wait", "no_wait": "n_no_wait", "received": "n_pilot_received",
                  "pilot_exec": "n_pilot_exec", "blend": "n_blend", "daa_override": "n_daa_override",
                  "stale": "n_stale", "link_lost": "n_link_lost"}


@dataclass(frozen=True)
class Estimate:
    """A point estimate with its ``conf`` interval ``[lo, hi]`` and the method used."""

    value: float
    lo: float
    hi: float
    method: str
    note: str = ""

    def as_dict(self) -> dict:
        return {"value": self.value, "lo": self.lo, "hi": self.hi, "method": self.method, "note": self.note}


# --- intervals ------------------------------------------------------------------------------------
def wilson(k: float, n: float, conf: float = CONF) -> tuple[float, float]:
    """Wilson score interval for ``k`` successes in ``n`` trials."""
    if n <= 0:
        raise UsageError(f"a proportion needs n > 0 trials, got n = {n}")
    z = float(stats.norm.ppf(1 - (1 - conf) / 2))
    p = k / n
    den = 1 + z * z / n
    c = (p + z * z / (2 * n)) / den
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    return max(0.0, c - h), min(1.0, c + h)


def poisson_exact(k: float, conf: float = CONF) -> tuple[float, float]:
    """Exact (Garwood) interval for a Poisson mean after observing count ``k``."""
    if k < 0:
        raise UsageError(f"a count must be >= 0, got {k}")
    a = 1.0 - conf
    lo = 0.0 if k == 0 else float(stats.chi2.ppf(a / 2, 2 * k) / 2)
    hi = float(stats.chi2.ppf(1 - a / 2, 2 * k + 2) / 2)
    return lo, hi


def rate_ratio(k1: float, n1: float, k2: float, n2: float, conf: float = CONF) -> tuple[float, float, float]:
    """Ratio of Poisson rates ``(k1/n1)/(k2/n2)`` with the exact conditional interval."""
    if n1 <= 0 or n2 <= 0:
        raise UsageError("a rate ratio needs positive exposures")
    if k2 <= 0:
        return (math.nan, math.nan, math.nan) if k1 <= 0 else (math.inf, math.nan, math.inf)
    lo_p, hi_p = clopper_pearson(k1, k1 + k2, conf)
    conv = lambda p: (p / (1 - p)) * (n2 / n1) if p < 1 else math.inf  # noqa: E731
    return (k1 / n1) / (k2 / n2), conv(lo_p), conv(hi_p)


def mean_t(x, conf: float = CONF) -> tuple[float, float, float]:
    """Mean and Student-t interval of ``x`` (nan bounds for fewer than 2 values)."""
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    if x.size == 0:
        return math.nan, math.nan, math.nan
    m = float(x.mean())
    if x.size < 2:
        return m, math.nan, math.nan
    h = float(stats.t.ppf(1 - (1 - conf) / 2, x.size - 1) * x.std(ddof=1) / math.sqrt(x.size))
    return m, m - h, m + h


@lru_cache(maxsize=1)
def paper_results() -> dict:
    """The paper's published numbers (``daa_sil/data/paper_results.yaml``)."""
    import yaml

    text = resources.files("daa_sil").joinpath("data/paper_results.yaml").read_text(encoding="utf-8")
    return yaml.safe_load(text)


def faa_category(p_per_hr: float) -> str:
    """FAA likelihood category of a probability per flight hour (paper Table 6; a value on a
    boundary belongs to the more frequent category)."""
    if p_per_hr is None or not np.isfinite(p_per_hr):
        return "n/a"
    bands = paper_results()["faa_likelihood"]
    for name in FAA_ORDER:
        lo, hi = bands[name]
        if p_per_hr >= lo:
            return name
    return "Extremely Improbable"


# --- tables ---------------------------------------------------------------------------------------
def as_columns(table) -> dict:
    """A pyarrow Table or a mapping of arrays as ``{column: numpy array}``."""
    if isinstance(table, Mapping):
        return {k: np.asarray(v) for k, v in table.items()}
    try:
        import pyarrow as pa
    except ImportError:  # pragma: no cover
        pa = None
    if pa is not None and isinstance(table, pa.Table):
        return {k: np.asarray(table.column(k).to_numpy(zero_copy_only=False)) for k in table.column_names}
    raise UsageError(f"result table must be a pyarrow Table or a dict of arrays, got {type(table).__name__}")


def _check(cols: dict, where: str = "encounter table") -> None:
    missing = [c for c in REQUIRED_COLUMNS if c not in cols]
    if missing:
        raise FileFormatError(f"{where} lacks column(s) {', '.join(missing)}")
    n = {len(np.asarray(v)) for v in cols.values()}
    if len(n) > 1:
        raise FileFormatError(f"{where}: columns have different lengths {sorted(n)}")


def groups_of(enc) -> list[str]:
    """Groups present, paper order first."""
    cols = enc if isinstance(enc, dict) else as_columns(enc)
    present = [str(g) for g in dict.fromkeys(np.asarray(cols["group"]).astype(str).tolist())]
    return [g for g in GROUP_ORDER if g in present] + sorted(g for g in present if g not in GROUP_ORDER)


def _select(cols: dict, group: str) -> dict:
    mask = np.asarray(cols["group"]).astype(str) == group
    return {k: np.asarray(v)[mask] for k, v in cols.items()}


def _count(x) -> float:
    return float(np.nansum(np.asarray(x, float)))


def group_metrics(enc, group: "str | None" = None, conf: float = CONF, dt_s: float = 1.0) -> dict:
    """The old analytic metrics of one group (``group`` None: the table must hold exactly one group).
    Returns ``{name: Estimate}`` plus ``n_encounters`` and ``flight_hours`` floats.

    Intervals treat time steps as independent: counts summed over steps get the exact (Garwood)
    Poisson interval, step shares Clopper-Pearson over steps, changes vs the baseline the exact
    conditional rate-ratio interval, ``p_lowc_per_hr`` Clopper-Pearson over (LoWC steps, steps) /
    flight hours, means Student t. Kept as the baseline of ``benchmarks/bench_report.py`` and for the
    interval-width comparison; :class:`Study` is the encounter-level replacement."""
    cols = as_columns(enc) if not isinstance(enc, dict) else {k: np.asarray(v) for k, v in enc.items()}
    _check(cols)
    if group is None:
        gs = groups_of(cols)
        if len(gs) != 1:
            raise UsageError(f"table holds groups {gs}; name one")
        group = gs[0]
    g = _select(cols, group)
    n = len(g["group"])
    if n == 0:
        raise UsageError(f"group {group!r} has no encounters in the results")
    dur = np.asarray(g["duration_s"], float)
    total_s = float(dur.sum())
    if not total_s > 0:
        raise FileFormatError(f"group {group!r}: total duration_s is {total_s}; cannot compute per-hour rates")
    hours = total_s / 3600.0
    out: dict = {"n_encounters": n, "flight_hours": hours}
    for name, col in _COUNT_COLUMNS.items():
        if col in g:
            k = _count(g[col])
            lo, hi = poisson_exact(k, conf)
            out[name] = Estimate(k, lo, hi, "exact Poisson (Garwood)", "k = 0: upper bound only" if k == 0 else "")
    nb = _count(g["n_blend"])
    # The paper's 84 % exact + 16 % axis-only = 100 % of its blends: every blend it counts carries
    # the pilot's maneuver intent. Ours also blends "hold" commands streamed before the pilot's first
    # maneuver (no (axis, direction) to match), so the match rates are taken over intent blends.
    if "n_blend_intent" in g:
        ni, basis = _count(g["n_blend_intent"]), "Clopper-Pearson over blends of a pilot maneuver"
    else:
        ni, basis = nb, "Clopper-Pearson over all blends (table without n_blend_intent)"
    for name, col in (("exact_match", "n_blend_exact"), ("axis_match", "n_blend_axis")):
        if ni > 0:
            k = _count(g[col])
            lo, hi = clopper_pearson(k, ni, conf)
            out[name] = Estimate(k / ni, lo, hi, basis)
        else:
            out[name] = Estimate(math.nan, math.nan, math.nan, basis, "no blends of a pilot maneuver")
    if "n_blend_intent" in g and nb > 0:
        lo, hi = clopper_pearson(ni, nb, conf)
        out["blend_intent_share"] = Estimate(ni / nb, lo, hi, "Clopper-Pearson over blends")
    else:
        out["blend_intent_share"] = Estimate(math.nan, math.nan, math.nan, "Clopper-Pearson over blends", "no blends")
    for ev in ("lowc", "nmac"):
        k = float(np.count_nonzero(np.asarray(g[ev]).astype(bool)))
        lo, hi = clopper_pearson(k, n, conf)
        out[f"n_{ev}"] = Estimate(k, *poisson_exact(k, conf), "exact Poisson (Garwood)")
        out[f"p_{ev}"] = Estimate(k / n, lo, hi, "Clopper-Pearson over encounters",
                                  f"k = 0: rule of three (one-sided 95 %) gives <= {3.0 / n:.3g}" if k == 0 else "")
        rlo, rhi = poisson_exact(k, conf)
        rate = k / hours
        out[f"{ev}_rate_per_hr"] = Estimate(rate, rlo / hours, rhi / hours, "exact Poisson / flight hours",
                                            f"FAA: {faa_category(rate)}")
    # the paper's P(LoWC)/flight hour: fraction of time steps in LoWC / flight hours
    steps = total_s / dt_s
    k_s = float(np.rint(_count(g["lowc_duration_s"]) / dt_s))
    p_step = k_s / steps
    lo, hi = clopper_pearson(k_s, steps, conf)
    out["p_lowc_step"] = Estimate(p_step, lo, hi, "Clopper-Pearson over time steps")
    est = p_step / hours
    out["p_lowc_per_hr"] = Estimate(est, lo / hours, hi / hours, "Clopper-Pearson over steps / flight hours",
                                    f"FAA: {faa_category(est)} (CI {faa_category(lo / hours)} .. {faa_category(hi / hours)})")
    lowc = np.asarray(g["lowc"]).astype(bool)
    pi = np.asarray(g["pi"], float)[lowc]
    m, lo, hi = mean_t(pi, conf)
    out["pi_mean"] = Estimate(m, lo, hi, "Student t over LoWC encounters", "no LoWC" if pi.size == 0 else "")
    pmax = float(np.nanmax(pi)) if pi.size else math.nan
    out["pi_max"] = Estimate(pmax, math.nan, math.nan, "maximum", "no LoWC" if pi.size == 0 else "")
    for name, col in (("dev_h_mean", "dev_h_m"), ("dev_v_mean", "dev_v_m")):
        m, lo, hi = mean_t(g[col], conf)
        out[name] = Estimate(m, lo, hi, "Student t over encounters")
    return out


def compute_metrics(enc, baseline: str = BASELINE_GROUP, conf: float = CONF, dt_s: float = 1.0) -> dict:
    """``{group: group_metrics}`` for every group, plus the changes vs ``baseline``
    (``no_wait_reduction_pct``, ``received_change_pct``) where the baseline is present."""
    cols = as_columns(enc) if not isinstance(enc, dict) else {k: np.asarray(v) for k, v in enc.items()}
    _check(cols)
    groups = groups_of(cols)
    if not groups:
        raise UsageError("the results hold no encounters")
    res = {g: group_metrics(cols, g, conf, dt_s) for g in groups}
    if baseline in res:
        b = res[baseline]
        for g, m in res.items():
            if g == baseline:
                continue
            rr, lo, hi = rate_ratio(m["no_wait"].value, m["n_encounters"], b["no_wait"].value, b["n_encounters"], conf)
            m["no_wait_reduction_pct"] = Estimate(100 * (1 - rr), 100 * (1 - hi), 100 * (1 - lo),
                                                  f"exact conditional rate ratio vs {baseline}")
            rr, lo, hi = rate_ratio(m["received"].value, m["n_encounters"], b["received"].value, b["n_encounters"], conf)
            m["received_change_pct"] = Estimate(100 * (rr - 1), 100 * (lo - 1), 100 * (hi - 1),
                                                f"exact conditional rate ratio vs {baseline}")
    return res


# ==================================================================================================
# The encounter-level study
# ==================================================================================================
#: counting settings of a reading (``campaign.json`` ``config.readings`` keys) and their defaults
COUNTING_DEFAULTS = {"received": "arrived", "window": "active"}
#: allowed values of each counting setting, as documented for readers of a report
COUNTING_HELP = {
    "received": {"arrived": "every fresh pilot command that arrived during the window (incl. those the DAA overrode)",
                 "pilot+blend": "executed as sent + blended (the paper's Table 5 arithmetic: received = pilot + blend)",
                 "executed": "executed as sent only"},
    "window": {"active": "steps where the agent decides (corrective alert, a wait or blend in progress, DAA holding)"},
}
#: counted quantity -> (the counting settings it depends on, {their values: per-encounter columns summed})
#: decisions happen only in the active phase, so their whole-encounter count is the active one;
#: commands also arrive outside it (``n_*_whole`` columns of :mod:`daa_sil.study.fasttime`)
def _decisions(col: str) -> tuple:
    return (("window",), {("active",): (col,), ("whole",): (col,)})


COUNT_SOURCES: dict[str, tuple[tuple[str, ...], dict[tuple[str, ...], tuple[str, ...]]]] = {
    "wait": _decisions("n_wait"),
    "no_wait": _decisions("n_no_wait"),
    "received": (("received", "window"), {("arrived", "active"): ("n_pilot_received",),
                                          ("pilot+blend", "active"): ("n_pilot_exec", "n_blend"),
                                          ("executed", "active"): ("n_pilot_exec",),
                                          ("arrived", "whole"): ("n_pilot_received_whole",),
                                          ("pilot+blend", "whole"): ("n_pilot_exec_whole", "n_blend"),
                                          ("executed", "whole"): ("n_pilot_exec_whole",)}),
    "pilot_exec": (("window",), {("active",): ("n_pilot_exec",), ("whole",): ("n_pilot_exec_whole",)}),
    "blend": _decisions("n_blend"),
    "daa_override": _decisions("n_daa_override"),
    "blend_intent": _decisions("n_blend_intent"),
    "blend_exact": _decisions("n_blend_exact"),
    "blend_axis": _decisions("n_blend_axis"),
    "stale": _decisions("n_stale"),
    "link_lost": _decisions("n_link_lost"),
}


def counting_options() -> dict[str, list[str]]:
    """The values each counting setting can take: every value some entry of :data:`COUNT_SOURCES`
    uses (so a new table entry is a new allowed value; :data:`COUNTING_HELP` only describes them)."""
    out: dict[str, list[str]] = {k: [] for k in COUNTING_DEFAULTS}
    for keys, table in COUNT_SOURCES.values():
        for opt in table:
            for k, v in zip(keys, opt):
                if v not in out.setdefault(k, []):
                    out[k].append(v)
    return out


#: quantities a report can do without (older result tables lack their columns)
OPTIONAL_QUANTITIES = ("blend_intent", "stale", "link_lost")
#: the paper's flight hours per group (10,000 encounters x 240 s)
PAPER_FLIGHT_HOURS = 10_000 * 240.0 / 3600.0
PAPER_MAX_PI = 3.79  # paper §V: the maximum PI over all groups (ID-1)
PI_SIGNIFICANT = 10.0  # paper §V (after DO-365): PI > 10 is a significant LoWC


@dataclass(frozen=True)
class Reading:
    """One named reading of the paper: its ``name``, its ``settings`` (``config.readings``; the
    counting keys of :data:`COUNTING_DEFAULTS` are used here, the rest is recorded) and where its
    results come from (``source``)."""

    name: str = "default"
    settings: Mapping = field(default_factory=dict)
    source: str = ""

    def counting(self) -> dict:
        """The counting settings in force: defaults overridden by the reading's."""
        out = dict(COUNTING_DEFAULTS)
        for k in COUNTING_DEFAULTS:
            if k in self.settings and self.settings[k] is not None:
                out[k] = str(self.settings[k])
        return out

    def columns_for(self, quantity: str) -> tuple[str, ...]:
        """Per-encounter columns summed for ``quantity`` under this reading."""
        direct = self.settings.get("columns") if isinstance(self.settings, Mapping) else None
        if isinstance(direct, Mapping) and quantity in direct:
            cols = direct[quantity]
            return (cols,) if isinstance(cols, str) else tuple(str(c) for c in cols)
        if quantity not in COUNT_SOURCES:
            raise UsageError(f"unknown counted quantity {quantity!r}; known: {', '.join(COUNT_SOURCES)}")
        keys, table = COUNT_SOURCES[quantity]
        cnt = self.counting()
        opt = tuple(cnt[k] for k in keys)
        if opt not in table:
            allowed = "; ".join(", ".join(f"{k}={v}" for k, v in zip(keys, o)) for o in table)
            raise UsageError(f"reading {self.name!r}: {quantity!r} cannot be counted with "
                             f"{', '.join(f'{k}={v}' for k, v in zip(keys, opt))}; allowed: {allowed}")
        return table[opt]

    def describe(self) -> str:
        c = self.counting()
        rest = {k: v for k, v in self.settings.items() if k not in COUNTING_DEFAULTS and k != "columns"}
        txt = ", ".join(f"{k}={v}" for k, v in c.items())
        if rest:
            txt += "; " + ", ".join(f"{k}={v}" for k, v in sorted(rest.items()))
        return txt


def paper_setup(group: str) -> "str | None":
    """``baseline`` / ``integrated`` for the paper's five groups (Table 2), None for others."""
    g = paper_results().get("groups", {}).get(group)
    return g.get("setup") if isinstance(g, dict) else None


#: decision-table columns the study reads (provenance needs ``decided_by`` and/or ``in_box``)
DECISION_COLUMNS = ("group", "encounter_id", "decision", "decided_by", "in_box", "wait_in_box")


def normalise_decisions(dec) -> "dict | None":
    """The decision table (Table or dict) as numpy columns for :class:`Study`: ``decided_by`` as
    str with ``""`` for none, ``in_box`` as int8 (1 inside the map's box, 0 outside, -1 no lookup).
    None when the table has neither provenance column."""
    if dec is None:
        return None
    names = dec.column_names if hasattr(dec, "column_names") else list(dec)
    if "in_box" not in names and "wait_in_box" in names:  # the simulator's name (daa_sil.study.fasttime)
        if hasattr(dec, "rename_columns"):
            dec = dec.rename_columns(["in_box" if c == "wait_in_box" else c for c in names])
        else:
            dec = {("in_box" if k == "wait_in_box" else k): v for k, v in dec.items()}
        names = dec.column_names if hasattr(dec, "column_names") else list(dec)
    if not any(c in names for c in ("decided_by", "in_box")):
        return None
    out = {}
    if hasattr(dec, "column_names"):
        import pyarrow as pa
        import pyarrow.compute as pc

        def arr(c):
            return dec.column(c)

        out["group"] = np.asarray(arr("group").to_numpy(zero_copy_only=False)).astype(str)
        out["encounter_id"] = np.asarray(arr("encounter_id").to_numpy(zero_copy_only=False), np.int64)
        if "decision" in names:
            out["decision"] = np.asarray(arr("decision").to_numpy(zero_copy_only=False)).astype(str)
        if "decided_by" in names:
            col = pc.cast(arr("decided_by"), pa.string())
            out["decided_by"] = np.asarray(pc.fill_null(col, "").to_numpy(zero_copy_only=False)).astype(str)
        if "in_box" in names:  # bool (or 0/1 numbers); null or nan = no lookup
            col = arr("in_box")
            valid = np.asarray(pc.is_valid(col).to_numpy(zero_copy_only=False), bool)
            vals = np.asarray(pc.fill_null(pc.cast(col, pa.float64()), 0.0).to_numpy(zero_copy_only=False), float)
            valid &= np.isfinite(vals)
            out["in_box"] = np.where(valid, (vals != 0).astype(np.int8), np.int8(-1)).astype(np.int8)
        return out
    out["group"] = np.asarray(dec["group"]).astype(str)
    out["encounter_id"] = np.asarray(dec["encounter_id"], np.int64)
    if "decision" in dec:
        out["decision"] = np.asarray(dec["decision"]).astype(str)
    if "decided_by" in dec:
        out["decided_by"] = np.array(["" if (b is None or b != b) else str(b) for b in dec["decided_by"]], dtype=str)
    if "in_box" in dec:
        out["in_box"] = np.array([-1 if (b is None or b != b) else int(bool(b)) for b in dec["in_box"]], np.int8)
    return out


def _decision_columns(dec: "dict | None", group: str, ids: np.ndarray) -> "dict | None":
    """Per-encounter provenance counts of ``group`` from a normalised decision table (or None):
    wait/no-wait decisions with a ``decided_by``, those decided by the map, by both and by ProjL;
    map lookups (``in_box`` given) and those inside the box."""
    if dec is None:
        return None
    m = dec["group"] == group
    eid = dec["encounter_id"][m]
    pos = np.searchsorted(ids, eid)
    ok = (pos < ids.size) & (ids[np.minimum(pos, ids.size - 1)] == eid)
    n = ids.size
    out = {}

    def count(mask):
        sel = mask & ok
        return np.bincount(pos[sel], minlength=n).astype(float)

    if "decided_by" in dec:
        by = dec["decided_by"][m]
        has = by != ""
        if "decision" in dec:
            has &= np.isin(dec["decision"][m], ("wait", "no_wait"))
        out["n_dec"] = count(has)
        out["n_dec_map"] = count(has & (by == "map"))
        out["n_dec_both"] = count(has & (by == "both"))
        out["n_dec_projl"] = count(has & (by == "projl"))
    if "in_box" in dec:
        ib = dec["in_box"][m]
        out["n_lookup"] = count(ib >= 0)
        out["n_in_box"] = count(ib == 1)
    return out


class Study:
    """Encounter-level metrics of every group of one reading (see the module docstring).

    ``enc`` the per-encounter table (Table or dict of arrays), ``reading`` a :class:`Reading`,
    ``dec`` the per-decision table (optional; for decision provenance), ``replicates``/``seed`` of
    the bootstrap, ``conf`` the interval level, ``dt_s`` the simulation step (s; bounds the
    instances one encounter can count)."""

    def __init__(self, enc, reading: "Reading | None" = None, *, dec=None, replicates: int = DEFAULT_REPLICATES,
                 seed: int = DEFAULT_SEED, conf: float = CONF, baseline: str = BASELINE_GROUP, dt_s: float = 1.0):
        cols = enc if isinstance(enc, dict) else as_columns(enc)
        cols = {k: np.asarray(v) for k, v in cols.items()}
        _check(cols)
        self.reading = reading if reading is not None else Reading()
        self.conf = conf
        self.baseline = baseline
        if not (math.isfinite(dt_s) and dt_s > 0):
            raise UsageError(f"dt must be > 0 s, got {dt_s!r}")
        self.dt_s = float(dt_s)
        self.groups = groups_of(cols)
        if not self.groups:
            raise UsageError("the results hold no encounters")
        gcol = np.asarray(cols["group"]).astype(str)
        ids = np.asarray(cols["encounter_id"]).astype(np.int64)
        self.ids = np.unique(ids)
        self.n = int(self.ids.size)
        self.boot = ClusterBootstrap(self.n, replicates, seed)
        self.notes: list[str] = []
        self.quantities = [q for q in COUNT_SOURCES]
        self.columns_used = {q: self.reading.columns_for(q) for q in self.quantities}
        for q, cs in list(self.columns_used.items()):
            miss = [c for c in cs if c not in cols]
            if miss:
                if q in OPTIONAL_QUANTITIES:
                    self.quantities.remove(q)
                    self.notes.append(f"{q}: not in these results (no column {', '.join(miss)})")
                    continue
                raise FileFormatError(f"reading {self.reading.name!r} counts {q!r} from column(s) "
                                      f"{', '.join(cs)}, which the results lack ({', '.join(miss)})")
        self.per_enc: dict[str, dict[str, np.ndarray]] = {}
        self.provenance: dict[str, bool] = {}
        dec_cols = normalise_decisions(dec)
        self.has_pi_paper = "pi_paper" in cols
        flat = {}
        for g in self.groups:
            m = gcol == g
            pos = np.searchsorted(self.ids, ids[m])
            if np.unique(pos).size != pos.size:
                raise FileFormatError(f"group {g!r}: encounter ids repeat in the results")

            def col(name, dtype=float, fill=0.0):
                out = np.full(self.n, fill, dtype=dtype)
                out[pos] = np.asarray(cols[name])[m].astype(dtype)
                return out

            present = np.zeros(self.n)
            present[pos] = 1.0
            e = {"present": present, "duration_s": col("duration_s")}
            lowc = col("lowc", bool, False)
            nmac = col("nmac", bool, False)
            e["lowc"], e["nmac"] = lowc.astype(float), nmac.astype(float)
            e["lowc_duration_s"] = col("lowc_duration_s")
            pi = np.nan_to_num(col("pi"))
            e["pi_lowc"] = np.where(lowc, pi, 0.0)
            e["pi_max_src"] = np.where(lowc, pi, np.nan)
            e["lowc_pi_zero"] = (lowc & (pi <= 0) & (e["lowc_duration_s"] > 0)).astype(float)
            e["lowc_pi_gt_max"] = (lowc & (pi > PAPER_MAX_PI)).astype(float)
            e["lowc_pi_significant"] = (lowc & (pi > PI_SIGNIFICANT)).astype(float)
            if self.has_pi_paper:
                pp = np.nan_to_num(col("pi_paper"))
                e["pi_paper_lowc"] = np.where(lowc, pp, 0.0)
            if "intruder_turns" in cols:
                e["lowc_turning"] = (lowc & col("intruder_turns", bool, False)).astype(float)
            e["dev_h_m"], e["dev_v_m"] = col("dev_h_m"), col("dev_v_m")
            for q in self.quantities:
                e[q] = sum((col(c) for c in self.columns_used[q]), np.zeros(self.n))
                e[f"{q}_any"] = (e[q] > 0).astype(float)
            if all(q in e for q in ("blend_intent", "blend_exact", "blend_axis")):
                # blends of a pilot maneuver matching neither its direction nor its axis
                e["blend_neither"] = np.maximum(e["blend_intent"] - e["blend_exact"] - e["blend_axis"], 0.0)
                e["blend_neither_any"] = (e["blend_neither"] > 0).astype(float)
            prov = _decision_columns(dec_cols, g, self.ids)
            self.provenance[g] = prov is not None
            if prov:
                e.update(prov)
            self.per_enc[g] = e
            for k, v in e.items():
                if k != "pi_max_src":
                    flat[f"{g}\x1f{k}"] = v
        self._sums = self.boot.sample_sums(flat)
        self.equal_durations = all(np.ptp(self.per_enc[g]["duration_s"][self.per_enc[g]["present"] > 0]) == 0
                                   for g in self.groups)

    # --- raw material -------------------------------------------------------------------------------
    def has(self, group: str, name: str) -> bool:
        return f"{group}\x1f{name}" in self._sums

    def sum(self, group: str, name: str) -> Sample:
        """The resampled sum over encounters of a per-encounter column of ``group``."""
        try:
            return self._sums[f"{group}\x1f{name}"]
        except KeyError:
            raise UsageError(f"no column {name!r} for group {group!r} in this study") from None

    def n_encounters(self, group: str) -> int:
        return int(self.sum(group, "present").value)

    def flight_hours(self, group: str) -> float:
        return self.sum(group, "duration_s").value / 3600.0

    def max_steps(self, group: str) -> float:
        """Time steps of the longest encounter of ``group`` (``duration_s / dt_s``): the most
        instances one encounter can count."""
        e = self.per_enc[group]
        return float(np.max(e["duration_s"][e["present"] > 0]) / self.dt_s)

    def both_present(self, a: str, b: str) -> np.ndarray:
        return (self.per_enc[a]["present"] > 0) & (self.per_enc[b]["present"] > 0)

    # --- metrics ------------------------------------------------------------------------------------
    def sample(self, group: str, metric: str) -> Sample:
        """A metric of ``group`` as a resampled statistic (:data:`METRICS`)."""
        if group not in self.per_enc:
            raise UsageError(f"group {group!r} is not in these results; present: {', '.join(self.groups)}")
        if metric not in METRICS:
            raise UsageError(f"unknown metric {metric!r}; known: {', '.join(METRICS)}")
        return METRICS[metric].fn(self, group)

    def available(self, group: str, metric: str) -> bool:
        need = METRICS[metric].needs
        return all(self.has(group, c) for c in need)

    def estimate(self, group: str, metric: str) -> "Estimate":
        """Value, 95 % interval and method of a metric (exact where the metric is an encounter
        proportion, the bootstrap otherwise; zeros get exact upper bounds in ``note``)."""
        spec = METRICS[metric]
        if not self.available(group, metric):
            return Estimate(math.nan, math.nan, math.nan, spec.method, "not in these results")
        if spec.exact is not None:
            return spec.exact(self, group)
        return self._boot_estimate(self.sample(group, metric), spec.method, zero_of=spec.zero_of, group=group)

    def _boot_estimate(self, smp: Sample, method: str, zero_of: "str | None" = None, group: str = "") -> "Estimate":
        lo, hi = smp.interval(self.conf)
        note = ""
        if smp.undefined:
            note = f"undefined on {smp.undefined} of {smp.reps.size} resamples (excluded)"
        if not math.isfinite(smp.value):
            return Estimate(math.nan, math.nan, math.nan, method, "undefined on these results")
        if zero_of is not None and smp.value == 0:
            k_enc = self.sum(group, zero_of).value
            n = self.n_encounters(group)
            if k_enc == 0:
                # an encounter counts at most one instance per step, so mean <= steps x share of
                # encounters with any: an exact, assumption-free upper limit for the mean
                one, two = zero_upper_bounds(n, self.conf)
                steps = self.max_steps(group)
                return Estimate(0.0, 0.0, steps * two, "exact binomial bound",
                                f"0 in {n:,} enc.; share of encounters <= {one:.2g} one-sided, <= {two:.2g} "
                                f"two-sided {100 * self.conf:.0f} %; mean <= {steps:g} steps x that share")
        return Estimate(smp.value, lo, hi, f"{method}; {self.boot.describe()}", note)

    def change(self, group: str, metric: str, other: "str | None" = None, kind: str = "ratio") -> "Estimate":
        """Paired change of ``metric`` from ``other`` (default: the baseline) to ``group``:
        ``kind="ratio"`` -> 100 (g/o - 1) %, ``"reduction"`` -> 100 (1 - g/o) %, ``"difference"`` -> g - o."""
        other = other or self.baseline
        smp = self.change_sample(group, metric, other, kind)
        return self._boot_estimate(smp, f"paired bootstrap ({group} vs {other})")

    def change_sample(self, group: str, metric: str, other: str, kind: str = "ratio") -> Sample:
        a, b = self.sample(group, metric), self.sample(other, metric)
        if kind == "ratio":
            return (a / b - 1.0) * 100.0
        if kind == "reduction":
            return (1.0 - a / b) * 100.0
        if kind == "difference":
            return a - b
        raise UsageError(f"change kind must be ratio, reduction or difference, got {kind!r}")

    def pooled_change_sample(self, metric: str, groups: Sequence[str], over: Sequence[str],
                             kind: str = "ratio") -> Sample:
        """Change of the mean of ``metric`` over ``groups`` from its mean over ``over`` (paired)."""
        a = sum((self.sample(g, metric) for g in groups[1:]), self.sample(groups[0], metric)) / len(groups)
        b = sum((self.sample(g, metric) for g in over[1:]), self.sample(over[0], metric)) / len(over)
        return (a / b - 1.0) * 100.0 if kind == "ratio" else (1.0 - a / b) * 100.0

    def mcnemar(self, a: str, b: str, event: str = "lowc"):
        """Exact McNemar of ``event`` encounters, group ``a`` vs ``b``, over encounters both flew."""
        both = self.both_present(a, b)
        return mcnemar_exact(self.per_enc[a][event][both] > 0, self.per_enc[b][event][both] > 0)

    def pi_max(self, group: str) -> float:
        x = self.per_enc[group]["pi_max_src"]
        return float(np.nanmax(x)) if np.isfinite(x).any() else math.nan

    def describe(self) -> str:
        return self.boot.describe()


@dataclass(frozen=True)
class MetricSpec:
    """How a metric is computed: ``fn(study, group) -> Sample``; ``needs`` the per-encounter columns;
    ``exact(study, group) -> Estimate`` replaces the bootstrap interval (encounter proportions);
    ``zero_of`` the column counting encounters with any, for the exact bound of a zero."""

    fn: Callable
    needs: tuple[str, ...]
    method: str
    unit: str = ""
    exact: "Callable | None" = None
    zero_of: "str | None" = None


def _ratio(num: str, den: str, scale: float = 1.0):
    return lambda st, g: st.sum(g, num) / st.sum(g, den) * scale


def _cp(num: str, den: str, scale_fn=None):
    """Clopper-Pearson estimate of sum(num)/sum(den) (both encounter counts), optionally scaled."""
    def f(st, g):
        k, n = st.sum(g, num).value, st.sum(g, den).value
        if n <= 0:
            return Estimate(math.nan, math.nan, math.nan, "Clopper-Pearson over encounters", "no encounters")
        lo, hi = clopper_pearson(k, n, st.conf)
        sc = scale_fn(st, g) if scale_fn else 1.0
        note = ""
        if k == 0:
            one, two = zero_upper_bounds(int(n), st.conf)
            note = f"0 of {int(n):,}; <= {one * sc:.2g} one-sided, <= {two * sc:.2g} two-sided {100 * st.conf:.0f} %"
        return Estimate(k / n * sc, lo * sc, hi * sc, f"Clopper-Pearson over {int(n)} encounters", note)
    return f


def _per_hour(st, g):
    return 3600.0 / float(np.mean(st.per_enc[g]["duration_s"][st.per_enc[g]["present"] > 0]))


def _lowc_rate_exact(st, g):
    if st.equal_durations:
        return _cp("lowc", "present", _per_hour)(st, g)
    return st._boot_estimate(st.sample(g, "lowc_rate_per_hr"), "ratio estimator (durations differ)")


def _build_metrics() -> dict:
    m: dict[str, MetricSpec] = {}
    for q in COUNT_SOURCES:
        m[q] = MetricSpec(_ratio(q, "present"), (q,), "per encounter", "per encounter", zero_of=f"{q}_any")
    m["exact_match"] = MetricSpec(_ratio("blend_exact", "blend_intent"), ("blend_exact", "blend_intent"),
                                  "ratio estimator over blends of a pilot maneuver")
    m["axis_match"] = MetricSpec(_ratio("blend_axis", "blend_intent"), ("blend_axis", "blend_intent"),
                                 "ratio estimator over blends of a pilot maneuver")
    m["neither_match"] = MetricSpec(
        lambda st, g: ((st.sum(g, "blend_intent") - st.sum(g, "blend_exact") - st.sum(g, "blend_axis"))
                       / st.sum(g, "blend_intent")),
        ("blend_exact", "blend_axis", "blend_intent"), "ratio estimator over blends of a pilot maneuver")
    m["blend_neither"] = MetricSpec(_ratio("blend_neither", "present"), ("blend_neither",),
                                    "per encounter (blends of a maneuver matching neither)",
                                    zero_of="blend_neither_any")
    m["blend_intent_share"] = MetricSpec(_ratio("blend_intent", "blend"), ("blend_intent", "blend"),
                                         "ratio estimator over blends")
    m["executed_share"] = MetricSpec(_ratio("pilot_exec", "received"), ("pilot_exec", "received"),
                                     "ratio estimator over received commands")
    m["p_lowc"] = MetricSpec(_ratio("lowc", "present"), ("lowc",), "Clopper-Pearson", exact=_cp("lowc", "present"))
    m["p_nmac"] = MetricSpec(_ratio("nmac", "present"), ("nmac",), "Clopper-Pearson", exact=_cp("nmac", "present"))
    m["lowc_turning_share"] = MetricSpec(_ratio("lowc_turning", "lowc"), ("lowc_turning",),
                                         "Clopper-Pearson over LoWC encounters", exact=_cp("lowc_turning", "lowc"))
    m["p_lowc_step"] = MetricSpec(_ratio("lowc_duration_s", "duration_s"), ("lowc_duration_s",),
                                  "ratio estimator (time in LoWC / flight time)")
    m["p_lowc_per_hr"] = MetricSpec(
        lambda st, g: st.sum(g, "lowc_duration_s") / st.sum(g, "duration_s") / st.flight_hours(g),
        ("lowc_duration_s",), "paper Eq.: ratio estimator of P(LoWC) / this campaign's flight hours")
    m["p_lowc_per_hr_paper_h"] = MetricSpec(
        lambda st, g: st.sum(g, "lowc_duration_s") / st.sum(g, "duration_s") / PAPER_FLIGHT_HOURS,
        ("lowc_duration_s",), "paper Eq. at the paper's 666.67 flight hours")
    m["lowc_rate_per_hr"] = MetricSpec(_ratio("lowc", "duration_s", 3600.0), ("lowc",),
                                       "LoWC encounters per flight hour", exact=_lowc_rate_exact)
    m["pi_mean"] = MetricSpec(_ratio("pi_lowc", "lowc"), ("pi_lowc",), "ratio estimator over LoWC encounters", "s")
    m["pi_paper_mean"] = MetricSpec(_ratio("pi_paper_lowc", "lowc"), ("pi_paper_lowc",),
                                    "ratio estimator over LoWC encounters", "s")
    for k in ("lowc_pi_zero", "lowc_pi_gt_max", "lowc_pi_significant", "nmac"):
        m[f"n_{k}"] = MetricSpec(lambda st, g, k=k: st.sum(g, k), (k,), "encounters", exact=_count_exact(k))
    m["n_lowc"] = MetricSpec(lambda st, g: st.sum(g, "lowc"), ("lowc",), "encounters", exact=_count_exact("lowc"))
    m["dev_h_mean"] = MetricSpec(_ratio("dev_h_m", "present"), ("dev_h_m",), "mean over encounters", "m")
    m["dev_v_mean"] = MetricSpec(_ratio("dev_v_m", "present"), ("dev_v_m",), "mean over encounters", "m")
    m["map_decided_share"] = MetricSpec(_ratio("n_dec_map", "n_dec"), ("n_dec_map", "n_dec"),
                                        "ratio estimator over wait/no-wait decisions")
    m["map_or_both_share"] = MetricSpec(
        lambda st, g: (st.sum(g, "n_dec_map") + st.sum(g, "n_dec_both")) / st.sum(g, "n_dec"),
        ("n_dec_map", "n_dec_both", "n_dec"), "ratio estimator over wait/no-wait decisions")
    m["in_box_share"] = MetricSpec(_ratio("n_in_box", "n_lookup"), ("n_in_box", "n_lookup"),
                                   "ratio estimator over wait-map lookups")
    return m


def _count_exact(col: str):
    """Encounters with ``col``: the count, with the Clopper-Pearson interval of the proportion x n."""
    def f(st, g):
        n = st.n_encounters(g)
        k = st.sum(g, col).value
        lo, hi = clopper_pearson(k, n, st.conf)
        note = ""
        if k == 0:
            one, two = zero_upper_bounds(n, st.conf)
            note = f"0 of {n:,} enc.; share <= {one:.2g} one-sided, <= {two:.2g} two-sided {100 * st.conf:.0f} %"
        return Estimate(k, lo * n, hi * n, f"Clopper-Pearson over {n} encounters", note)
    return f


METRICS: dict[str, MetricSpec] = _build_metrics()


__all__ = ["Estimate", "clopper_pearson", "wilson", "poisson_exact", "rate_ratio", "mean_t", "faa_category",
           "paper_results", "as_columns", "groups_of", "group_metrics", "compute_metrics", "REQUIRED_COLUMNS",
           "BASELINE_GROUP", "GROUP_ORDER", "Study", "Reading", "METRICS", "MetricSpec", "COUNT_SOURCES",
           "COUNTING_DEFAULTS", "COUNTING_HELP", "PAPER_FLIGHT_HOURS", "paper_setup", "counting_options",
           "normalise_decisions"]
