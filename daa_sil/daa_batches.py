"""DAA batches: which encounters of a fast-time batch may share one call of the DAA.

The DAA's numbers for one encounter depend, in their last bits, on the other encounters of the same
call: the safety metric flies every command on the batch's common knot grid and bisects to the
batch's depth (:mod:`daa_sil.daa.safety`, :mod:`daa_sil.daa.undecided`), and the speed axes have
the batch's number of candidates. A fast-time batch that holds several chunks or groups side by
side (:func:`daa_sil.study.fasttime.simulate_parts`) therefore calls the DAA once per *DAA batch*
(one chunk of one group), on exactly the rows that chunk run alone would pass, in the same order,
so that its results are bit for bit those of the chunks run one by one. Everything else in a step
is element-wise per encounter and runs on the whole batch.

``batch_of`` is an ``(N,)`` int array (the DAA batch of each row) or None (one batch).
"""

from __future__ import annotations

import numpy as np


def positions_by_batch(batch_of: "np.ndarray | None", rows: np.ndarray) -> list[np.ndarray]:
    """Positions into ``rows`` (ascending row indices) grouped by DAA batch, in batch order; an
    empty list when ``rows`` is empty."""
    rows = np.asarray(rows)
    if rows.size == 0:
        return []
    if batch_of is None:
        return [np.arange(rows.size)]
    b = np.asarray(batch_of)[rows]
    if b[0] == b[-1] and np.all(b == b[0]):
        return [np.arange(rows.size)]
    return [np.flatnonzero(b == v) for v in np.unique(b)]


def check_batches(batch_of: "np.ndarray | None", n: int) -> "np.ndarray | None":
    """``batch_of`` as an ``(n,)`` int64 array (None stays None); ValueError on a wrong shape."""
    if batch_of is None:
        return None
    arr = np.asarray(batch_of, np.int64)
    if arr.shape != (n,):
        raise ValueError(f"daa_batches must have shape ({n},), got {arr.shape}")
    return arr


__all__ = ["positions_by_batch", "check_batches"]
