"""Python's cyclic garbage collector around a SIL node's start-up (the vehicle and the GCS).

Starting a node creates ~180,000 long-lived objects (numba's typing registries and loaded kernels,
the dialect, the project's modules) and almost no garbage: a collection after the imports and the
kernel loads finds fewer than 2,000 unreachable objects. With the default thresholds (700, 10, 10)
the collector still ran ~260 young, ~24 middle and 2 full collections during that start-up, and
the full ones traverse everything alive: about 0.15 s of CPU of a 1.5-2 s start.

* :func:`relax_for_startup` (first thing in ``python -m vehicle`` / ``python -m gcs``) raises the
  young generation's threshold to :data:`STARTUP_THRESHOLD` allocations. Garbage is still
  collected, a few times during start-up instead of hundreds, so a long start (a first run that
  builds the wait maps) stays bounded in memory.
* :func:`freeze_after_startup` (just before the node prints READY) moves every object alive into
  the collector's permanent generation (``gc.freeze``) and restores the thresholds it found: the
  steps' collections then traverse only what the steps create, never the start-up's objects.
  Python's documentation describes the same pattern for servers that fork after loading.

Neither changes what a node computes: only when unreachable cycles are freed.
"""

from __future__ import annotations

import gc

#: young-generation threshold (net allocations of tracked objects) while a node starts
STARTUP_THRESHOLD = 50_000

_saved_thresholds: "tuple[int, int, int] | None" = None


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
