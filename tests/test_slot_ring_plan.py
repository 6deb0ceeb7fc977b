"""The slot ring of fast-time's links and the campaign's batch plan (issue 21)."""

from __future__ import annotations

import numpy as np
import pytest

from daa_sil.errors import UsageError
from daa_sil.study.campaign.plan import plan_batches
from daa_sil.study.simulation.slot_ring import SlotRing


def test_ring_holds_what_is_still_read_and_grows_when_a_reader_lags():
    ring = SlotRing(3, {"v": ((), float, np.nan), "p": ((2,), np.int64, -1)}, capacity=4)
    for k in range(10):
        slot = ring.open(k)
        assert np.isnan(slot["v"]).all() and (slot["p"] == -1).all()  # a reused slot starts at its fill
        slot["v"][:] = k + np.arange(3) / 10
        slot["p"][:] = k
        ring.release(k - 2 if k < 6 else 3)  # from k = 6 on the reader lags at slot 3: the ring must grow
    assert ring.capacity >= 7
    got = ring.gather("v", np.array([3, 9, -1]))
    assert got[0] == pytest.approx(3.0) and got[1] == pytest.approx(9.1) and np.isnan(got[2])
    assert ring.gather("p", np.array([5, 5]), rows=np.array([2, 0])).tolist() == [[5, 5], [5, 5]]
    assert ring.gather("p", np.array([-1, 4, 8])).tolist() == [[-1, -1], [4, 4], [8, 8]]
    with pytest.raises(ValueError):
        ring.open(12)
    with pytest.raises(IndexError):
        ring.slot(1)


def test_gather_reads_each_rows_own_slot_element_by_element():
    """Every (slot, row, component) holds a distinct value; gather of any slots for any rows (also a
    subset in another order, and slot -1) equals reading them one element at a time, before and after
    the ring grew."""
    n = 7
    ring = SlotRing(n, {"m": ((2, 3), float, np.nan), "i": ((), np.int64, -5)}, capacity=2)
    rng = np.random.default_rng(3)
    kept = {}
    for k in range(12):
        slot = ring.open(k)
        slot["m"][:] = k * 1000 + np.arange(n)[:, None, None] * 10 + np.arange(6).reshape(2, 3)
        slot["i"][:] = k * 100 + np.arange(n)
        kept[k] = {f: v.copy() for f, v in slot.items()}
        ring.release(max(0, k - (1 if k < 6 else 8)))  # lagging from k = 6: the ring grows
        for rows in (None, rng.permutation(n)[:4]):
            r = np.arange(n) if rows is None else rows
            idx = rng.integers(ring.oldest, k + 1, r.size)
            idx[0] = -1
            for f, fill in (("m", np.nan), ("i", -5)):
                got = ring.gather(f, idx, rows=rows)
                want = np.stack([np.full_like(kept[k][f][0], fill) if j < 0 else kept[j][f][row]
                                 for j, row in zip(idx, r)])
                np.testing.assert_array_equal(got, want)
    assert ring.capacity > 2
    empty = SlotRing(3, {"intr": ((0, 6), float, np.nan)})  # no intruder fields at all: still (N, 0, 6)
    empty.open(0)
    assert empty.gather("intr", np.array([0, -1, 0])).shape == (3, 0, 6)


def test_ring_memory_does_not_grow_with_the_number_of_steps():
    ring = SlotRing(5, {"v": ((), float, 0.0)}, capacity=8)
    for k in range(1000):
        ring.open(k)
        ring.release(k - 5)
    assert ring.capacity == 8


def _units(n_chunks, groups, rows):
    return [(g, c, rows) for c in range(n_chunks) for g in groups]


def test_plan_uses_every_unit_once_and_balances_the_workers():
    units = _units(5, ["B-1", "B-2", "IC-1", "ID-1", "ID-2"], 2000)
    tasks = plan_batches(units, workers=2, batch_rows=26_000)  # two tasks of about 25,000 rows
    assert sorted(u for t in tasks for u in t) == sorted(units)
    assert len(tasks) == 2
    loads = [sum(u[2] for u in t) for t in tasks]
    assert max(loads) - min(loads) <= 2000  # one unit apart at most
    for t in tasks:  # every task holds every group
        assert {u[0] for u in t} == {"B-1", "B-2", "IC-1", "ID-1", "ID-2"}


def test_plan_keeps_the_groups_of_a_chunk_together():
    """A task is a contiguous run of units in (chunk, group) order: it spans at most two chunks (whose
    parts then share their streams and delay tables), still holds four or five groups, and the tasks
    stay within one unit of each other."""
    groups = ["B-1", "B-2", "IC-1", "ID-1", "ID-2"]
    units = _units(5, groups, 2000)
    tasks = plan_batches(units, workers=2, batch_rows=10_000, min_tasks=4)
    assert len(tasks) == 6 and [u for t in tasks for u in t] == units  # every unit once, in order
    for t in tasks:
        assert len({c for _, c, _ in t}) <= 2 and len({g for g, _, _ in t}) >= 4
    loads = [sum(u[2] for u in t) for t in tasks]
    assert max(loads) - min(loads) <= 2000


def test_plan_of_unequal_units_keeps_its_task_count_and_balance():
    """Units of different sizes (a last, smaller chunk; a resume with some units done) still give the
    planned number of non-empty tasks, every unit once and in order, no task more than one unit over
    an equal share. (Assigning each unit by the position of its first row left tasks empty here: 3,001
    encounters in chunks of 2,000, four groups, four workers gave 7 tasks, one of them two units.)"""
    units = [(g, 0, 2000) for g in ("B-1", "B-2", "IC-1", "ID-1")] + [(g, 1, 1001) for g in ("B-1", "B-2", "IC-1", "ID-1")]
    tasks = plan_batches(units, workers=4, min_tasks=8)
    assert [len(t) for t in tasks] == [1] * 8
    rng = np.random.default_rng(5)
    for _ in range(300):
        rows = [int(r) for r in rng.choice([1, 7, 1001, 2000], size=int(rng.integers(1, 40)))]
        us = [(f"G{i % 5}", i // 5, r) for i, r in enumerate(rows)]
        workers, min_tasks, batch = int(rng.integers(1, 9)), int(rng.integers(1, 20)), int(rng.choice([500, 4000, 10_000]))
        tasks = plan_batches(us, workers=workers, batch_rows=batch, min_tasks=min_tasks)
        want = min(max(workers * -(-sum(rows) // (workers * batch)), min_tasks), len(us))
        assert len(tasks) == want and all(tasks)
        assert [u for t in tasks for u in t] == us
        assert max(sum(u[2] for u in t) for t in tasks) <= sum(rows) / want + max(rows)


def test_plan_bounds_rows_per_task_and_keeps_a_multiple_of_the_workers():
    units = _units(10, ["B-1", "ID-2"], 1000)
    tasks = plan_batches(units, workers=2, batch_rows=5000)
    assert len(tasks) % 2 == 0 and max(sum(u[2] for u in t) for t in tasks) <= 5000
    assert len(plan_batches(units, workers=1, batch_rows=10**6, min_tasks=4)) == 4
    assert len(plan_batches(units[:3], workers=8)) == 3  # never more tasks than units
    assert plan_batches([], workers=2) == []
    for bad in (0, -1, 2.5, True):
        with pytest.raises(UsageError, match="--batch-rows"):
            plan_batches(units, workers=2, batch_rows=bad)
