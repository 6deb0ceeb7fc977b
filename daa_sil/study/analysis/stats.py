"""Encounter-level statistics: a seeded, vectorised cluster bootstrap, exact binomial bounds and the
exact McNemar test. Pure numpy/scipy, no I/O.

Why encounters: the campaign's counts (no-wait decisions, pilot commands received, blends, ...) are
per time step, but the steps of one encounter are not independent -- an encounter that turns into
a long conflict contributes dozens of correlated steps, most contribute none. The independent unit
is the encounter, so every interval here resamples encounters (clusters), never steps.

**Cluster bootstrap** (:class:`ClusterBootstrap`). ``B`` resamples of the ``n`` encounters, drawn
with replacement, are stored as multinomial count weights ``W`` (``B x n``; row ``b`` says how often
each encounter appears in resample ``b``). Any statistic that is a function of per-encounter sums
-- a total, a mean per encounter, a ratio of two sums (exact-match share, PI over LoWC encounters,
P(LoWC) per step), a change between two groups -- is evaluated on every resample at once from
``W @ X`` (``X``: ``n x K`` per-encounter columns), one matrix product per block of
:data:`BLOCK` replicates, no Python loop over replicates. The weights depend only on ``(n, B,
seed)``: block ``j`` is drawn from ``SeedSequence(seed).spawn`` child ``j``, so a report is
reproducible from the seed and replicate count it records.

**Paired comparisons.** The groups of a campaign fly the same encounters (same ``encounter_id``),
so the same ``W`` is applied to every group: one resample of encounter ids per replicate, used by
both sides of a comparison. A change such as ``mean_g / mean_B-2 - 1`` is then computed on each
resample from paired sums, which keeps the (large, positive) correlation between groups and gives
the narrower, correct interval.

**Interval**: BCa (bias-corrected and accelerated; Efron 1987) from the replicates, with the
acceleration from the leave-one-encounter-out jackknife, which for functions of sums is exact and
vectorised (``total - x_i``); the plain percentile interval is available and is the fallback where
BCa is undefined. Resamples on which a statistic is undefined (e.g. a mean PI over LoWC encounters when
a resample holds no LoWC encounter) are dropped and counted (:attr:`Sample.undefined`).
``tests/test_stats.py`` checks the coverage on clustered data with a known answer.

**Exact results** where the bootstrap has nothing to resample: Clopper-Pearson for encounter-level
proportions (a LoWC/NMAC encounter is one Bernoulli trial per encounter), upper bounds for zero
observed (:func:`zero_upper_bounds`: one-sided ``1 - a^(1/n)`` and the upper limit of the
two-sided interval ``1 - (a/2)^(1/n)``), and the exact McNemar test for paired binary outcomes
(:func:`mcnemar_exact`: a binomial test on the discordant pairs).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterator, Mapping

import numpy as np
from scipy import stats as sps

from daa_sil.config.settings import BOOTSTRAP_REPLICATES
from daa_sil.errors import UsageError

CONF = 0.95
#: bootstrap replicates per report unless told otherwise (its range: ``campaign report --replicates``)
DEFAULT_REPLICATES = BOOTSTRAP_REPLICATES.default
#: bootstrap seed per report unless told otherwise (recorded in every report)
DEFAULT_SEED = 14
#: replicates per weight block (fixed: the weights of a seed must not depend on memory settings)
BLOCK = 250


# --- a statistic and its replicates ------------------------------------------------------------------
def _vals(x):
    return (x.value, x.reps, x.jack) if isinstance(x, Sample) else (x, x, x)


@dataclass(frozen=True, eq=False)
class Sample:
    """A statistic: ``value`` on the full sample, ``reps`` (B,) on the bootstrap resamples and
    ``jack`` (n,) on the leave-one-encounter-out samples (for the BCa acceleration).

    Arithmetic with another Sample (of the same bootstrap) or a number applies to all three, so a
    derived statistic carries its own bootstrap and jackknife distributions. Division by zero gives
    nan/inf (undefined on that resample), never a warning."""

    value: float
    reps: np.ndarray
    jack: "np.ndarray | None" = None

    def _op(self, other, f) -> "Sample":
        a, ar, aj = _vals(self)
        b, br, bj = _vals(other)
        with np.errstate(all="ignore"):
            # jackknife values pair up only within one bootstrap (same encounters); numbers broadcast
            jack = None
            if aj is not None and bj is not None and (np.ndim(aj) == 0 or np.ndim(bj) == 0
                                                      or np.shape(aj) == np.shape(bj)):
                jack = f(aj, bj)
            return Sample(float(f(np.float64(a), np.float64(b))), f(ar, br), jack)

    def __add__(self, o):
        return self._op(o, np.add)

    def __radd__(self, o):
        return self._op(o, lambda a, b: np.add(b, a))

    def __sub__(self, o):
        return self._op(o, np.subtract)

    def __rsub__(self, o):
        return self._op(o, lambda a, b: np.subtract(b, a))

    def __mul__(self, o):
        return self._op(o, np.multiply)

    def __rmul__(self, o):
        return self._op(o, lambda a, b: np.multiply(b, a))

    def __truediv__(self, o):
        return self._op(o, np.divide)

    def __rtruediv__(self, o):
        return self._op(o, lambda a, b: np.divide(b, a))

    def __neg__(self):
        return Sample(-self.value, -self.reps, None if self.jack is None else -self.jack)

    def map(self, f) -> "Sample":
        """``f`` (vectorised) applied to the value, every replicate and every jackknife value."""
        with np.errstate(all="ignore"):
            return Sample(float(f(np.float64(self.value))), f(self.reps), None if self.jack is None else f(self.jack))

    @property
    def undefined(self) -> int:
        """Resamples on which the statistic is undefined (nan or infinite)."""
        return int(np.count_nonzero(~np.isfinite(self.reps)))

    def interval(self, conf: float = CONF, method: str = "bca") -> tuple[float, float]:
        """``conf`` interval over the defined replicates: ``"bca"`` (bias-corrected and accelerated,
        acceleration from the jackknife; the default) or ``"percentile"``. BCa falls back to the
        percentile interval when its corrections are undefined (every replicate on one side of the
        value, or no jackknife). nan if the value itself is undefined or fewer than 2 replicates are."""
        r = self.reps[np.isfinite(self.reps)]
        if not math.isfinite(self.value) or r.size < 2:
            return math.nan, math.nan
        a = (1.0 - conf) / 2.0
        qs = [a, 1.0 - a]
        if method == "bca":
            qs = _bca_levels(self.value, r, self.jack, a) or qs
        elif method != "percentile":
            raise UsageError(f"interval method must be 'bca' or 'percentile', got {method!r}")
        lo, hi = np.quantile(r, qs)
        return float(lo), float(hi)


def _bca_levels(value: float, r: np.ndarray, jack, a: float) -> "list[float] | None":
    """BCa quantile levels (Efron 1987) or None when undefined."""
    below = (np.count_nonzero(r < value) + 0.5 * np.count_nonzero(r == value)) / r.size
    if not 0.0 < below < 1.0 or jack is None:
        return None
    j = np.asarray(jack, float)
    j = j[np.isfinite(j)]
    if j.size < 3:
        return None
    d = j.mean() - j
    den = float(np.sum(d * d)) ** 1.5
    acc = float(np.sum(d ** 3)) / (6.0 * den) if den > 0 else 0.0
    z0 = float(sps.norm.ppf(below))
    out = []
    for q in (a, 1.0 - a):
        z = z0 + float(sps.norm.ppf(q))
        den_q = 1.0 - acc * z
        if den_q <= 0:
            return None
        out.append(float(sps.norm.cdf(z0 + z / den_q)))
    return out


def independent_difference(a: Sample, b: Sample, seed: int = DEFAULT_SEED) -> Sample:
    """``a - b`` for statistics of two *independent* samples (e.g. two campaigns on different
    seeds): ``b``'s replicates are permuted (seeded) so they no longer share ``a``'s resampling
    weights; percentile intervals (no common jackknife)."""
    if a.reps.size != b.reps.size:
        raise UsageError(f"replicate counts differ ({a.reps.size} vs {b.reps.size})")
    perm = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(0xD1FF,))).permutation(b.reps.size)
    with np.errstate(all="ignore"):
        return Sample(a.value - b.value, a.reps - b.reps[perm], None)


def combine(f, *samples: Sample) -> Sample:
    """``f(*values)``, ``f(*replicates)`` and ``f(*jackknife values)`` for any vectorised ``f``."""
    with np.errstate(all="ignore"):
        jack = None if any(s.jack is None for s in samples) else f(*[s.jack for s in samples])
        return Sample(float(f(*[np.float64(s.value) for s in samples])), f(*[s.reps for s in samples]), jack)


# --- the cluster bootstrap -----------------------------------------------------------------------------
class ClusterBootstrap:
    """``replicates`` resamples of ``n`` encounters with replacement, seeded (see the module doc).

    ``sums(X)`` -> ``(B, K)`` weighted column sums of ``X`` (n, K); ``sample_sums(columns)`` ->
    ``{name: Sample}`` for a mapping of per-encounter columns (each (n,)), value = the plain sum."""

    def __init__(self, n: int, replicates: int = DEFAULT_REPLICATES, seed: int = DEFAULT_SEED):
        if not isinstance(n, (int, np.integer)) or n < 1:
            raise UsageError(f"the bootstrap needs at least one encounter, got n = {n!r}")
        if not isinstance(replicates, (int, np.integer)) or replicates < 10:
            raise UsageError(f"bootstrap replicates must be an integer >= 10, got {replicates!r}")
        if not isinstance(seed, (int, np.integer)) or seed < 0:
            raise UsageError(f"bootstrap seed must be a non-negative integer, got {seed!r}")
        self.n, self.replicates, self.seed = int(n), int(replicates), int(seed)

    def describe(self) -> str:
        return (f"encounter-level (cluster) bootstrap, {self.replicates} replicates, seed {self.seed}, "
                f"BCa intervals")

    def weight_blocks(self) -> Iterator[np.ndarray]:
        """Multinomial count weights, ``(b, n)`` float64 blocks of up to :data:`BLOCK` replicates."""
        n = self.n
        children = np.random.SeedSequence(self.seed).spawn((self.replicates + BLOCK - 1) // BLOCK)
        for j, child in enumerate(children):
            b = min(BLOCK, self.replicates - j * BLOCK)
            idx = np.random.default_rng(child).integers(0, n, size=(b, n))
            idx += (np.arange(b) * n)[:, None]
            yield np.bincount(idx.ravel(), minlength=b * n).reshape(b, n).astype(np.float64)

    def sums(self, X) -> np.ndarray:
        """``W @ X`` for per-encounter columns ``X`` (n, K): (B, K)."""
        X = np.asarray(X, dtype=np.float64)
        if X.ndim == 1:
            X = X[:, None]
        if X.shape[0] != self.n:
            raise UsageError(f"bootstrap over {self.n} encounters got columns of length {X.shape[0]}")
        out = np.empty((self.replicates, X.shape[1]))
        row = 0
        for w in self.weight_blocks():
            out[row:row + w.shape[0]] = w @ X
            row += w.shape[0]
        return out

    def sample_sums(self, columns: Mapping[str, np.ndarray]) -> dict[str, Sample]:
        """Per-encounter columns -> their sums as Samples (one matrix product for all)."""
        names = list(columns)
        if not names:
            return {}
        X = np.column_stack([np.nan_to_num(np.asarray(columns[k], dtype=np.float64)) for k in names])
        full = X.sum(axis=0)
        reps = self.sums(X)
        jack = full[None, :] - X  # leave-one-encounter-out sums (n, K)
        return {k: Sample(float(full[i]), reps[:, i], jack[:, i]) for i, k in enumerate(names)}


# --- exact results -------------------------------------------------------------------------------------
def clopper_pearson(k: float, n: float, conf: float = CONF) -> tuple[float, float]:
    """Exact binomial interval for ``k`` successes in ``n`` trials."""
    if n <= 0:
        raise UsageError(f"a proportion needs n > 0 trials, got n = {n}")
    a = 1.0 - conf
    lo = 0.0 if k <= 0 else float(sps.beta.ppf(a / 2, k, n - k + 1))
    hi = 1.0 if k >= n else float(sps.beta.ppf(1 - a / 2, k + 1, n - k))
    return lo, hi


def zero_upper_bounds(n: int, conf: float = CONF) -> tuple[float, float]:
    """Exact upper bounds on a proportion after 0 events in ``n`` trials: ``(one-sided, two-sided)``
    = ``(1 - a^(1/n), 1 - (a/2)^(1/n))`` for ``a = 1 - conf`` (about 3.0/n and 3.7/n at 95 %)."""
    if n <= 0:
        raise UsageError(f"an upper bound needs n > 0 trials, got n = {n}")
    a = 1.0 - conf
    return 1.0 - a ** (1.0 / n), 1.0 - (a / 2.0) ** (1.0 / n)


@dataclass(frozen=True)
class McNemar:
    """Exact McNemar test of paired binary outcomes ``a`` vs ``b`` over the same encounters."""

    a_only: int  #: encounters where the event happened under a but not b
    b_only: int  #: ... under b but not a
    both: int
    n: int
    p_value: float  #: two-sided exact: binomial test of a_only among the discordant pairs, p = 1/2

    @property
    def difference(self) -> float:
        """``P(a) - P(b)`` = ``(a_only - b_only) / n``."""
        return (self.a_only - self.b_only) / self.n


def mcnemar_exact(a, b) -> McNemar:
    """Exact McNemar test for bool arrays ``a``, ``b`` (same encounters, same order)."""
    a = np.asarray(a, bool)
    b = np.asarray(b, bool)
    if a.shape != b.shape or a.ndim != 1:
        raise UsageError(f"McNemar needs two paired 1-D outcome arrays, got shapes {a.shape} and {b.shape}")
    n10 = int(np.count_nonzero(a & ~b))
    n01 = int(np.count_nonzero(~a & b))
    p = 1.0 if n10 + n01 == 0 else float(sps.binomtest(n10, n10 + n01, 0.5).pvalue)
    return McNemar(n10, n01, int(np.count_nonzero(a & b)), int(a.size), min(1.0, p))


def ratio_linearized(y, x, conf: float = CONF) -> tuple[float, float, float]:
    """The classical ratio estimator ``R = sum y / sum x`` over independent clusters with its
    linearised (delta-method) normal interval: ``Var R = n/(n-1) sum (y_i - R x_i)^2 / (sum x)^2``.
    An analytic cross-check of the bootstrap (no resampling)."""
    y = np.asarray(y, float)
    x = np.asarray(x, float)
    n = y.size
    sx = x.sum()
    if n < 2 or sx == 0:
        return math.nan, math.nan, math.nan
    r = y.sum() / sx
    e = y - r * x
    se = math.sqrt(n / (n - 1) * float(np.sum(e * e))) / abs(sx)
    z = float(sps.norm.ppf(0.5 + conf / 2))
    return float(r), float(r - z * se), float(r + z * se)


__all__ = ["CONF", "DEFAULT_REPLICATES", "DEFAULT_SEED", "BLOCK", "Sample", "combine", "independent_difference",
           "ClusterBootstrap",
           "clopper_pearson", "zero_upper_bounds", "McNemar", "mcnemar_exact", "ratio_linearized"]
