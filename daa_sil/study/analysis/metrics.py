"""Paper metrics (Tabassum & Bai §V, Tables 3-8) with encounter-level 95 % confidence intervals, as
pure functions of the campaign result tables (``docs/architecture.md``: one row per encounter, one
per decision; a pyarrow Table or a dict of numpy arrays).

**The study** (:class:`Study`, what the report uses). Encounters are the independent units; every
group of a campaign flies the same encounters, so the per-encounter columns of all groups are
aligned by ``encounter_id`` into one panel and resampled together (:mod:`daa_sil.study.analysis.stats`: one
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
resampled sums (paired). Zeros get exact upper bounds (:func:`daa_sil.study.analysis.stats.zero_upper_bounds`).

**Readings** (:class:`~daa_sil.study.analysis.counting.CountingRules`): a campaign directory is one named reading of the paper
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
from dataclasses import dataclass
from functools import lru_cache
from importlib import resources
from typing import Mapping

import numpy as np
from scipy import stats

from daa_sil.config.settings import STEP
from daa_sil.errors import FileFormatError, UsageError
from daa_sil.study.analysis.stats import clopper_pearson

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
    from daa_sil.config.yaml_input import load_yaml  # lazy: start-up time

    text = resources.files("daa_sil").joinpath("data/paper_results.yaml").read_text(encoding="utf-8")
    return load_yaml(text, "daa_sil/data/paper_results.yaml", "table of the paper's results")


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
        import pyarrow as pa  # lazy: start-up time
    except ImportError:  # pragma: no cover
        pa = None
    if pa is not None and isinstance(table, pa.Table):
        return {k: np.asarray(table.column(k).to_numpy(zero_copy_only=False)) for k in table.column_names}
    raise UsageError(f"result table must be a pyarrow Table or a dict of arrays, got {type(table).__name__}")


def check_columns(cols: dict, where: str = "encounter table") -> None:
    """Raise :class:`FileFormatError` naming ``where`` if a required column is missing or the columns differ in length."""
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


def group_metrics(enc, group: "str | None" = None, conf: float = CONF, dt_s: float = STEP.default) -> dict:
    """The old analytic metrics of one group (``group`` None: the table must hold exactly one group).
    Returns ``{name: Estimate}`` plus ``n_encounters`` and ``flight_hours`` floats.

    Intervals treat time steps as independent: counts summed over steps get the exact (Garwood)
    Poisson interval, step shares Clopper-Pearson over steps, changes vs the baseline the exact
    conditional rate-ratio interval, ``p_lowc_per_hr`` Clopper-Pearson over (LoWC steps, steps) /
    flight hours, means Student t. Kept as the baseline of ``benchmarks/bench_report.py`` and for the
    interval-width comparison; :class:`Study` is the encounter-level replacement."""
    cols = as_columns(enc) if not isinstance(enc, dict) else {k: np.asarray(v) for k, v in enc.items()}
    check_columns(cols)
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


def compute_metrics(enc, baseline: str = BASELINE_GROUP, conf: float = CONF, dt_s: float = STEP.default) -> dict:
    """``{group: group_metrics}`` for every group, plus the changes vs ``baseline``
    (``no_wait_reduction_pct``, ``received_change_pct``) where the baseline is present."""
    cols = as_columns(enc) if not isinstance(enc, dict) else {k: np.asarray(v) for k, v in enc.items()}
    check_columns(cols)
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


#: the paper's flight hours per group (10,000 encounters x 240 s)
PAPER_FLIGHT_HOURS = 10_000 * 240.0 / 3600.0
PAPER_MAX_PI = 3.79  # paper §V: the maximum PI over all groups (ID-1)
PI_SIGNIFICANT = 10.0  # paper §V (after DO-365): PI > 10 is a significant LoWC


__all__ = ["Estimate", "clopper_pearson", "poisson_exact", "rate_ratio", "mean_t", "faa_category",
           "paper_results", "as_columns", "groups_of", "group_metrics", "compute_metrics", "REQUIRED_COLUMNS",
           "BASELINE_GROUP", "GROUP_ORDER", "PAPER_FLIGHT_HOURS"]
