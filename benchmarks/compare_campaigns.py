"""Compare the result tables of two campaign directories column by column.

Used to show that a refactoring left a campaign's numbers unchanged: for every group present in
both directories, the per-encounter and per-decision tables (all chunks, in encounter order) and
the shared encounter set ``encounters.parquet`` must have the same columns with identical values
(floats compared bit for bit, NaN equal to NaN). ``campaign.json`` is metadata and is only
reported (its configuration record may legitimately grow).

    python benchmarks/compare_campaigns.py /tmp/arch-before /tmp/arch-after

Prints one line per table and a final ``identical: yes|no`` figure line; exit status 0 when every
data column is identical, 1 otherwise.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq


def read_table(paths: list[Path]) -> pa.Table:
    return pa.concat_tables([pq.read_table(p) for p in sorted(paths)])


def column_equal(a: pa.ChunkedArray, b: pa.ChunkedArray) -> bool:
    """Exact equality of two columns (NaN == NaN, lists element by element)."""
    if a.type != b.type or len(a) != len(b):
        return False
    la, lb = a.to_pylist(), b.to_pylist()
    if pa.types.is_floating(a.type):
        x = np.asarray(a.to_numpy(zero_copy_only=False), dtype=float)
        y = np.asarray(b.to_numpy(zero_copy_only=False), dtype=float)
        return bool(np.array_equal(x, y, equal_nan=True))
    return all(_same(u, v) for u, v in zip(la, lb))


def _same(u, v) -> bool:
    if isinstance(u, float) and isinstance(v, float):
        return (u == v) or (u != u and v != v)
    if isinstance(u, list) and isinstance(v, list):
        return len(u) == len(v) and all(_same(p, q) for p, q in zip(u, v))
    return u == v


def compare_tables(name: str, a: pa.Table, b: pa.Table) -> list[str]:
    """Differences between two tables (empty = identical data columns)."""
    diffs = []
    if a.num_rows != b.num_rows:
        diffs.append(f"{name}: {a.num_rows} rows vs {b.num_rows}")
    ca, cb = set(a.column_names), set(b.column_names)
    for c in sorted(ca ^ cb):
        diffs.append(f"{name}: column {c!r} only in {'A' if c in ca else 'B'}")
    if a.num_rows == b.num_rows:
        for c in a.column_names:
            if c in cb and not column_equal(a.column(c), b.column(c)):
                diffs.append(f"{name}: column {c!r} differs")
    return diffs


def compare_dirs(dir_a: Path, dir_b: Path) -> tuple[list[str], int]:
    """(differences, number of columns compared) between two campaign directories."""
    diffs, n_cols = [], 0
    groups_a = {p.name for p in dir_a.iterdir() if p.is_dir()}
    groups_b = {p.name for p in dir_b.iterdir() if p.is_dir()}
    for g in sorted(groups_a ^ groups_b):
        diffs.append(f"group {g} only in {'A' if g in groups_a else 'B'}")
    pairs = [("encounters.parquet", [dir_a / "encounters.parquet"], [dir_b / "encounters.parquet"])]
    for g in sorted(groups_a & groups_b):
        for kind in ("encounters", "decisions"):
            pairs.append((f"{g}/{kind}", list((dir_a / g).glob(f"{kind}-*.parquet")),
                          list((dir_b / g).glob(f"{kind}-*.parquet"))))
    for name, pa_, pb_ in pairs:
        if not pa_ or not pb_:
            diffs.append(f"{name}: missing in {'A' if not pa_ else 'B'}")
            continue
        ta, tb = read_table(pa_), read_table(pb_)
        d = compare_tables(name, ta, tb)
        n_cols += ta.num_columns
        print(f"{name}: {ta.num_rows} rows x {ta.num_columns} columns: {'identical' if not d else 'DIFFERENT'}")
        diffs += d
    return diffs, n_cols


def main(argv: "list[str] | None" = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dir_a", type=Path)
    ap.add_argument("dir_b", type=Path)
    args = ap.parse_args(argv)
    diffs, n_cols = compare_dirs(args.dir_a, args.dir_b)
    for d in diffs:
        print("  " + d)
    print(f"identical: {'yes' if not diffs else 'no'} ({n_cols} columns compared, {len(diffs)} differences)")
    return 0 if not diffs else 1


if __name__ == "__main__":
    sys.exit(main())
