"""Shared argument parsing helpers: numbers and vectors with one-line errors."""

from __future__ import annotations

import math

from ..errors import UsageError


def parse_vector(text: str, n: int, name: str, units: str = "") -> list[float]:
    """Parse ``"a,b,c"`` into ``n`` finite floats or raise a one-line UsageError naming ``name``."""
    parts = [p.strip() for p in str(text).split(",")]
    if len(parts) != n:
        raise UsageError(f"{name} needs {n} comma-separated numbers{(' (' + units + ')') if units else ''}, "
                         f"got {len(parts)}: {text!r}")
    out = []
    for i, p in enumerate(parts):
        try:
            val = float(p)
        except ValueError:
            raise UsageError(f"{name} component {i + 1} is not a number: {p!r}") from None
        if not math.isfinite(val):
            raise UsageError(f"{name} component {i + 1} must be finite, got {p!r}")
        out.append(val)
    return out


def finite_float(name: str, lo: float | None = None, hi: float | None = None):
    """argparse ``type=`` factory: a finite float within [lo, hi] with a clear message."""

    def conv(text: str) -> float:
        try:
            val = float(text)
        except ValueError:
            raise UsageError(f"{name} must be a number, got {text!r}") from None
        if not math.isfinite(val):
            raise UsageError(f"{name} must be finite, got {text!r}")
        if lo is not None and val < lo or hi is not None and val > hi:
            rng = f"[{'-inf' if lo is None else lo}, {'inf' if hi is None else hi}]"
            raise UsageError(f"{name} must be within {rng}, got {val:g}")
        return val

    conv.__name__ = name
    return conv
