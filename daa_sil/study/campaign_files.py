"""A campaign directory on disk: chunk tables (Parquet, written atomically), ``campaign.json``, the
check that an output directory is empty unless resumed, and reading the merged tables back."""

from __future__ import annotations

import json
import os
import platform
from pathlib import Path
from typing import TYPE_CHECKING, Sequence

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from daa_sil import __version__
from daa_sil.errors import FileFormatError, UsageError
from daa_sil.files import atomic_path

if TYPE_CHECKING:
    from daa_sil.study.campaign import ChunkResult

#: campaign.json format version
CAMPAIGN_FORMAT = 1


def chunk_paths(out_dir: Path, group: str, chunk: int) -> tuple[Path, Path]:
    """``(encounters, decisions)`` Parquet paths of a chunk."""
    return (out_dir / group / f"encounters-{chunk:05d}.parquet", out_dir / group / f"decisions-{chunk:05d}.parquet")


def chunk_done(out_dir: Path, group: str, chunk: int) -> bool:
    """A chunk is complete when both files exist (decisions is written first, encounters last) and
    both have a readable Parquet footer (a damaged chunk is computed again on resume)."""
    enc, dec = chunk_paths(out_dir, group, chunk)
    if not (enc.is_file() and dec.is_file()):
        return False
    try:
        pq.read_metadata(enc)
        pq.read_metadata(dec)
    except (OSError, pa.ArrowException):
        return False
    return True


def _write_table(table: pa.Table, path: Path) -> None:
    with atomic_path(path) as tmp:
        pq.write_table(table, tmp, compression="zstd")


def write_chunk(out_dir: Path, res: ChunkResult) -> None:
    """Write a chunk's two tables atomically, decisions first (so encounters marks completion)."""
    enc, dec = chunk_paths(out_dir, res.group, res.chunk)
    _write_table(res.decisions, dec)
    _write_table(res.encounters, enc)


def read_results(out_dir: "str | os.PathLike", kind: str = "encounters",
                 groups: "Sequence[str] | None" = None) -> pa.Table:
    """Concatenate the per-chunk tables of ``kind`` (``encounters`` or ``decisions``) in
    (group, chunk) order."""
    out = Path(out_dir)
    if kind not in ("encounters", "decisions"):
        raise UsageError(f"kind must be 'encounters' or 'decisions', got {kind!r}")
    cfg = load_campaign_json(out)["config"] if (out / "campaign.json").is_file() else None
    names = list(groups) if groups is not None else ([g["name"] for g in cfg["groups"]] if cfg else
                                                     sorted(p.name for p in out.iterdir() if p.is_dir()))
    tables = []
    for g in names:
        for f in sorted((out / g).glob(f"{kind}-*.parquet")):
            try:
                tables.append(pq.read_table(f))
            except (OSError, pa.ArrowException) as exc:
                raise FileFormatError(f"{f} is not a readable Parquet file: {str(exc).splitlines()[0]}") from None
    if not tables:
        raise FileFormatError(f"{out} holds no {kind}-*.parquet results")
    return pa.concat_tables(tables)


def load_campaign_json(out_dir: Path) -> dict:
    """Read ``DIR/campaign.json`` (FileFormatError if unreadable)."""
    path = Path(out_dir) / "campaign.json"
    try:
        meta = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise FileFormatError(f"{path} does not exist; not a campaign directory") from None
    except (OSError, ValueError) as exc:
        raise FileFormatError(f"{path} is not readable JSON: {exc}") from None
    if not isinstance(meta, dict) or meta.get("format") != CAMPAIGN_FORMAT or "config" not in meta:
        raise FileFormatError(f"{path}: not a daa-sil campaign file (format {CAMPAIGN_FORMAT} expected)")
    return meta


def _versions() -> dict:
    import llvmlite
    import numba

    out = {"daa_sil": __version__, "python": platform.python_version(), "numpy": np.__version__,
           "pyarrow": pa.__version__, "numba": numba.__version__, "llvmlite": llvmlite.__version__}
    return out


def check_out_dir(out_dir: "str | os.PathLike", resume: bool) -> Path:
    """Validate ``DIR`` before anything is written: writable, and empty unless resuming."""
    p = Path(out_dir)
    if p.exists() and not p.is_dir():
        raise UsageError(f"--out {p} exists and is not a directory")
    if p.is_dir():
        if not os.access(p, os.W_OK | os.X_OK):
            raise UsageError(f"--out {p} is not writable")
        if any(p.iterdir()) and not resume:
            raise UsageError(f"--out {p} is not empty; pass --resume to continue the campaign there "
                             f"or choose a new directory")
        return p
    anc = p.absolute().parent
    while not anc.exists():
        anc = anc.parent
    if not anc.is_dir() or not os.access(anc, os.W_OK | os.X_OK):
        raise UsageError(f"--out {p} cannot be created: {anc} is not a writable directory")
    return p
