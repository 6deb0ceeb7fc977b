"""Link-delay models and seeded delay processes (sans-IO: no sockets, no clock).

Used by the fast-time study (batched, :class:`BatchedDelay`) and by the UDP delay shim
(:class:`DelayProcess` inside :class:`daa_sil.link.delayline.DelayLine`), so both see the same
delays for the same seed. All times and delays are seconds.

Models (delay distributions in seconds; what a value means -- one link's delay or a round trip --
is the caller's rule, :data:`LATENCY_RULES`):

* :class:`Constant` ``(s)``                         -- groups B-1 (4 s), IC-1 (5 s), ID-1 (4 s)
* :class:`TruncatedGaussian` ``(mean, sd, lo, hi)`` -- groups B-2/ID-2: N(5, 3) restricted to
  [0.2, 10] by **rejection sampling** (not clipping, which would pile mass on the bounds). The
  truncated law has mean ~5.04 s and sd ~2.34 s, not 3 s.
* :class:`Uniform` ``(lo, hi)``
* :class:`Trace` ``(times, delays)``                 -- a recorded trace (CSV ``t,delay``), zero-order
  hold: the delay at ``t`` is the last recorded value at or before ``t`` (the first value before
  the trace starts, the last one after it ends).
* :class:`Spike` ``(base, peak, start, length, period)`` -- a trace built from parameters: ``base``
  seconds, raised to ``peak`` over ``[start, start + length)`` and, with ``period > 0``, again every
  ``period`` seconds (link-fault scenarios: delay spikes to 10 s).
* :class:`daa_sil.models.link_rule.HalfRoundTrip` ``(round_trip)`` -- one link's share of a round trip
  (spec ``half:...``, YAML ``{type: half, round_trip: ...}``).

**Range.** The paper's only sentence on what its latency measures is "The round-trip latency
duration can be in the range of 0.2 to 10 seconds" (Problem Formulation). :data:`ROUND_TRIP_MIN_S`
and :data:`ROUND_TRIP_MAX_S` are that range and the default truncation of :class:`TruncatedGaussian`.
A model's values are validated within ``[LEG_MIN_S, ROUND_TRIP_MAX_S]`` = [0.1, 10] s: 0.1 s is one
link's half of the shortest round trip (the ``round-trip`` rule), 10 s the longest value any
reading applies to one link (the ``one-way`` rule applies the group's value to each link).

The text and YAML forms of these models (``gauss:5,3``, ``{type: gaussian, ...}``) are read by
:mod:`daa_sil.models.delay_spec`. How a group's latency value reaches the two links (one-way on each, or a round trip split evenly)
is :mod:`daa_sil.models.link_rule`.

**Why a piecewise-constant delay process.** Drawing an independent delay per packet reorders
about half of adjacent packets of a 10 Hz stream (48 % measured), and forcing FIFO on top of that
(``release_i = max(t_i + d_i, release_{i-1})``) inflates the effective mean delay from 5.0 s to
8.3 s -- a different experiment (``docs/models.md``, "Link delay"). A :class:`DelayProcess`
therefore holds one draw per *epoch* of ``epoch_s`` seconds (default 10 s); ``epoch_s = 0``
gives per-packet draws for those who want them. Draws are indexed by epoch number (or packet
index with ``epoch_s = 0``) and come from per-block child seeds, so the delay at time ``t`` does
not depend on how many packets were sent before ``t`` or on the order of queries.
"""

from __future__ import annotations

import csv
import abc
import math
import os
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from daa_sil.config.settings import DELAY_EPOCH
from daa_sil.errors import FileFormatError, UsageError

#: the paper's round-trip latency range (s): "The round-trip latency duration can be in the range of
#: 0.2 to 10 seconds" (Problem Formulation); the default truncation of a Gaussian delay
ROUND_TRIP_MIN_S = 0.2
ROUND_TRIP_MAX_S = 10.0
#: one link's share of the shortest round trip (s): the smallest value a model may take
LEG_MIN_S = ROUND_TRIP_MIN_S / 2.0
#: names kept for callers: the default Gaussian truncation, and the largest value (s)
DELAY_MIN_S = ROUND_TRIP_MIN_S
DELAY_MAX_S = ROUND_TRIP_MAX_S
#: default epoch length of the piecewise-constant delay process (s)
DEFAULT_EPOCH_S = DELAY_EPOCH.default
#: epochs (or packets) drawn per child seed; part of the reproducibility contract
BLOCK = 256


def _check_delay(name: str, val: float) -> float:
    try:
        v = float(val)
    except (TypeError, ValueError):
        raise UsageError(f"{name} must be a number of seconds, got {val!r}") from None
    if not math.isfinite(v) or v < LEG_MIN_S or v > DELAY_MAX_S:
        raise UsageError(f"{name} must be within [{LEG_MIN_S:g}, {DELAY_MAX_S:g}] s, got {val!r}")
    return v


class DelayModel(abc.ABC):
    """Abstract base: a one-way delay distribution in seconds (every model implements all four)."""

    kind = "model"
    #: False for a model whose :meth:`sample` never reads its generator (the caller may pass None)
    draws = True

    @abc.abstractmethod
    def sample(self, rng: "np.random.Generator | None", t: "np.ndarray | float") -> np.ndarray:
        """Draw delays (s), one per element of ``t`` (sim times, s; only :class:`Trace` uses them);
        ``rng`` may be None when :attr:`draws` is False."""
        raise NotImplementedError

    @abc.abstractmethod
    def mean(self) -> float:
        """Expected delay (s)."""
        raise NotImplementedError

    @abc.abstractmethod
    def to_dict(self) -> dict:
        """The ``paper_results.yaml`` form (inverse of :func:`delay_model_from_dict`)."""
        raise NotImplementedError

    @abc.abstractmethod
    def spec(self) -> str:
        """The ``--delay`` spec string form (inverse of :func:`parse_delay_spec`)."""
        raise NotImplementedError

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.spec()!r})"


@dataclass(frozen=True, repr=False)
class Constant(DelayModel):
    """Fixed delay ``seconds`` (s)."""

    seconds: float
    kind = "constant"
    draws = False

    def __post_init__(self):
        object.__setattr__(self, "seconds", _check_delay("constant delay", self.seconds))

    def sample(self, rng, t):
        return np.full(np.shape(t), self.seconds, dtype=float)

    def mean(self) -> float:
        return self.seconds

    def to_dict(self) -> dict:
        return {"type": "constant", "seconds": self.seconds}

    def spec(self) -> str:
        return f"const:{self.seconds:g}"


@dataclass(frozen=True, repr=False)
class Uniform(DelayModel):
    """Delay uniform on ``[lo, hi]`` (s)."""

    lo: float
    hi: float
    kind = "uniform"

    def __post_init__(self):
        lo, hi = _check_delay("uniform lo", self.lo), _check_delay("uniform hi", self.hi)
        if hi < lo:
            raise UsageError(f"uniform delay needs lo <= hi, got lo={lo:g} hi={hi:g}")
        object.__setattr__(self, "lo", lo)
        object.__setattr__(self, "hi", hi)

    def sample(self, rng, t):
        return rng.uniform(self.lo, self.hi, size=np.shape(t))

    def mean(self) -> float:
        return 0.5 * (self.lo + self.hi)

    def to_dict(self) -> dict:
        return {"type": "uniform", "lo_s": self.lo, "hi_s": self.hi}

    def spec(self) -> str:
        return f"uniform:{self.lo:g},{self.hi:g}"


@dataclass(frozen=True, repr=False)
class TruncatedGaussian(DelayModel):
    """Gaussian N(``mean``, ``sd``) (s) restricted to ``[lo, hi]`` by rejection sampling."""

    mean_s: float
    sd_s: float
    lo: float = DELAY_MIN_S
    hi: float = DELAY_MAX_S
    kind = "gaussian"

    def __post_init__(self):
        try:
            m, sd = float(self.mean_s), float(self.sd_s)
        except (TypeError, ValueError):
            raise UsageError(f"gaussian delay needs numeric mean and sd, got {self.mean_s!r}, {self.sd_s!r}") from None
        if not (math.isfinite(m) and math.isfinite(sd)) or sd <= 0:
            raise UsageError(f"gaussian delay needs a finite mean and sd > 0, got mean={self.mean_s!r} sd={self.sd_s!r}")
        lo, hi = _check_delay("gaussian lo", self.lo), _check_delay("gaussian hi", self.hi)
        if hi <= lo:
            raise UsageError(f"gaussian delay needs lo < hi, got lo={lo:g} hi={hi:g}")
        # acceptance probability; refuse hopeless truncations (rejection would spin)
        p = 0.5 * (math.erf((hi - m) / (sd * math.sqrt(2))) - math.erf((lo - m) / (sd * math.sqrt(2))))
        if p < 1e-3:
            raise UsageError(f"gaussian delay N({m:g}, {sd:g}) has almost no mass in [{lo:g}, {hi:g}] s "
                             f"(acceptance {p:.1e}); move the mean into the range")
        for k, v in (("mean_s", m), ("sd_s", sd), ("lo", lo), ("hi", hi)):
            object.__setattr__(self, k, v)
        object.__setattr__(self, "_accept", p)

    def sample(self, rng, t):
        shape = np.shape(t)
        n = int(np.prod(shape, dtype=np.int64))
        out = np.empty(n)
        filled = 0
        while filled < n:
            need = n - filled
            batch = rng.normal(self.mean_s, self.sd_s, size=int(need / self._accept * 1.1) + 8)
            ok = batch[(batch >= self.lo) & (batch <= self.hi)][:need]
            out[filled:filled + ok.size] = ok
            filled += ok.size
        return out.reshape(shape)

    def mean(self) -> float:
        """Mean of the truncated law (s), closed form."""
        a, b = (self.lo - self.mean_s) / self.sd_s, (self.hi - self.mean_s) / self.sd_s
        return self.mean_s + self.sd_s * (_phi(a) - _phi(b)) / self._accept

    def std(self) -> float:
        """Standard deviation of the truncated law (s), closed form."""
        a, b = (self.lo - self.mean_s) / self.sd_s, (self.hi - self.mean_s) / self.sd_s
        z = self._accept
        r = (_phi(a) - _phi(b)) / z
        var = 1 + (a * _phi(a) - b * _phi(b)) / z - r * r
        return self.sd_s * math.sqrt(var)

    def to_dict(self) -> dict:
        return {"type": "gaussian", "mean_s": self.mean_s, "sd_s": self.sd_s, "lo_s": self.lo, "hi_s": self.hi}

    def spec(self) -> str:
        return f"gauss:{self.mean_s:g},{self.sd_s:g},{self.lo:g},{self.hi:g}"


def _phi(x: float) -> float:
    return math.exp(-0.5 * x * x) / math.sqrt(2 * math.pi)


class Trace(DelayModel):
    """Recorded delays: ``delays[i]`` (s) holds from ``times[i]`` (s, strictly increasing) on."""

    kind = "trace"
    draws = False

    def __init__(self, times: Sequence[float], delays: Sequence[float], source: str = "<memory>"):
        t = np.asarray(times, dtype=float).ravel()
        d = np.asarray(delays, dtype=float).ravel()
        if t.size == 0 or t.size != d.size:
            raise UsageError(f"delay trace {source} needs the same non-zero number of times and delays "
                             f"(got {t.size} and {d.size})")
        if not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
            raise UsageError(f"delay trace {source}: times must be finite and strictly increasing")
        bad = ~np.isfinite(d) | (d < LEG_MIN_S) | (d > DELAY_MAX_S)
        if bad.any():
            i = int(np.argmax(bad))
            raise UsageError(f"delay trace {source}: delay at t={t[i]:g} s is {d[i]:g}; "
                             f"allowed [{LEG_MIN_S:g}, {DELAY_MAX_S:g}] s")
        self.times, self.delays, self.source = t, d, source

    @classmethod
    def from_csv(cls, path: "str | os.PathLike") -> "Trace":
        """Read a CSV with columns ``t,delay`` (s; a header row is optional)."""
        times, delays = [], []
        try:
            with open(path, newline="", encoding="utf-8") as fh:
                for lineno, row in enumerate(csv.reader(fh), start=1):
                    if not row or not "".join(row).strip() or row[0].lstrip().startswith("#"):
                        continue
                    if len(row) != 2:
                        raise FileFormatError(f"{path}:{lineno}: expected 2 columns 't,delay', got {len(row)}")
                    try:
                        times.append(float(row[0]))
                        delays.append(float(row[1]))
                    except ValueError:
                        if lineno == 1 and not times:  # header
                            continue
                        raise FileFormatError(f"{path}:{lineno}: not numbers: {','.join(row)!r}") from None
        except OSError as exc:
            raise FileFormatError(f"cannot read delay trace {path}: {exc.strerror or exc}") from None
        except UnicodeDecodeError:
            raise FileFormatError(f"delay trace {path} is not a UTF-8 text CSV") from None
        try:
            return cls(times, delays, source=str(path))
        except UsageError as exc:
            raise FileFormatError(str(exc)) from None

    def sample(self, rng, t):
        t = np.asarray(t, dtype=float)
        idx = np.searchsorted(self.times, t, side="right") - 1
        return self.delays[np.clip(idx, 0, self.delays.size - 1)]

    def mean(self) -> float:
        """Time-weighted mean over the trace span (s); plain mean for a one-point trace."""
        if self.times.size == 1:
            return float(self.delays[0])
        return float(np.sum(self.delays[:-1] * np.diff(self.times)) / (self.times[-1] - self.times[0]))

    def to_dict(self) -> dict:
        return {"type": "trace", "file": self.source}

    def spec(self) -> str:
        return f"trace:{self.source}"


class Spike(Trace):
    """Delay spikes: ``base`` s, ``peak`` s over ``[start + n*period, start + n*period + length)``.

    ``period = 0`` is a single spike. It is a :class:`Trace` (zero-order hold, sampled at the
    packet's send time whatever the epoch), built up to ``horizon_s`` (s, default 3600).
    Spec: ``spike:BASE,PEAK,START,LENGTH[,PERIOD]`` (seconds).
    """

    kind = "spike"

    def __init__(self, base: float, peak: float, start: float, length: float, period: float = 0.0,
                 horizon_s: float = 3600.0):
        b, p = _check_delay("spike base", base), _check_delay("spike peak", peak)
        try:
            st, ln, per = float(start), float(length), float(period)
        except (TypeError, ValueError):
            raise UsageError(f"spike start/length/period must be numbers of seconds, got {start!r}, {length!r}, "
                             f"{period!r}") from None
        if not (math.isfinite(st) and st >= 0):
            raise UsageError(f"spike start must be >= 0 s, got {start!r}")
        if not (math.isfinite(ln) and ln > 0):
            raise UsageError(f"spike length must be > 0 s, got {length!r}")
        if not (math.isfinite(per) and (per == 0 or per > ln)):
            raise UsageError(f"spike period must be 0 (one spike) or longer than the spike ({ln:g} s), got {period!r}")
        times, delays = [0.0], [b]
        k = 0
        while True:
            s0 = st + k * per
            if s0 >= horizon_s or (k and per == 0):
                break
            if s0 == 0.0:
                delays[0] = p
            else:
                times.append(s0)
                delays.append(p)
            times.append(s0 + ln)
            delays.append(b)
            k += 1
        self.base, self.peak, self.start, self.length, self.period = b, p, st, ln, per
        super().__init__(times, delays, source=self.spec())

    def to_dict(self) -> dict:
        return {"type": "spike", "base_s": self.base, "peak_s": self.peak, "start_s": self.start,
                "length_s": self.length, "period_s": self.period}

    def spec(self) -> str:
        s = f"spike:{self.base:g},{self.peak:g},{self.start:g},{self.length:g}"
        return s + (f",{self.period:g}" if self.period else "")
