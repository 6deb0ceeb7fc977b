"""Errors meant for people: one line, naming what is wrong and what is allowed.

The CLI prints ``daa-sil: error: <message>`` and exits with ``exit_code`` (2 for usage errors),
never a traceback.
"""

from __future__ import annotations
import sys


class DaaSilError(Exception):
    """Base class; ``exit_code`` is the process exit status the CLI uses."""

    exit_code = 1


class UsageError(DaaSilError):
    """Bad command-line value or bad configuration value (exit 2)."""

    exit_code = 2


class FileFormatError(DaaSilError):
    """A file that cannot be read: corrupt, truncated, wrong version or schema (exit 2)."""

    exit_code = 2


class OutputError(DaaSilError):
    """An output cannot be written (unwritable directory, disk full, would overwrite) (exit 1)."""

    exit_code = 1


def warn(message: str) -> None:
    """Print ``daa-sil: warning: <message>`` as one line on stderr (something was wrong and was
    repaired or worked around; the command goes on)."""

    print(f"daa-sil: warning: {' '.join(str(message).split())}", file=sys.stderr, flush=True)


def error_class(name: str) -> type:
    """The error class of this module called ``name`` (DaaSilError if none is): re-raises an error a
    worker process reported by name with the same exit code."""
    cls = globals().get(str(name))
    return cls if isinstance(cls, type) and issubclass(cls, DaaSilError) else DaaSilError
