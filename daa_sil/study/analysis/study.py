"""The encounter-level study of one reading (:class:`Study`).

Every metric of every group (the registry :data:`METRICS`) with its encounter-level interval
(cluster bootstrap or exact), and paired changes between groups that flew the same encounters.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from daa_sil.config.settings import STEP
from daa_sil.errors import FileFormatError, UsageError
from daa_sil.study.analysis.metrics import (BASELINE_GROUP, CONF, PAPER_FLIGHT_HOURS, PAPER_MAX_PI, PI_SIGNIFICANT, Estimate,
                                  check_columns, as_columns, groups_of)
from daa_sil.study.analysis.counting import COUNT_SOURCES, OPTIONAL_QUANTITIES, CountingRules, provenance_columns, normalise_decisions
from daa_sil.study.analysis.stats import (
    DEFAULT_REPLICATES,
    DEFAULT_SEED,
    ClusterBootstrap,
    Sample,
    clopper_pearson,
    mcnemar_exact,
    zero_upper_bounds,
)


#: per-encounter columns a study reads when the results have them (severity, deviation definitions)
OPTIONAL_COLUMNS = ("max_alert_level", "dev_h_tmean_m", "dev_v_tmean_m", "dev_xtrack_m", "dev_h_end_m")


class Study:
    """Encounter-level metrics of every group of one reading (see the module docstring).

    ``enc`` the per-encounter table (Table or dict of arrays), ``reading`` a :class:`CountingRules`,
    ``dec`` the per-decision table (optional; for decision provenance), ``replicates``/``seed`` of
    the bootstrap, ``conf`` the interval level, ``dt_s`` the simulation step (s; bounds the
    instances one encounter can count)."""

    def __init__(self, enc, reading: "CountingRules | None" = None, *, dec=None, replicates: int = DEFAULT_REPLICATES,
                 seed: int = DEFAULT_SEED, conf: float = CONF, baseline: str = BASELINE_GROUP, dt_s: float = STEP.default):
        cols = enc if isinstance(enc, dict) else as_columns(enc)
        cols = {k: np.asarray(v) for k, v in cols.items()}
        check_columns(cols)
        self.reading = reading if reading is not None else CountingRules()
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
            e["maneuvered"] = (e["dev_h_m"] + e["dev_v_m"] > 1.0).astype(float)  # left the plan by over 1 m
            for c in (x for x in OPTIONAL_COLUMNS if x in cols):
                e[c] = col(c)
            if "max_alert_level" in cols:
                for lvl in (1, 2, 3):
                    e[f"alert_ge{lvl}"] = (e["max_alert_level"] >= lvl).astype(float)
            e["dev_h_maneuvered"] = e["dev_h_m"] * e["maneuvered"]
            if "n_active_steps" in cols:
                e["active_steps"] = col("n_active_steps")
                e["active_any"] = (e["active_steps"] > 0).astype(float)
            for q in self.quantities:
                e[q] = sum((col(c) for c in self.columns_used[q]), np.zeros(self.n))
                e[f"{q}_any"] = (e[q] > 0).astype(float)
            if all(q in e for q in ("blend_intent", "blend_exact", "blend_axis")):
                # blends of a pilot maneuver matching neither its direction nor its axis
                e["blend_neither"] = np.maximum(e["blend_intent"] - e["blend_exact"] - e["blend_axis"], 0.0)
                e["blend_neither_any"] = (e["blend_neither"] > 0).astype(float)
            prov = provenance_columns(dec_cols, g, self.ids)
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
    # --- signatures of the simulator (daa_sil/study/report/signatures.py) and LoWC time -------------------
    m["unsafe_share"] = MetricSpec(
        lambda st, g: ((st.sum(g, "daa_override") + st.sum(g, "blend"))
                       / (st.sum(g, "pilot_exec") + st.sum(g, "daa_override") + st.sum(g, "blend"))),
        ("daa_override", "blend", "pilot_exec"), "ratio estimator over arriving commands (pilot + override + blend)")
    m["no_wait_per_received"] = MetricSpec(_ratio("no_wait", "received"), ("no_wait", "received"),
                                           "ratio estimator (DAA allocations without a command / received)")
    m["wait_per_received"] = MetricSpec(_ratio("wait", "received"), ("wait", "received"),
                                        "ratio estimator (waits / received)")
    m["active_share"] = MetricSpec(_ratio("active_any", "present"), ("active_any",), "Clopper-Pearson",
                                   exact=_cp("active_any", "present"))
    m["active_steps_mean"] = MetricSpec(_ratio("active_steps", "active_any"), ("active_steps", "active_any"),
                                        "ratio estimator over encounters ever active", "steps")
    m["lowc_duration_mean"] = MetricSpec(_ratio("lowc_duration_s", "lowc"), ("lowc_duration_s",),
                                         "ratio estimator over LoWC encounters", "s")
    m["lowc_s_per_hr"] = MetricSpec(_ratio("lowc_duration_s", "duration_s", 3600.0), ("lowc_duration_s",),
                                    "ratio estimator (seconds in LoWC per flight hour)", "s/h")
    # --- severity, deviation definitions, authority switches (the experiments' page) ----------------
    for lvl in (1, 2, 3):
        m[f"alert_share_{lvl}"] = MetricSpec(_ratio(f"alert_ge{lvl}", "present"), (f"alert_ge{lvl}",),
                                             "Clopper-Pearson", exact=_cp(f"alert_ge{lvl}", "present"))
    m["maneuvered_share"] = MetricSpec(_ratio("maneuvered", "present"), ("maneuvered",), "Clopper-Pearson",
                                       exact=_cp("maneuvered", "present"))
    m["dev_h_maneuvered_mean"] = MetricSpec(_ratio("dev_h_maneuvered", "maneuvered"), ("dev_h_maneuvered",),
                                            "ratio estimator over encounters that left the plan", "m")
    for c in OPTIONAL_COLUMNS[1:]:
        m[c[:-2] + "_mean"] = MetricSpec(_ratio(c, "present"), (c,), "mean over encounters", "m")
    m["switches_per_active"] = MetricSpec(_ratio("n_switches", "active_any"), ("n_switches", "active_any"),
                                          "ratio estimator over encounters ever active")
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
