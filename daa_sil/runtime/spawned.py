"""Worker processes the core starts itself (``multiprocessing``'s spawn context): they die with their
parent and need nothing from its main script. The wait-map builders (:mod:`daa_sil.waitmap.build`) and
the compile helper of a cold kernel cache (:mod:`daa_sil.daa.kernels`) start this way; the SIL's
processes go through :mod:`daa_sil.sil.children`."""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import types
from typing import Iterator, Sequence
import ctypes

#: signals that stop a command: Ctrl-C, and SIGTERM / SIGHUP, which our commands take as Ctrl-C
STOP_SIGNALS = tuple(getattr(signal, s) for s in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, s))


def usable_cpus() -> int:
    """The cores this process may run on (its affinity where the OS says, else the machine's count)."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def die_with_parent(parent_pid: int, name: str) -> None:
    """First thing in a worker: Linux: have the kernel SIGKILL this process when its parent dies
    (``PR_SET_PDEATHSIG``), name it ``name`` (``ps``, ``pgrep``; at most 15 characters), and exit at once
    if the parent is already gone. Elsewhere a daemonic worker is stopped when its parent exits
    normally; a killed parent leaves it to finish its task and exit."""
    if sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(1, int(signal.SIGKILL), 0, 0, 0)  # 1 = PR_SET_PDEATHSIG
            libc.prctl(15, ctypes.c_char_p(name.encode()), 0, 0, 0)  # 15 = PR_SET_NAME: pgrep finds it
        except (OSError, AttributeError):
            pass
    if os.getppid() != parent_pid:
        os._exit(1)


def start_spawned(proc) -> None:
    """Start ``proc`` (spawn context) as a worker that needs nothing from this process's main script.

    * SIGINT is ignored from the child's first instruction (a spawned interpreter keeps an inherited
      SIG_IGN), so Ctrl-C reaches only this process, which stops its workers itself.
    * ``spawn`` normally re-runs the parent's main script in the child. A script that builds the wait
      maps or compiles the kernels without an ``if __name__ == "__main__"`` guard would then wait in
      the child for the cache lock its parent holds (a deadlock), and ``python - < script`` has no
      script to re-run at all. A worker needs only its own module, so the main module is hidden
      while the child's start-up data is taken.
    """
    main = sys.modules.get("__main__")
    sys.modules["__main__"] = types.ModuleType("__main__")
    try:
        old = signal.signal(signal.SIGINT, signal.SIG_IGN)
    except ValueError:  # not the main thread: signals are the main thread's business
        old = None
    try:
        proc.start()
    finally:
        if old is not None:
            signal.signal(signal.SIGINT, old)
        if main is not None:
            sys.modules["__main__"] = main


@contextlib.contextmanager
def signals_ignored(signals: Sequence[int] = STOP_SIGNALS) -> Iterator[None]:
    """Ignore ``signals`` (default Ctrl-C, SIGTERM and SIGHUP) while the block runs, so that stopping
    workers or children cannot be cut short by a second Ctrl-C; the previous handlers come back
    afterwards. Only the main thread may set handlers: elsewhere a no-op."""
    try:
        old = {s: signal.signal(s, signal.SIG_IGN) for s in signals}
    except ValueError:  # not the main thread
        yield
        return
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h)
