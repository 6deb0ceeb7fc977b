"""Delay models from their text and YAML forms: ``--latency``/``--up``/``--down`` specs
(``const:4``, ``gauss:5,3``, ...) and scenario / group ``latency:`` mappings. The models themselves are
:mod:`daa_sil.models.latency`; one link's share of a round trip is :mod:`daa_sil.models.link_rule`."""

from __future__ import annotations

from daa_sil.errors import UsageError
from daa_sil.models.latency import (DELAY_MAX_S, DELAY_MIN_S, LEG_MIN_S, Constant, DelayModel, Spike, Trace,
                                    TruncatedGaussian, Uniform)
from daa_sil.models.link_rule import HalfRoundTrip

SPEC_HELP = ("const:S | gauss:MEAN,SD[,LO,HI] | uniform:LO,HI | trace:FILE.csv | spike:BASE,PEAK,START,LEN[,PERIOD] "
             f"(seconds, within [{LEG_MIN_S:g}, {DELAY_MAX_S:g}])")


def parse_delay_spec(spec: str) -> DelayModel:
    """Parse ``const:4``, ``gauss:5,3``, ``gauss:5,3,0.2,10``, ``uniform:1,8``, ``trace:FILE.csv`` or
    ``spike:4,10,60,15[,40]``."""
    text = str(spec).strip()
    kind, sep, rest = text.partition(":")
    kind = kind.strip().lower()
    if not sep or not rest.strip():
        raise UsageError(f"bad delay spec {spec!r}; expected {SPEC_HELP}")
    if kind in ("trace", "file"):
        return Trace.from_csv(rest.strip())
    parts = [p.strip() for p in rest.split(",")]
    try:
        nums = [float(p) for p in parts]
    except ValueError:
        raise UsageError(f"bad delay spec {spec!r}: not all numbers; expected {SPEC_HELP}") from None
    if kind in ("const", "constant") and len(nums) == 1:
        return Constant(nums[0])
    if kind in ("gauss", "gaussian", "normal") and len(nums) in (2, 4):
        return TruncatedGaussian(*nums)
    if kind in ("uniform", "unif") and len(nums) == 2:
        return Uniform(*nums)
    if kind == "spike" and len(nums) in (4, 5):
        return Spike(*nums)
    raise UsageError(f"bad delay spec {spec!r}; expected {SPEC_HELP}")


def delay_model_from_dict(d: dict, where: str = "latency") -> DelayModel:
    """Build a model from the YAML form, e.g. ``{"type": "gaussian", "mean_s": 5, "sd_s": 3}``.

    Types and keys: ``constant`` (``seconds``); ``gaussian`` (``mean_s``, ``sd_s``, optional
    ``lo_s``, ``hi_s``); ``uniform`` (``lo_s``, ``hi_s``); ``trace`` (``file``); ``spike``
    (``base_s``, ``peak_s``, ``start_s``, ``length_s``, optional ``period_s``); ``half``
    (``round_trip``: one of the above, :class:`HalfRoundTrip`).
    ``where`` names the location in error messages.
    """
    if not isinstance(d, dict):
        raise UsageError(f"{where} must be a mapping with a 'type', got {d!r}")
    allowed = {"constant": ({"seconds"}, set()), "gaussian": ({"mean_s", "sd_s"}, {"lo_s", "hi_s"}),
               "uniform": ({"lo_s", "hi_s"}, set()), "trace": ({"file"}, set()),
               "spike": ({"base_s", "peak_s", "start_s", "length_s"}, {"period_s"}),
               "half": ({"round_trip"}, set())}
    typ = str(d.get("type", "")).lower()
    if typ not in allowed:
        raise UsageError(f"{where}.type must be one of {', '.join(allowed)}, got {d.get('type')!r}")
    need, opt = allowed[typ]
    keys = set(d) - {"type"}
    if need - keys:
        raise UsageError(f"{where} ({typ}) is missing {', '.join(sorted(need - keys))}")
    if keys - need - opt:
        raise UsageError(f"{where} ({typ}) has unknown key(s) {', '.join(sorted(keys - need - opt))}; "
                         f"allowed: {', '.join(sorted(need | opt))}")
    if typ == "constant":
        return Constant(d["seconds"])
    if typ == "gaussian":
        return TruncatedGaussian(d["mean_s"], d["sd_s"], d.get("lo_s", DELAY_MIN_S), d.get("hi_s", DELAY_MAX_S))
    if typ == "uniform":
        return Uniform(d["lo_s"], d["hi_s"])
    if typ == "spike":
        return Spike(d["base_s"], d["peak_s"], d["start_s"], d["length_s"], d.get("period_s", 0.0))
    if typ == "half":
        return HalfRoundTrip(delay_model_from_dict(d["round_trip"], where=f"{where}.round_trip"))
    return Trace.from_csv(d["file"])
