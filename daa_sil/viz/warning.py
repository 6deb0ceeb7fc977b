"""The viz warning category: visualisation problems are warnings, never exceptions."""

from __future__ import annotations

import warnings


class VizWarning(UserWarning):
    """Visualisation problem that does not stop the simulation (no viewer, no display, ...)."""


def _warn(msg: str) -> None:
    warnings.warn(msg, VizWarning, stacklevel=3)
