"""Encounter sets on disk: Parquet with the sampler's configuration and seeds in the metadata
(format name and version checked on load)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from daa_sil.config.settings import DURATION
from daa_sil.errors import FileFormatError
from daa_sil.files import atomic_path, local_file
from daa_sil.geometry.kinematics import AircraftState
from daa_sil.models.encounters import SEGMENT_FIELDS, FORMAT_NAME, FORMAT_VERSION, PARAM_NAMES, EncounterSet

_STATE = ("x", "y", "z", "gs", "trk", "vs")


def save_encounters(es: EncounterSet, path: "str | os.PathLike") -> Path:
    """Write ``es`` as one Parquet file (one row per encounter; intruder values as list columns)
    atomically. The schema carries ``format``/``version``/``m``/``s`` metadata checked on load."""
    import pyarrow as pa  # lazy: start-up time
    import pyarrow.parquet as pq  # lazy: start-up time

    n, m = len(es), es.m
    s = es.seg_start_s.shape[-1]

    def lst(a, width):
        flat = np.ascontiguousarray(a, dtype=np.float64).reshape(n * width)
        return pa.ListArray.from_arrays(pa.array(np.arange(0, n * width + 1, width, dtype=np.int32)),
                                        pa.array(flat, type=pa.float64()))

    cols = {"encounter_id": pa.array(es.encounter_id.astype(np.int64)), "seed": pa.array(es.seed.astype(np.int64))}
    for f in _STATE:
        cols[f"own_{f}"] = pa.array(getattr(es.own, f).astype(np.float64))
    for f in _STATE:
        cols[f"intr_{f}"] = lst(getattr(es.intr, f), m)
    for k in SEGMENT_FIELDS:
        cols[k] = lst(getattr(es, k), m * s)
    for k in PARAM_NAMES:
        cols[f"p_{k}"] = lst(es.params.get(k, np.full((n, m), np.nan)), m)
    meta = {"format": FORMAT_NAME, "version": FORMAT_VERSION, "m": m, "s": s, "root_seed": es.root_seed,
            "duration_s": es.duration_s, "dt_s": es.dt_s, "config": es.config}
    table = pa.table(cols).replace_schema_metadata({"daa_sil": json.dumps(meta)})
    with atomic_path(path) as tmp, local_file(tmp, "wb") as fh:
        pq.write_table(table, fh)
    return Path(path)


def load_encounters(path: "str | os.PathLike") -> EncounterSet:
    """Read a file written by :func:`save_encounters`; FileFormatError (one line) if it is missing,
    not Parquet, not an encounter set, of another version, or has missing/ill-shaped columns."""
    import pyarrow as pa  # lazy: start-up time
    import pyarrow.parquet as pq  # lazy: start-up time

    p = Path(path)
    if not p.is_file():
        raise FileFormatError(f"{p}: no such encounter file")
    try:
        with local_file(p) as fh:
            table = pq.read_table(fh)
    except (OSError, pa.ArrowException, ValueError) as exc:
        raise FileFormatError(f"{p} is not a readable Parquet file: {str(exc).splitlines()[0] if str(exc) else exc}") from None
    raw = (table.schema.metadata or {}).get(b"daa_sil")
    try:
        meta = json.loads(raw) if raw else None
    except ValueError:
        meta = None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT_NAME:
        raise FileFormatError(f"{p} is not a daa-sil encounter set (no '{FORMAT_NAME}' metadata)")
    if meta.get("version") != FORMAT_VERSION:
        raise FileFormatError(f"{p}: encounter format version {meta.get('version')!r}, this daa-sil reads {FORMAT_VERSION}")
    n = table.num_rows
    try:
        m, s = int(meta["m"]), int(meta["s"])
    except (KeyError, TypeError, ValueError):
        raise FileFormatError(f"{p}: metadata lacks intruder/segment counts 'm'/'s'") from None
    names = set(table.column_names)

    def col(name):
        if name not in names:
            raise FileFormatError(f"{p}: missing column {name!r}")
        return table.column(name)

    def scalar(name, dtype):
        c = col(name)
        try:
            return np.asarray(c.to_numpy(zero_copy_only=False), dtype=dtype)
        except (TypeError, ValueError, pa.ArrowException):
            raise FileFormatError(f"{p}: column {name!r} is not {np.dtype(dtype).name}") from None

    def lst(name, width):
        c = col(name).combine_chunks()
        if not pa.types.is_list(c.type) or not pa.types.is_floating(c.type.value_type):
            raise FileFormatError(f"{p}: column {name!r} must be list<double>, got {c.type}")
        lens = np.asarray(c.value_lengths().to_numpy(zero_copy_only=False))
        if c.null_count or (lens != width).any():
            raise FileFormatError(f"{p}: column {name!r} must hold {width} values per row")
        return np.asarray(c.flatten().to_numpy(zero_copy_only=False), float).reshape((n, m, -1) if width != m else (n, m))

    own = AircraftState(*(scalar(f"own_{f}", float) for f in _STATE))
    intr = AircraftState(*(lst(f"intr_{f}", m) for f in _STATE))
    segs = {k: lst(k, m * s).reshape(n, m, s) for k in SEGMENT_FIELDS}
    params = {k: lst(f"p_{k}", m) for k in PARAM_NAMES}
    return EncounterSet(own=own, intr=intr, **segs, encounter_id=scalar("encounter_id", np.int64),
                        seed=scalar("seed", np.int64), params=params, root_seed=meta.get("root_seed"),
                        duration_s=float(meta.get("duration_s", DURATION.default)), dt_s=float(meta.get("dt_s", 1.0)),
                        config=meta.get("config", {}))
