"""Compare the result tables of two campaign directories (or two SIL step logs) column by column.

Used to show that a change left a campaign's numbers unchanged: for every group present in both
directories, the per-encounter and per-decision tables (all chunks, in encounter order) and the
shared encounter set ``encounters.parquet`` must have the same columns with identical values
(floats compared bit for bit, NaN equal to NaN). ``campaign.json`` is metadata and is only
reported (its configuration record may legitimately grow).

The same for SIL step logs: A and B may be two ``steplog.parquet`` files, two ``daa-sil run``
output directories (each holding ``steplog.parquet``), or two directories of such run directories
(e.g. one run per scenario: every name present in both is compared). Step-log metadata is not
compared.

    python benchmarks/compare_campaigns.py /tmp/arch-before /tmp/arch-after
    python benchmarks/compare_campaigns.py /work/ref/sil runs/sil-after

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

from daa_sil.steplog import RENAMED, rename_legacy

STEPLOG = "steplog.parquet"
RENAMED_HELP = "; ".join(f"column {col!r}: " + ", ".join(f"{old!r} -> {new!r}" for old, new in m.items())
                         for col, m in RENAMED.items())
EPILOG = f"""values renamed since older runs (applied to both sides when reading, so runs written by
bba2fd8 compare with newer ones): {RENAMED_HELP} (daa_sil.steplog.RENAMED).

examples:
  python benchmarks/compare_campaigns.py /tmp/arch-before /tmp/arch-after
  python benchmarks/compare_campaigns.py /work/ref/sil/head_on/steplog.parquet runs/head_on/steplog.parquet
  python benchmarks/compare_campaigns.py /work/ref/sil runs/sil-after
"""


def read_table(paths: list[Path]) -> pa.Table:
    """The chunks ``paths`` (in name order) as one table, old names renamed (``RENAMED``)."""
    return rename_legacy(pa.concat_tables([pq.read_table(p) for p in sorted(paths)]))


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


def _steplog_pairs(dir_a: Path, dir_b: Path) -> "list[tuple[str, list[Path], list[Path]]] | None":
    """Step-log pairs if A and B are step logs, run directories or directories of runs; else None."""
    if dir_a.is_file() or dir_b.is_file():
        return [(STEPLOG, [dir_a], [dir_b])]
    if (dir_a / STEPLOG).is_file() or (dir_b / STEPLOG).is_file():
        return [(STEPLOG, [dir_a / STEPLOG], [dir_b / STEPLOG])]
    runs_a = {p.parent.name for p in dir_a.glob(f"*/{STEPLOG}")}
    runs_b = {p.parent.name for p in dir_b.glob(f"*/{STEPLOG}")}
    if not (runs_a or runs_b):
        return None
    pairs = [(f"{r}/{STEPLOG}", [dir_a / r / STEPLOG] if r in runs_a else [], [dir_b / r / STEPLOG] if r in runs_b else [])
             for r in sorted(runs_a | runs_b)]
    return pairs


def _campaign_pairs(dir_a: Path, dir_b: Path) -> "tuple[list, list[str]]":
    diffs = []
    groups_a = {p.name for p in dir_a.iterdir() if p.is_dir()}
    groups_b = {p.name for p in dir_b.iterdir() if p.is_dir()}
    for g in sorted(groups_a ^ groups_b):
        diffs.append(f"group {g} only in {'A' if g in groups_a else 'B'}")
    pairs = [("encounters.parquet", [dir_a / "encounters.parquet"], [dir_b / "encounters.parquet"])]
    for g in sorted(groups_a & groups_b):
        for kind in ("encounters", "decisions"):
            pairs.append((f"{g}/{kind}", list((dir_a / g).glob(f"{kind}-*.parquet")),
                          list((dir_b / g).glob(f"{kind}-*.parquet"))))
    return pairs, diffs


def compare_dirs(dir_a: Path, dir_b: Path) -> tuple[list[str], int]:
    """(differences, number of columns compared) between two campaign directories or step logs."""
    n_cols = 0
    pairs = _steplog_pairs(dir_a, dir_b)
    diffs: list[str] = []
    if pairs is None:
        pairs, diffs = _campaign_pairs(dir_a, dir_b)
    for name, pa_, pb_ in pairs:
        pa_ = [p for p in pa_ if p.is_file()]
        pb_ = [p for p in pb_ if p.is_file()]
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
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0], epilog=EPILOG,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dir_a", type=Path, metavar="A", help="campaign directory, step log, run directory or directory of runs")
    ap.add_argument("dir_b", type=Path, metavar="B", help="the same kind as A")
    args = ap.parse_args(argv)
    for p in (args.dir_a, args.dir_b):
        if not p.exists():
            ap.error(f"{p} does not exist")
    diffs, n_cols = compare_dirs(args.dir_a, args.dir_b)
    for d in diffs:
        print("  " + d)
    print(f"identical: {'yes' if not diffs else 'no'} ({n_cols} columns compared, {len(diffs)} differences)")
    return 0 if not diffs else 1


if __name__ == "__main__":
    sys.exit(main())
