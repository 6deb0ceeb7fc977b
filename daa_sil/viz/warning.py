"""The viz warning category: visualisation problems are warnings, never exceptions."""

from __future__ import annotations

import contextlib
import sys
import warnings
from typing import Iterator


class VizWarning(UserWarning):
    """Visualisation problem that does not stop the simulation (no viewer, no display, ...)."""


def warn_viz(msg: str) -> None:
    """Issue ``msg`` as a :class:`VizWarning`, attributed to the caller's caller."""
    warnings.warn(msg, VizWarning, stacklevel=3)


@contextlib.contextmanager
def one_line_warnings() -> Iterator[None]:
    """Print VizWarnings as ``daa-sil: warning: ...`` (one line, no source location)."""


    def show(message, category, filename, lineno, file=None, line=None):
        if issubclass(category, VizWarning):
            print(f"daa-sil: warning: {message}", file=sys.stderr)
        else:
            previous(message, category, filename, lineno, file, line)

    previous = warnings.showwarning
    with warnings.catch_warnings():
        warnings.simplefilter("always", VizWarning)
        warnings.showwarning = show
        try:
            yield
        finally:
            warnings.showwarning = previous
