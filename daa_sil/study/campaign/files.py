"""A campaign directory on disk: chunk tables (Parquet, written atomically) with their checksum files,
``campaign.json``, the check that an output directory is empty unless resumed, and reading the
merged tables back (after checking every chunk against its checksums)."""

from __future__ import annotations

import hashlib
import json
import os
import platform
import re
from pathlib import Path
from dataclasses import dataclass
from typing import Sequence

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from daa_sil import __version__
from daa_sil.errors import FileFormatError, UsageError
from daa_sil.files import atomic_write_bytes, atomic_write_text, local_file
from importlib.metadata import version
from daa_sil.errors import OutputError
from daa_sil.files import check_output_path
import shutil

#: campaign.json format version
CAMPAIGN_FORMAT = 1
#: one line of a ``sha256sum`` file: 64 hex digits, two spaces, a file name
_SUM_LINE = re.compile(r"([0-9a-f]{64})  ([^/\\\n]+)")


def chunk_paths(out_dir: Path, group: str, chunk: int) -> tuple[Path, Path]:
    """``(encounters, decisions)`` Parquet paths of a chunk."""
    return (out_dir / group / f"encounters-{chunk:05d}.parquet", out_dir / group / f"decisions-{chunk:05d}.parquet")


def checksum_path(out_dir: Path, group: str, chunk: int) -> Path:
    """The chunk's checksum file ``<group>/chunk-<chunk>.sha256`` (``sha256sum`` format, written last:
    its presence marks the chunk complete; ``sha256sum -c`` in the group directory verifies it)."""
    return out_dir / group / f"chunk-{chunk:05d}.sha256"


def _parse_checksums(path: Path) -> dict[str, str]:
    """``{file name: sha256 hex}`` of a checksum file; FileFormatError if it is not one."""
    try:
        text = path.read_text(encoding="ascii")
    except (OSError, UnicodeDecodeError) as exc:
        raise FileFormatError(f"{path}: unreadable checksum file ({getattr(exc, 'strerror', None) or exc})") from None
    sums: dict[str, str] = {}
    for line in text.splitlines():
        m = _SUM_LINE.fullmatch(line)
        if m is None or m.group(2) in sums:
            raise FileFormatError(f"{path}: not a sha256sum checksum file")
        sums[m.group(2)] = m.group(1)
    return sums


def chunk_problem(out_dir: Path, group: str, chunk: int) -> "str | None":
    """Why the chunk is not complete and intact, or None if it is.

    Complete means: the checksum file exists and lists exactly the chunk's two tables, and each table's
    SHA-256 equals its entry. The whole of both files is hashed (a few hundred kB per chunk: well
    under a millisecond of hashing per chunk, so milliseconds for a campaign of hundreds of chunks),
    because reading them as Parquet is not enough: zeroed bytes inside a data page often decode to
    different values without any error. Returns ``"missing"`` when the chunk was never finished (no
    checksum file), otherwise a description of the damage naming the file.
    """
    enc, dec = chunk_paths(out_dir, group, chunk)
    sums_path = checksum_path(out_dir, group, chunk)
    if not sums_path.is_file():
        return "missing"
    try:
        sums = _parse_checksums(sums_path)
    except FileFormatError:
        return f"{sums_path.name} is not a checksum file"
    if sorted(sums) != sorted((enc.name, dec.name)):
        return f"{sums_path.name} does not list {dec.name} and {enc.name}"
    for f in (dec, enc):
        try:
            digest = hashlib.sha256(f.read_bytes()).hexdigest()
        except FileNotFoundError:
            return f"{f.name} is missing"
        except OSError as exc:
            return f"{f.name} cannot be read ({exc.strerror or exc})"
        if digest != sums[f.name]:
            return f"{f.name} does not match its SHA-256 in {sums_path.name}"
    return None


def chunk_done(out_dir: Path, group: str, chunk: int) -> bool:
    """True if the chunk is complete and intact (:func:`chunk_problem` is None)."""
    return chunk_problem(out_dir, group, chunk) is None


def _table_bytes(table: pa.Table) -> bytes:
    buf = pa.BufferOutputStream()
    pq.write_table(table, buf, compression="zstd")
    return buf.getvalue().to_pybytes()


@dataclass
class ChunkResult:
    """What a worker returns per unit: the two result tables of one chunk of one group and its
    compute time (s; a batch's time shared by rows)."""

    group: str
    chunk: int
    encounters: pa.Table
    decisions: pa.Table
    compute_s: float
    n: int


def write_chunk(out_dir: Path, res: ChunkResult) -> None:
    """Write a chunk's two tables atomically, then its checksum file (which marks completion)."""
    enc, dec = chunk_paths(out_dir, res.group, res.chunk)
    sums = checksum_path(out_dir, res.group, res.chunk)
    sums.unlink(missing_ok=True)  # a chunk being (re)written is not complete until its new checksums are
    lines = []
    for table, path in ((res.decisions, dec), (res.encounters, enc)):
        data = _table_bytes(table)
        atomic_write_bytes(path, data)
        lines.append(f"{hashlib.sha256(data).hexdigest()}  {path.name}\n")
    atomic_write_text(sums, "".join(lines))


def verify_chunks(out_dir: Path) -> None:
    """Check every chunk that has a checksum file (FileFormatError naming the first damaged one).

    Chunks without one (campaigns written before checksums existed, or a chunk being written) are
    not checked here; ``campaign run --resume`` computes a chunk without checksums again."""
    out = Path(out_dir)
    for sums_path in sorted(out.glob("*/chunk-*.sha256")):
        m = re.fullmatch(r"chunk-(\d+)\.sha256", sums_path.name)
        if m is None:
            continue
        group, chunk = sums_path.parent.name, int(m.group(1))
        why = chunk_problem(out, group, chunk)
        if why is not None and why != "missing":
            raise FileFormatError(f"{out}: chunk {chunk} of group {group} is damaged: {why}; "
                                  f"'daa-sil campaign run --out {out} --resume' computes it again")


def read_results(out_dir: "str | os.PathLike", kind: str = "encounters",
                 groups: "Sequence[str] | None" = None) -> pa.Table:
    """Concatenate the per-chunk tables of ``kind`` (``encounters`` or ``decisions``) in
    (group, chunk) order, after checking every chunk against its checksums (:func:`verify_chunks`)."""
    out = Path(out_dir)
    if kind not in ("encounters", "decisions"):
        raise UsageError(f"kind must be 'encounters' or 'decisions', got {kind!r}")
    if out.is_dir():
        verify_chunks(out)
    cfg = load_campaign_json(out)["config"] if (out / "campaign.json").is_file() else None
    names = list(groups) if groups is not None else ([g["name"] for g in cfg["groups"]] if cfg else
                                                     sorted(p.name for p in out.iterdir() if p.is_dir()))
    tables = []
    for g in names:
        for f in sorted((out / g).glob(f"{kind}-*.parquet")):
            try:
                with local_file(f) as fh:
                    tables.append(pq.read_table(fh))
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


def software_versions() -> dict:
    """The versions of daa-sil, Python and the libraries whose numbers a campaign's results depend on.
    numba's and llvmlite's are read from their installed metadata: importing numba only to ask costs the
    campaign's driver ~0.4 s while its workers wait."""

    return {"daa_sil": __version__, "python": platform.python_version(), "numpy": np.__version__,
            "pyarrow": pa.__version__, "numba": version("numba"), "llvmlite": version("llvmlite")}


def check_out_dir(out_dir: "str | os.PathLike", resume: bool, force: bool = False) -> Path:
    """Validate ``DIR`` before anything is written: a path that can be written
    (:func:`daa_sil.files.check_output_path`: name, length, UTF-8, writable), not held by another
    process (:func:`daa_sil.out_dir.check_not_busy`), and empty unless resuming or replacing (``force``)."""
    from daa_sil.out_dir import check_not_busy, contents  # lazy: start-up time

    try:
        p = check_output_path(out_dir, "--out", directory=True)
    except OutputError as exc:  # before anything runs: a usage error of --out (exit 2)
        raise UsageError(str(exc)) from None
    check_not_busy(p)
    if contents(p) and not (resume or force):
        raise UsageError(f"--out {p} is not empty; pass --resume to continue the campaign there, --force to "
                         f"replace it, or choose a new directory")
    return p


#: what a campaign writes into its directory (``--force`` removes these and nothing else)
_CAMPAIGN_FILES = ("campaign.json", "encounters.parquet")
_CHUNK_FILE = re.compile(r"(encounters|decisions)-\d+\.parquet|chunk-\d+\.sha256|\..+\.tmp")


def remove_campaign(out_dir: Path) -> None:
    """``--force``: remove a previous campaign's files from ``out_dir`` (``campaign.json``, the encounter
    set, the group directories holding only chunk files); anything else stays."""

    for name in _CAMPAIGN_FILES:
        (out_dir / name).unlink(missing_ok=True)
    for d in out_dir.iterdir():
        if d.is_dir() and not d.is_symlink() and all(_CHUNK_FILE.fullmatch(f.name) for f in d.iterdir()):
            shutil.rmtree(d)
