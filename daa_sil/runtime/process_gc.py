"""Python's cyclic garbage collector over the life of one of our processes: start-up, steps, exit.

A process that loads the compiled DAA holds ~180,000 long-lived objects (numba's typing registries
and kernels, the MAVLink dialect, our modules) and makes almost no garbage while it starts: a
collection after the imports and the kernel loads finds fewer than 2,000 unreachable objects.
The collector's default thresholds (700, 10, 10) still cost it twice:

* **Start-up.** ~260 young, 24 middle and 2 full collections while a SIL node starts, ~0.15 s of
  CPU of a 1.5-2 s start. :func:`relax_for_startup` (first thing in ``python -m vehicle`` /
  ``python -m gcs``) raises the young generation's threshold to :data:`STARTUP_THRESHOLD`
  allocations: garbage is still collected, a few times instead of hundreds, so a long start (a
  first run that builds the wait maps) stays bounded in memory. :func:`freeze_after_startup` (just
  before the node prints READY) moves every live object into the permanent generation
  (``gc.freeze``) and restores the thresholds, so the steps' collections traverse only what the
  steps create.
* **Exit.** The interpreter's shutdown runs full collections while it clears the modules, and they
  traverse everything still alive: 0.3-0.5 s of CPU once the kernels are loaded (0.1 s for numba
  alone). :func:`freeze_at_exit` registers an ``atexit`` handler that freezes the collector: the
  shutdown is otherwise the normal one (every other ``atexit`` handler runs first, the standard
  streams are flushed, modules are cleared and objects freed by reference counting); only objects
  in reference cycles are left to the operating system. Python makes no promise that ``__del__``
  runs for objects alive at exit anyway, and our files are written and closed explicitly
  (atomically) before a command returns. ``daa-sil`` (:func:`daa_sil.cli.main`), ``daa-vehicle``
  and ``daa-gcs`` (:func:`daa_sil.cli.run_guarded`) call it.

Python's documentation of ``gc.freeze`` describes a similar pattern (the collector off early, frozen
before ``fork``) for processes that fork after loading. None of this changes what a process computes: only when unreachable cycles are freed.
"""

from __future__ import annotations

import atexit
import gc

#: young-generation threshold (net allocations of tracked objects) while a node starts
STARTUP_THRESHOLD = 50_000

_saved_thresholds: "tuple[int, int, int] | None" = None
_exit_hook_registered = False


def relax_for_startup() -> None:
    """Collect the young generation every :data:`STARTUP_THRESHOLD` allocations until
    :func:`freeze_after_startup` (the older generations' ratios are unchanged)."""
    global _saved_thresholds
    if _saved_thresholds is None:
        _saved_thresholds = gc.get_threshold()
    gc.set_threshold(STARTUP_THRESHOLD, *_saved_thresholds[1:])


def freeze_after_startup() -> None:
    """Move every live object to the permanent generation and restore the thresholds
    :func:`relax_for_startup` replaced (a no-op on them if it was not called)."""
    global _saved_thresholds
    gc.freeze()
    if _saved_thresholds is not None:
        gc.set_threshold(*_saved_thresholds)
        _saved_thresholds = None


def freeze_at_exit() -> None:
    """Freeze the collector when the interpreter exits (idempotent; module docstring). The handler
    runs after every ``atexit`` handler registered after it."""
    global _exit_hook_registered
    if not _exit_hook_registered:
        atexit.register(gc.freeze)
        _exit_hook_registered = True
