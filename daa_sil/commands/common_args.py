"""Shared argument parsing helpers: numbers and vectors with one-line errors, the one-line-error
parser of every console script, and the options the node scripts share (speed, signing key)."""

from __future__ import annotations

import argparse
import contextlib
import errno
import math
import os
import sys
from typing import Iterator

from ..errors import UsageError

#: realtime speed factor range of ``--speed`` (daa-sil run/demo, daa-vehicle, daa-gcs)
SPEED_MIN, SPEED_MAX = 0.01, 1000.0


class OneLineParser(argparse.ArgumentParser):
    """``argparse`` with the project's error form: one line ``prog: error: message``, exit 2."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message}\n")


def check_speed(speed: float) -> float:
    """``--speed`` (realtime factor) finite within [0.01, 1000]; otherwise a one-line UsageError."""
    if not (math.isfinite(speed) and SPEED_MIN <= speed <= SPEED_MAX):
        raise UsageError(f"--speed must be within [{SPEED_MIN:g}, {SPEED_MAX:g}], got {speed:g}")
    return speed


def load_key_option(path, prog: str = "daa-sil") -> "bytes | None":
    """The MAVLink 2 signing key of ``--key FILE`` (None without the option); notes about the file
    (mode, passphrase or raw key) go to stderr as ``PROG: warning: ...``."""
    if path is None:
        return None

    from ..link.keys import load_key  # lazy: start-up time

    return load_key(path, warn=lambda text: print(f"{prog}: warning: {text}", file=sys.stderr, flush=True))


def int_at_least(name: str, lo: int):
    """argparse ``type=`` factory: an integer >= ``lo`` (0: non-negative, 1: positive)."""
    what = {0: "a non-negative integer", 1: "a positive integer"}.get(lo, f"an integer >= {lo}")

    def conv(text: str) -> int:
        try:
            val = int(text)
        except ValueError:
            raise UsageError(f"{name} must be {what}, got {text!r}") from None
        if val < lo:
            raise UsageError(f"{name} must be {what}, got {val}")
        return val

    conv.__name__ = name
    return conv


def setting_int(name: str, setting):
    """argparse ``type=`` factory: an integer within ``setting``'s range
    (:class:`daa_sil.config.settings.Setting`, where the range is defined once), one line otherwise."""

    def conv(text: str) -> int:
        try:
            val = int(text)
        except ValueError:
            raise UsageError(f"{name} must be an integer, got {text!r}") from None
        return setting.check(val, key=name)

    conv.__name__ = name
    return conv


def workers_option(name: str = "--workers"):
    """argparse ``type=`` factory: a worker count within ``[1, WORKERS_PER_CORE x usable cores]``
    (:func:`daa_sil.runtime.resources.check_workers`)."""

    def conv(text: str) -> int:
        from daa_sil.runtime.resources import check_workers  # lazy: start-up time

        try:
            val = int(text)
        except ValueError:
            raise UsageError(f"{name} must be an integer, got {text!r}") from None
        return check_workers(val, name)

    conv.__name__ = name
    return conv


def add_allow_large(p: argparse.ArgumentParser, what: str) -> None:
    """``--allow-large``: run even when the memory estimate exceeds the machine's memory."""
    from daa_sil.runtime.resources import MEMORY_SHARE  # lazy: start-up time

    p.add_argument("--allow-large", action="store_true",
                   help=f"run even when the estimated peak memory of {what} exceeds {MEMORY_SHARE * 100:.0f} %% of "
                        "this machine's memory (without it such a run is refused before anything starts)")


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


class _KeepPlaying:
    """``sys.stdout`` for :func:`stdout_may_close`: writes through until the reader goes away, then
    says so once on stderr and drops the rest (fd 1 becomes ``/dev/null``, so the interpreter's own
    flush at exit does not fail either)."""

    def __init__(self, real, prog: str, out) -> None:
        self.real, self.prog, self.out, self.closed_reader = real, prog, out, False

    def _gone(self) -> None:
        if self.closed_reader:
            return
        self.closed_reader = True
        try:
            fd = os.open(os.devnull, os.O_WRONLY)
            os.dup2(fd, self.real.fileno())
            os.close(fd)
        except (OSError, ValueError, AttributeError):  # not a real file (a test's StringIO)
            pass
        print(f"{self.prog}: note: standard output was closed; playing on, the results are in {self.out}",
              file=sys.stderr, flush=True)

    def write(self, text: str) -> int:
        if not self.closed_reader:
            try:
                return self.real.write(text)
            except OSError as exc:
                if exc.errno not in (errno.EPIPE, errno.EINVAL):
                    raise
                self._gone()
        return len(text)

    def flush(self) -> None:
        if not self.closed_reader:
            try:
                self.real.flush()
            except OSError as exc:
                if exc.errno not in (errno.EPIPE, errno.EINVAL):
                    raise
                self._gone()

    def __getattr__(self, name):
        return getattr(self.real, name)


@contextlib.contextmanager
def stdout_may_close(prog: str, out) -> Iterator[None]:
    """While the block runs, a standard output whose reader goes away (``daa-sil demo --out D | true``,
    ``| head -3``) does not stop the command: one note on stderr, the rest of stdout is dropped, and the
    run plays on to its files in ``out`` and its usual exit status (the run is the product; its
    commentary on stdout is not)."""
    real = sys.stdout
    guard = _KeepPlaying(real, prog, out)
    sys.stdout = guard
    try:
        yield
    finally:
        if sys.stdout is guard:
            sys.stdout = real
