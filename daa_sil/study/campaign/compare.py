"""Are two campaign directories the same results? Column by column, bit for bit.

The one definition of "the same campaign results", used by ``benchmarks/compare_campaigns.py`` (a
speed-up must leave a campaign identical) and by the golden-campaign test: for every group present
in both directories, the per-encounter and per-decision tables (all chunks, in chunk order) and
the shared encounter set ``encounters.parquet`` must have the same columns with identical values
(floats bit for bit, NaN equal to NaN, lists element by element: :func:`daa_sil.steplog.cells_equal`).
``campaign.json`` is metadata and is not compared (its configuration record may legitimately grow).

The same for SIL step logs: A and B may be two ``steplog.parquet`` files, two ``daa-sil run`` output
directories (each holding ``steplog.parquet``), or two directories of such run directories (every
run name present in either is compared). Step-log metadata is not compared. Values renamed since
older runs (:data:`daa_sil.steplog.RENAMED`, e.g. the authority ``hold`` -> ``waiting``) are mapped
on both sides when reading, so runs written before a rename still compare.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from daa_sil.errors import FileFormatError, UsageError
from daa_sil.steplog import cells_equal, rename_legacy

STEPLOG = "steplog.parquet"


def read_table(paths: list[Path]) -> pa.Table:
    """The tables of ``paths`` concatenated in path order (chunk order), old names renamed."""
    try:
        return rename_legacy(pa.concat_tables([pq.read_table(p) for p in sorted(paths)]))
    except (OSError, pa.ArrowException) as exc:
        raise FileFormatError(f"cannot read campaign table: {str(exc).splitlines()[0]}") from None


def column_equal(a: pa.ChunkedArray, b: pa.ChunkedArray) -> bool:
    """Exact equality of two columns (same type and length; NaN == NaN, lists element by element)."""
    if a.type != b.type or len(a) != len(b):
        return False
    if pa.types.is_floating(a.type):
        x = np.asarray(a.to_numpy(zero_copy_only=False), dtype=float)
        y = np.asarray(b.to_numpy(zero_copy_only=False), dtype=float)
        return bool(np.array_equal(x, y, equal_nan=True))
    return all(cells_equal(u, v) for u, v in zip(a.to_pylist(), b.to_pylist()))


def compare_tables(name: str, a: pa.Table, b: pa.Table, added: "list | None" = None) -> list[str]:
    """Differences between two tables (empty = identical data columns). With ``added`` (a list), a
    column only in B is not a difference but is appended there (``name: column``): new columns of a
    newer version, the shared ones still compared bit for bit."""
    diffs = []
    if a.num_rows != b.num_rows:
        diffs.append(f"{name}: {a.num_rows} rows vs {b.num_rows}")
    ca, cb = set(a.column_names), set(b.column_names)
    for c in sorted(ca ^ cb):
        if added is not None and c in cb:
            added.append(f"{name}: {c}")
            continue
        diffs.append(f"{name}: column {c!r} only in {'A' if c in ca else 'B'}")
    if a.num_rows == b.num_rows:
        for c in a.column_names:
            if c in cb and not column_equal(a.column(c), b.column(c)):
                diffs.append(f"{name}: column {c!r} differs")
    return diffs


@dataclass
class Comparison:
    """Outcome of :func:`compare_dirs`: the differences (one line each), the number of columns
    compared and one line per table compared."""

    differences: list = field(default_factory=list)
    columns: int = 0
    tables: list = field(default_factory=list)
    added: list = field(default_factory=list)  #: columns only in B, when they were allowed

    @property
    def identical(self) -> bool:
        return not self.differences


def steplog_pairs(dir_a: Path, dir_b: Path) -> "list[tuple[str, list[Path], list[Path]]] | None":
    """Step-log pairs if A and B are step logs, run directories or directories of runs; else None."""
    if dir_a.is_file() or dir_b.is_file():
        return [(STEPLOG, [dir_a], [dir_b])]
    if (dir_a / STEPLOG).is_file() or (dir_b / STEPLOG).is_file():
        return [(STEPLOG, [dir_a / STEPLOG], [dir_b / STEPLOG])]
    runs_a = {p.parent.name for p in dir_a.glob(f"*/{STEPLOG}")}
    runs_b = {p.parent.name for p in dir_b.glob(f"*/{STEPLOG}")}
    if not (runs_a or runs_b):
        return None
    return [(f"{r}/{STEPLOG}", [dir_a / r / STEPLOG] if r in runs_a else [],
             [dir_b / r / STEPLOG] if r in runs_b else []) for r in sorted(runs_a | runs_b)]


def campaign_pairs(dir_a: Path, dir_b: Path, out: "Comparison") -> "list[tuple[str, list[Path], list[Path]]]":
    """The tables of two campaign directories to compare, pairwise (groups in only one are differences)."""
    groups_a = {p.name for p in dir_a.iterdir() if p.is_dir()}
    groups_b = {p.name for p in dir_b.iterdir() if p.is_dir()}
    for g in sorted(groups_a ^ groups_b):
        out.differences.append(f"group {g} only in {'A' if g in groups_a else 'B'}")
    pairs = [("encounters.parquet", [dir_a / "encounters.parquet"], [dir_b / "encounters.parquet"])]
    for g in sorted(groups_a & groups_b):
        for kind in ("encounters", "decisions"):
            pairs.append((f"{g}/{kind}", list((dir_a / g).glob(f"{kind}-*.parquet")),
                          list((dir_b / g).glob(f"{kind}-*.parquet"))))
    return pairs


def compare_dirs(dir_a: "str | Path", dir_b: "str | Path", on_table: "Callable[[str], None] | None" = None,
                 allow_added: bool = False) -> Comparison:
    """Compare the campaign results (or SIL step logs) in ``dir_a`` and ``dir_b`` (see the module
    docstring); ``on_table`` gets each table's one-line verdict as it is compared. ``allow_added``:
    columns only in B are listed in :attr:`Comparison.added`, not counted as differences."""
    dir_a, dir_b = Path(dir_a), Path(dir_b)
    for d in (dir_a, dir_b):
        if not d.exists():
            raise UsageError(f"{d} does not exist (expected a campaign directory, a step log or run directories)")
    out = Comparison()
    pairs = steplog_pairs(dir_a, dir_b)
    if pairs is None:
        pairs = campaign_pairs(dir_a, dir_b, out)
    for name, pa_, pb_ in pairs:
        pa_ = [p for p in pa_ if p.is_file()]
        pb_ = [p for p in pb_ if p.is_file()]
        if not pa_ or not pb_:
            out.differences.append(f"{name}: missing in {'A' if not pa_ else 'B'}")
            continue
        ta, tb = read_table(pa_), read_table(pb_)
        d = compare_tables(name, ta, tb, out.added if allow_added else None)
        out.columns += ta.num_columns
        line = f"{name}: {ta.num_rows} rows x {ta.num_columns} columns: {'identical' if not d else 'DIFFERENT'}"
        out.tables.append(line)
        if on_table is not None:
            on_table(line)
        out.differences += d
    return out


__all__ = ["compare_dirs", "steplog_pairs", "campaign_pairs", "STEPLOG", "compare_tables", "column_equal", "read_table", "Comparison"]
