"""Step-log rows (dicts or a ``pyarrow`` table) as numpy columns: :class:`StepColumns`."""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np
import pyarrow as pa

from ..steplog import BAND_COLUMNS, INTRUDER_COLUMNS, VOCAB

#: the step log's per-intruder, band and scalar string columns (:mod:`daa_sil.steplog`)
PER_INTRUDER = tuple(INTRUDER_COLUMNS)
BANDS = tuple(BAND_COLUMNS)
STRINGS = tuple(k for k in VOCAB if k not in INTRUDER_COLUMNS and k not in BAND_COLUMNS)


class StepColumns:
    """Step-log rows of one encounter as numpy columns: scalars ``(n,)``, intruders ``(n, M)``, bands ragged."""

    def __init__(self, scalars: dict[str, np.ndarray], intruders: dict[str, np.ndarray],
                 bands: list[list[tuple[float, float, str]]]):
        self.scalars, self.intruders, self.bands = scalars, intruders, bands
        self.n = len(bands)
        self.m = max((a.shape[1] for a in intruders.values()), default=0)

    def f(self, name: str) -> np.ndarray:
        """Float column (nan where missing)."""
        a = self.scalars.get(name)
        if a is None:
            return np.full(self.n, np.nan)
        return np.asarray(a, float)

    def s(self, name: str, default: str = "none") -> list[str]:
        """String column (``default`` where missing)."""
        a = self.scalars.get(name)
        return [default] * self.n if a is None else [default if v is None else str(v) for v in a]

    def b(self, name: str) -> np.ndarray:
        """Bool column (False where missing)."""
        a = self.scalars.get(name)
        return np.zeros(self.n, bool) if a is None else np.array([bool(v) if v is not None else False for v in a])

    def i(self, name: str) -> np.ndarray:
        """Per-intruder float column ``(n, M)`` (nan padded)."""
        a = self.intruders.get(name)
        return np.full((self.n, self.m), np.nan) if a is None else a

    @classmethod
    def from_table(cls, table: "pa.Table | pa.RecordBatch") -> "StepColumns":
        """Columns of a step-log table (rows in step order)."""
        if isinstance(table, pa.RecordBatch):
            table = pa.Table.from_batches([table])
        n = table.num_rows
        scalars: dict[str, np.ndarray] = {}
        intruders: dict[str, np.ndarray] = {}
        for name in table.column_names:
            col = table.column(name).combine_chunks()
            if name in BANDS:
                continue
            if pa.types.is_list(col.type) or pa.types.is_large_list(col.type):
                if name in PER_INTRUDER:
                    intruders[name] = pad_lists(col, n)
                continue
            if pa.types.is_string(col.type) or pa.types.is_large_string(col.type) or pa.types.is_dictionary(col.type):
                scalars[name] = np.array(col.to_pylist(), dtype=object)
            elif pa.types.is_boolean(col.type):
                scalars[name] = np.array(col.fill_null(False).to_numpy(zero_copy_only=False), bool)
            else:
                scalars[name] = np.asarray(col.cast(pa.float64()).fill_null(np.nan).to_numpy(zero_copy_only=False))
        bands = bands_from_lists(*(table.column(b).to_pylist() if b in table.column_names else [[]] * n
                                    for b in BANDS))
        return cls(scalars, intruders, bands)

    @classmethod
    def from_records(cls, records: "list[Mapping[str, Any]]") -> "StepColumns":
        """Columns of step-log row dicts (values: scalars, lists, or N = 1 arrays)."""
        rows = [normalise_row(r) for r in records]
        n = len(rows)
        keys: dict[str, None] = {}
        for r in rows:
            keys.update(dict.fromkeys(r))
        scalars: dict[str, np.ndarray] = {}
        intruders: dict[str, np.ndarray] = {}
        for name in keys:
            if name in BANDS or name == "bands_count":
                continue
            vals = [r.get(name) for r in rows]
            if name in PER_INTRUDER:
                m = max((len(v) for v in vals if v is not None), default=0)
                out = np.full((n, m), np.nan)
                for k, v in enumerate(vals):
                    if v is not None and len(v):
                        out[k, :len(v)] = np.asarray(v, float)
                intruders[name] = out
            elif any(isinstance(v, str) for v in vals):
                scalars[name] = np.array(vals, dtype=object)
            else:
                scalars[name] = np.array([np.nan if v is None else float(v) for v in vals])
        bands = bands_from_lists(*([r.get(b, []) for r in rows] for b in BANDS))
        return cls(scalars, intruders, bands)


def pad_lists(col: pa.Array, n: int) -> np.ndarray:
    """A list column as an ``(n, M)`` float array padded with nan."""
    lens = np.asarray(col.value_lengths().fill_null(0).to_numpy(zero_copy_only=False), np.int64)
    m = int(lens.max(initial=0))
    out = np.full((n, m), np.nan)
    if m == 0:
        return out
    flat = col.flatten()
    vals = np.asarray(flat.cast(pa.float64()).fill_null(np.nan).to_numpy(zero_copy_only=False))
    rows = np.repeat(np.arange(n), lens)
    starts = np.concatenate([[0], np.cumsum(lens)[:-1]])
    cols = np.arange(lens.sum()) - np.repeat(starts, lens)
    out[rows, cols] = vals
    return out


def bands_from_lists(lo, hi, region) -> list[list[tuple[float, float, str]]]:
    """Per row, the bands as ``(lo, hi, region)`` tuples from three list columns (a missing list is no band)."""
    out = []
    for a, b, c in zip(lo, hi, region):
        a, b, c = a or [], b or [], c or []
        out.append([(float(x), float(y), str(z)) for x, y, z in zip(a, b, c)])
    return out


def normalise_row(record: Mapping[str, Any]) -> dict[str, Any]:
    """One row from a dict whose values may be N = 1 arrays (StepLogBuilder step dicts)."""
    out: dict[str, Any] = {}
    count = record.get("bands_count")
    if count is not None:
        count = int(np.asarray(count).reshape(-1)[0])
    for k, v in record.items():
        if isinstance(v, np.ndarray):
            if k in PER_INTRUDER or k in BANDS:
                v = v[0] if v.ndim == 2 else v
                v = v.tolist()
                if k in BANDS and count is not None:
                    v = v[:count]
            else:
                v = v.reshape(-1)[0].item() if v.size else None
        elif isinstance(v, np.generic):
            v = v.item()
        elif isinstance(v, (list, tuple)):
            v = list(v)
        out[k] = v
    return out
