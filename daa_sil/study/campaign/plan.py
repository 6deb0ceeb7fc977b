"""How a campaign's chunks are batched into tasks.

A *unit* is one chunk of one group (one pair of result files). A task simulates several units side
by side in one batch (:func:`daa_sil.study.simulation.fasttime.simulate_parts`), so that every element-wise
numpy call of a step carries the rows of all of them; the results of each unit are exactly those of
the unit run alone. The plan keeps the workers balanced and each task's memory bounded:

* about ``batch_rows`` encounter rows per task at most: peak memory grows with the rows of a task
  (about 21 kB a row with two intruders, 10,000 rows ~ 0.43 GiB), and a killed campaign loses the
  tasks in flight;
* a number of tasks that is a multiple of the worker count (when there are enough units), each
  with about the same number of rows: a task is a contiguous run of units in (chunk, group) order
  (cut at the unit boundaries nearest to equal shares of the rows; every task gets a unit), so it
  holds the groups of one or two chunks.
  Those fly the same encounters and share their random streams and equal delay tables
  (:func:`daa_sil.study.simulation.fasttime.simulate_parts`); with chunks of five groups, a task of four or
  more units still holds four or five different groups (the groups' costs differ);
* with ``min_tasks``, at least that many tasks (finer progress and resume), as far as units allow.
"""

from __future__ import annotations

import bisect
import math
from typing import Sequence

from daa_sil.config.settings import BATCH_ROWS
from daa_sil.errors import UsageError

#: encounter rows per task by default: the five paper groups of one 2,000-encounter chunk (results do
#: not depend on it; larger tasks gain little and lose more on a kill)
DEFAULT_BATCH_ROWS = BATCH_ROWS.default


def plan_batches(units: Sequence[tuple], workers: int, batch_rows: int = DEFAULT_BATCH_ROWS,
                 min_tasks: int = 1) -> list[list[tuple]]:
    """Tasks (lists of units) for ``units`` = ``[(group, chunk, rows), ...]`` in (chunk, group) order.

    Every unit is in exactly one task, whole (a unit's rows are never split).
    """
    if not isinstance(batch_rows, int) or isinstance(batch_rows, bool):
        raise UsageError(f"--batch-rows must be an integer, got {batch_rows!r}")
    BATCH_ROWS.check(batch_rows, key="--batch-rows")
    units = list(units)
    if not units:
        return []
    total = sum(u[2] for u in units)
    workers = max(int(workers), 1)
    n_tasks = workers * math.ceil(total / (workers * batch_rows))
    n_tasks = min(max(n_tasks, min_tasks), len(units))
    return [units[a:b] for a, b in zip(*_contiguous_bounds([u[2] for u in units], n_tasks))]


def _contiguous_bounds(rows: Sequence[int], n_tasks: int) -> tuple[list[int], list[int]]:
    """``(starts, ends)`` of ``n_tasks`` non-empty contiguous runs of ``rows`` (``n_tasks <= len(rows)``):
    each cut at the unit boundary nearest to its share ``k / n_tasks`` of the rows, kept so that every
    run has at least one unit."""
    cum = [0]
    for r in rows:
        cum.append(cum[-1] + r)
    total, n = cum[-1], len(rows)
    scaled = [c * n_tasks for c in cum]
    cuts = [0]
    for k in range(1, n_tasks):
        lo, hi = cuts[-1] + 1, n - (n_tasks - k)
        # the boundary b with cum[b] * n_tasks nearest to k * total (integers: no rounding), the first on ties
        b = bisect.bisect_left(scaled, k * total)
        best = min((c for c in (b - 1, b) if 0 <= c <= n), key=lambda c: (abs(scaled[c] - k * total), c))
        cuts.append(max(lo, min(hi, best)))
    return cuts, cuts[1:] + [n]


__all__ = ["plan_batches", "DEFAULT_BATCH_ROWS"]
