"""The step log: one row per encounter per step (``docs/architecture.md`` "Step log schema").

Used by fast-time (``record_steps=True``) and by the SIL vehicle, so both produce the same table.

* :data:`STEP_SCHEMA` -- the pyarrow schema (SI units; angles in degrees, compass).
* :class:`StepLogBuilder` -- columnar accumulation of per-step column dicts (one numpy array per
  column with a leading encounter axis ``(N,)``; per-intruder columns ``(N, M)``; band columns padded
  ``(N, B)`` plus a count ``(N,)``; string columns as integer codes into the vocabularies below or
  as string arrays). No per-row Python objects: :meth:`StepLogBuilder.finish` stacks the steps and
  builds Arrow arrays with offsets.
* :func:`write_steplog` (atomic Parquet) and :func:`read_steplog` (schema check, one-line
  :class:`~daa_sil.errors.FileFormatError`).

Rows are ordered by ``(encounter_id, step)``. Missing values are ``nan`` / empty lists.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Mapping

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from daa_sil.daa.config import AXIS_NAMES, DIR_NAMES, REGION_NAMES, RULE_NAMES
from daa_sil.agent.decision import AUTHORITY_NAMES, DECIDED_BY_NAMES, DECISION_NAMES

from .errors import FileFormatError, UsageError
from .files import atomic_path, local_file

#: schema version stored in the file metadata under ``daa_sil.steplog``
STEPLOG_VERSION = "2"

# vocabularies of the string columns (integer codes index these tuples): the agent's and the DAA's code
# names (daa_sil.agent.decision.CODE_NAMES, daa_sil.daa.config), defined there once
DECISIONS = DECISION_NAMES
RULES = RULE_NAMES
AUTHORITIES = AUTHORITY_NAMES
AXES = AXIS_NAMES
DIRECTIONS = DIR_NAMES
REGIONS = REGION_NAMES
DECIDED_BY = DECIDED_BY_NAMES

#: values renamed since bba2fd8, applied when a step log (or a campaign table) is read: column -> {old: new}.
#: The waiting authority was ``hold``, the same word as the pilot's "hold the current course" command
#: kind (``gcs_commands.jsonl`` ``kind``); it is ``waiting`` now. The wire code (2) is unchanged.
RENAMED: dict[str, dict[str, str]] = {"authority": {"hold": "waiting"}}

#: vocabulary of every string column (scalar or list)
VOCAB: dict[str, tuple[str, ...]] = {
    "decision": DECISIONS, "rule": RULES, "authority": AUTHORITIES,
    "pilot_axis": AXES, "exec_axis": AXES, "pilot_dir": DIRECTIONS, "exec_dir": DIRECTIONS,
    "bands_trk_region": REGIONS, "decided_by": DECIDED_BY,
}

_F, _B, _S = pa.float64(), pa.bool_(), pa.string()

#: per-intruder list columns (length M) and their value types
INTRUDER_COLUMNS: dict[str, pa.DataType] = {
    "intr_x": _F, "intr_y": _F, "intr_z": _F, "intr_gs": _F, "intr_trk_deg": _F, "intr_vs": _F,
    "range_m": _F, "hmd_m": _F, "dh_m": _F, "tau_mod_s": _F, "alert_level": pa.int8(), "wcv": _B,
    "intr_turn_est_dps": _F,
}
#: variable-length band list columns (padded ``(N, B)`` + ``bands_count`` in a step dict)
BAND_COLUMNS: dict[str, pa.DataType] = {"bands_trk_lo_deg": _F, "bands_trk_hi_deg": _F, "bands_trk_region": _S}

STEP_SCHEMA = pa.schema(
    [("encounter_id", pa.int64()), ("step", pa.int32()), ("t", _F),
     ("own_x", _F), ("own_y", _F), ("own_z", _F), ("own_gs", _F), ("own_trk_deg", _F), ("own_vs", _F)]
    + [(k, pa.list_(v)) for k, v in INTRUDER_COLUMNS.items()]
    + [("decision", _S), ("rule", _S), ("authority", _S), ("wait_s", _F), ("projl", _B), ("decided_by", _S),
       ("wait_p_lowc", _F), ("wait_in_box", _B), ("wait_map_turn_dps", _F),
       ("pilot_cmd_received", _B), ("pilot_cmd_age_s", _F), ("sm_pilot", _F), ("sm_exec", _F),
       ("cmd_trk_deg", _F), ("cmd_vs", _F), ("cmd_gs", _F),
       ("pilot_trk_deg", _F), ("pilot_vs", _F), ("pilot_gs", _F),
       ("daa_trk_deg", _F), ("daa_vs", _F), ("daa_gs", _F),
       ("pilot_axis", _S), ("pilot_dir", _S), ("exec_axis", _S), ("exec_dir", _S),
       ("delay_up_s", _F), ("delay_down_s", _F), ("lowc", _B), ("nmac", _B)]
    + [(k, pa.list_(v)) for k, v in BAND_COLUMNS.items()],
    metadata={b"daa_sil.steplog": STEPLOG_VERSION.encode()},
)

#: every column name in schema order
STEP_COLUMNS: tuple[str, ...] = tuple(STEP_SCHEMA.names)
_SCALAR_COLUMNS = tuple(c for c in STEP_COLUMNS if c not in INTRUDER_COLUMNS and c not in BAND_COLUMNS)


def _np_dtype(t: pa.DataType):
    if t == pa.string():
        return None
    return t.to_pandas_dtype()


def _string_array(values: np.ndarray, vocab: "tuple[str, ...] | None") -> pa.Array:
    """Strings from integer codes (vectorised through a dictionary array) or from a str array."""
    values = np.asarray(values)
    if values.dtype.kind in "iu":
        if vocab is None:
            raise UsageError("integer codes given for a string column without a vocabulary")
        codes = values.astype(np.int32, copy=False)
        if codes.size and (codes.min() < 0 or codes.max() >= len(vocab)):
            raise UsageError(f"string code out of range 0..{len(vocab) - 1}")
        return pa.DictionaryArray.from_arrays(pa.array(codes), pa.array(list(vocab), _S)).cast(_S)
    return pa.array(values.astype(str), _S)


class StepLogBuilder:
    """Accumulate step columns for N encounters with M intruders; :meth:`finish` -> ``pa.Table``.

    ``append(cols)`` takes a dict with every scalar column as an ``(N,)`` array (``encounter_id``
    may be omitted: it is filled from ``encounter_ids``), every :data:`INTRUDER_COLUMNS` entry as
    ``(N, M)``, and the :data:`BAND_COLUMNS` entries padded to ``(N, B)`` with ``bands_count`` (N,)
    the number of valid bands per row. Missing scalar float columns may be omitted (nan).
    """

    def __init__(self, encounter_ids: np.ndarray, n_intruders: int):
        self.encounter_ids = np.asarray(encounter_ids, dtype=np.int64)
        self.n = self.encounter_ids.size
        self.m = int(n_intruders)
        self._steps: list[dict[str, np.ndarray]] = []

    def __len__(self) -> int:
        """Number of steps appended."""
        return len(self._steps)

    def append(self, cols: Mapping[str, np.ndarray]) -> None:
        """Add one step's columns (arrays are copied, so callers may reuse buffers)."""
        n, m = self.n, self.m
        rec: dict[str, np.ndarray] = {}
        for name in _SCALAR_COLUMNS:
            if name == "encounter_id":
                continue
            if name not in cols:
                typ = STEP_SCHEMA.field(name).type
                if typ == _F:
                    rec[name] = np.full(n, np.nan)
                    continue
                raise UsageError(f"step log column {name!r} is missing")
            a = np.asarray(cols[name])
            rec[name] = np.array(np.broadcast_to(a, (n,)))
        for name in INTRUDER_COLUMNS:
            if name not in cols:
                raise UsageError(f"step log column {name!r} is missing")
            a = np.asarray(cols[name])
            if a.shape != (n, m):
                raise UsageError(f"step log column {name!r} has shape {a.shape}, expected {(n, m)}")
            rec[name] = a.copy()
        count = np.asarray(cols.get("bands_count", np.zeros(n, np.int64)), dtype=np.int64)
        rec["bands_count"] = np.array(np.broadcast_to(count, (n,)))
        width = None
        for name in BAND_COLUMNS:
            a = np.asarray(cols.get(name, np.zeros((n, 0))))
            if a.ndim != 2 or a.shape[0] != n or (width is not None and a.shape[1] != width):
                raise UsageError(f"step log band column {name!r} has shape {a.shape}, expected (N, B)")
            width = a.shape[1]
            rec[name] = a.copy()
        if count.size and count.max(initial=0) > (width or 0):
            raise UsageError("bands_count exceeds the padded band width")
        self._steps.append(rec)

    def finish(self) -> pa.Table:
        """The step log as a table with :data:`STEP_SCHEMA`, rows ordered by (encounter, step)."""
        k, n, m = len(self._steps), self.n, self.m
        arrays = []
        for f in STEP_SCHEMA:
            name = f.name
            if name == "encounter_id":
                arrays.append(pa.array(np.tile(self.encounter_ids, k), pa.int64()))
            elif name in INTRUDER_COLUMNS:
                vals = np.stack([s[name] for s in self._steps]).ravel() if k else np.zeros(0)
                vt = f.type.value_type
                offsets = pa.array(np.arange(k * n + 1, dtype=np.int32) * m)
                arrays.append(pa.ListArray.from_arrays(offsets, _values(vals, vt, VOCAB.get(name)), type=f.type))
            elif name in BAND_COLUMNS:
                if k == 0:
                    arrays.append(pa.array([], f.type))
                    continue
                flat, counts = [], []
                for s in self._steps:
                    a, c = s[name], s["bands_count"]
                    flat.append(a[np.arange(a.shape[1])[None, :] < c[:, None]])
                    counts.append(c)
                offsets = pa.array(np.concatenate([[0], np.cumsum(np.concatenate(counts))]).astype(np.int32))
                arrays.append(pa.ListArray.from_arrays(offsets, _values(np.concatenate(flat), f.type.value_type,
                                                                        VOCAB.get(name)), type=f.type))
            else:
                vals = np.concatenate([s[name] for s in self._steps]) if k else np.zeros(0)
                arrays.append(_values(vals, f.type, VOCAB.get(name)))
        table = pa.Table.from_arrays(arrays, schema=STEP_SCHEMA)
        # step-major rows (k, n) -> encounter-major order
        return table.take(pa.array(np.arange(k * n).reshape(k, n).T.ravel()))


def step_row(cols: Mapping[str, np.ndarray], i: int = 0, encounter_id: int = 0) -> dict:
    """Row ``i`` of one step's columns (as :meth:`StepLogBuilder.append` takes them, e.g.
    :func:`daa_sil.onboard.step_columns`) as plain Python values, one per :data:`STEP_COLUMNS`: numbers,
    bools, names for the coded string columns, lists for the per-intruder and band columns (the bands
    cut to ``bands_count``). A float column that is missing is nan. The SIL vehicle keeps its step log as
    these rows, and sends them to the live viewer."""
    row: dict = {}
    for f in STEP_SCHEMA:
        name, typ = f.name, f.type
        if name == "encounter_id":
            row[name] = int(encounter_id)
            continue
        if name in BAND_COLUMNS:
            continue
        if name not in cols:
            if typ != _F:
                raise UsageError(f"step log column {name!r} is missing")
            row[name] = float("nan")
            continue
        a = np.asarray(cols[name])
        if name in INTRUDER_COLUMNS:
            row[name] = _plain_list(a[i], typ.value_type, VOCAB.get(name))
            continue
        v = a[i] if a.ndim else a
        row[name] = _plain_list(np.asarray(v).reshape(1), typ, VOCAB.get(name))[0]
    row.update(band_row(cols, i))
    return row


def band_row(cols: Mapping[str, np.ndarray], i: int = 0) -> dict:
    """The :data:`BAND_COLUMNS` of row ``i`` (padded ``(N, B)`` with ``bands_count``, as
    :func:`daa_sil.onboard.band_intervals` gives them) as lists cut to the row's count, regions named;
    empty lists without bands."""
    counts = np.asarray(cols.get("bands_count", 0))
    count = int(counts[i] if counts.ndim else counts)
    return {name: _plain_list(np.asarray(cols[name])[i, :count] if count else np.zeros(0), typ,
                              VOCAB.get(name))
            for name, typ in BAND_COLUMNS.items()}


def _plain_list(vals: np.ndarray, typ: pa.DataType, vocab: "tuple[str, ...] | None") -> list:
    """``vals`` as a list of Python values of column type ``typ`` (codes named through ``vocab``)."""
    vals = np.asarray(vals)
    if typ == _S:
        if vals.dtype.kind in "iu":
            return [vocab[int(c)] for c in vals.tolist()]
        return [str(v) for v in vals.tolist()]
    return vals.astype(_np_dtype(typ)).tolist()


def _values(vals: np.ndarray, typ: pa.DataType, vocab: "tuple[str, ...] | None") -> pa.Array:
    if typ == _S:
        return _string_array(vals, vocab)
    return pa.array(np.asarray(vals).astype(_np_dtype(typ)), typ)


def concat_steplogs(tables: "list[pa.Table]") -> pa.Table:
    """Concatenate step logs (e.g. of several chunks) keeping the schema."""
    if not tables:
        return STEP_SCHEMA.empty_table()
    return pa.concat_tables([t.cast(STEP_SCHEMA) for t in tables])


def write_steplog(table: pa.Table, path: "str | os.PathLike", metadata: "Mapping[str, str] | None" = None,
                  overwrite: bool = True) -> Path:
    """Write a step log as Parquet atomically; ``metadata`` (e.g. ``{"preset": "paper"}``) is stored
    in the file's key-value metadata next to the schema version."""
    check_steplog_schema(table.schema, str(path))
    meta = dict(STEP_SCHEMA.metadata)
    for k, v in (metadata or {}).items():
        meta[str(k).encode()] = str(v).encode()
    table = table.replace_schema_metadata(meta)
    with atomic_path(path, overwrite=overwrite) as tmp, local_file(tmp, "wb") as fh:
        pq.write_table(table, fh, compression="zstd")
    return Path(path)


def check_steplog_schema(schema: pa.Schema, where: str = "step log") -> None:
    """Raise FileFormatError naming the first missing or mistyped column."""
    for f in STEP_SCHEMA:
        idx = schema.get_field_index(f.name)
        if idx < 0:
            raise FileFormatError(f"{where}: not a daa-sil step log, column {f.name!r} is missing")
        got = schema.field(idx).type
        if got != f.type:
            raise FileFormatError(f"{where}: column {f.name!r} has type {got}, expected {f.type}")


def read_steplog(path: "str | os.PathLike") -> pa.Table:
    """Read a step log written by :func:`write_steplog` and check its schema and version."""
    p = Path(path)
    try:
        src = local_file(p)
    except FileNotFoundError:
        raise FileFormatError(f"step log {p} does not exist") from None
    except (OSError, pa.ArrowException) as exc:
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise FileFormatError(f"step log {p} is not a readable Parquet file: {msg}") from None
    with src:
        return _read_open(src, p)


def _read_open(src, p: Path) -> pa.Table:
    try:
        pf = pq.ParquetFile(src)
    except (OSError, pa.ArrowException) as exc:
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise FileFormatError(f"step log {p} is not a readable Parquet file: {msg}") from None
    schema = pf.schema_arrow
    version = (schema.metadata or {}).get(b"daa_sil.steplog")
    if version is None:
        check_steplog_schema(schema, str(p))  # names the missing column if it is another table
        raise FileFormatError(f"step log {p} has no daa_sil.steplog version in its metadata")
    if version.decode() != STEPLOG_VERSION:
        raise FileFormatError(f"step log {p} has version {version.decode()}, this daa-sil reads {STEPLOG_VERSION}")
    check_steplog_schema(schema, str(p))
    try:
        table = pf.read()
    except (OSError, pa.ArrowException) as exc:
        raise FileFormatError(f"step log {p} is corrupt: {str(exc).splitlines()[0]}") from None
    return rename_legacy(table)


def rename_legacy(table: pa.Table) -> pa.Table:
    """``table`` with the old names of :data:`RENAMED` replaced by the new ones (scalar string
    columns; other columns and the schema metadata untouched). A table without old names is returned as is."""
    import pyarrow.compute as pc  # lazy: start-up time

    for col, mapping in RENAMED.items():
        i = table.schema.get_field_index(col)
        if i < 0 or table.schema.field(i).type != _S:
            continue
        arr = table.column(i)
        for old, new in mapping.items():
            hit = pc.equal(arr, old)
            if pc.any(hit).as_py():
                arr = pc.if_else(hit, new, arr)
                table = table.set_column(i, table.schema.field(i), arr)
    return table


def steplog_metadata(table_or_path: "pa.Table | str | os.PathLike") -> dict[str, str]:
    """The file's key-value metadata as ``str -> str``."""
    if isinstance(table_or_path, pa.Table):
        meta = table_or_path.schema.metadata or {}
    else:
        with local_file(table_or_path) as fh:
            meta = pq.read_schema(fh).metadata or {}
    return {k.decode(): v.decode() for k, v in meta.items()}


def cells_equal(a, b) -> bool:
    """Step-log cells ``a`` and ``b`` (Python values from ``to_pylist``) are the same: lists
    element-wise, floats exactly, NaN equal to NaN (an absent value in both logs)."""
    if isinstance(a, list):
        return isinstance(b, list) and len(a) == len(b) and all(cells_equal(x, y) for x, y in zip(a, b))
    if isinstance(a, float) and isinstance(b, float):
        return (np.isnan(a) and np.isnan(b)) or a == b
    return a == b


__all__ = ["cells_equal", "step_row", "band_row", "STEP_SCHEMA", "STEP_COLUMNS", "STEPLOG_VERSION", "INTRUDER_COLUMNS", "BAND_COLUMNS", "VOCAB",
           "DECISIONS", "RULES", "AUTHORITIES", "AXES", "DIRECTIONS", "REGIONS", "StepLogBuilder",
           "concat_steplogs", "write_steplog", "read_steplog", "check_steplog_schema", "steplog_metadata", "RENAMED",
           "rename_legacy"]
