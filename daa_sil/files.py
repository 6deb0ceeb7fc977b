"""Atomic file output: write to a temporary name in the same directory, fsync, then rename.

A crash, Ctrl-C or full disk therefore never leaves a half-written output behind; either the old
file (or nothing) or the complete new file is there. A process killed with SIGKILL mid-write can
leave its temporary file (``.<name>.<random>.tmp``) next to the target; :func:`remove_stale_temps`
clears those when a job resumes in that directory.

Errors are :class:`~daa_sil.errors.OutputError` (one line, exit 1): disk full (``ENOSPC``), file
size limit (``EFBIG``) and quota (``EDQUOT``) say so explicitly. Files get the usual permissions
(``0o666`` minus the umask), not ``mkstemp``'s private ``0o600``.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import tempfile
from pathlib import Path
from typing import Iterator

from .errors import OutputError

#: errno values that mean "no room for this file"
_FULL = {errno.ENOSPC: "disk full", errno.EFBIG: "file size limit reached", errno.EDQUOT: "disk quota exceeded"}


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


#: the process umask at import time (reading it needs a set/restore pair, so do it once)
_UMASK = _umask()


def ensure_dir(path: "str | os.PathLike") -> Path:
    """Create ``path`` (and parents) if needed; raise OutputError if no file can be created in it
    (checked by creating and removing a probe file, so it holds for root and read-only mounts too)."""
    p = Path(path)
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"cannot create output directory {p}: {exc.strerror or exc}") from None
    if not os.access(p, os.W_OK | os.X_OK):
        raise OutputError(f"output directory {p} is not writable")
    try:  # os.access says yes to root on read-only file systems and sysfs: try for real
        fd, probe = tempfile.mkstemp(prefix=".daa-sil-probe.", suffix=".tmp", dir=p)
    except OSError as exc:
        raise OutputError(f"output directory {p} is not writable: {exc.strerror or exc}") from None
    os.close(fd)
    os.unlink(probe)
    return p


@contextlib.contextmanager
def atomic_path(path: "str | os.PathLike", overwrite: bool = True) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; on success it is renamed over ``path``.

    On any exception the temporary file is removed and ``path`` is untouched.
    """
    target = Path(path)
    if not overwrite and target.exists():
        raise OutputError(f"{target} exists; refusing to overwrite (choose another path or remove it)")
    parent = ensure_dir(target.parent if str(target.parent) else ".")
    if target.is_dir():
        raise OutputError(f"cannot write {target}: it is a directory")
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=parent)
    except OSError as exc:
        raise OutputError(f"cannot write {target}: {exc.strerror or exc}") from None
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        with open(tmp_path, "rb+") as fh:
            os.fsync(fh.fileno())
        os.chmod(tmp_path, 0o666 & ~_UMASK)
        os.replace(tmp_path, target)
        _fsync_dir(parent)
    except OSError as exc:
        tmp_path.unlink(missing_ok=True)
        if exc.errno in _FULL:
            raise OutputError(f"{_FULL[exc.errno]} while writing {target}; nothing was written there") from None
        raise OutputError(f"cannot write {target}: {exc.strerror or exc}") from None
    except BaseException:
        tmp_path.unlink(missing_ok=True)
        raise


def _fsync_dir(directory: Path) -> None:
    """Make a rename durable (best effort: some file systems refuse fsync on directories)."""
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def is_temp_file(path: "str | os.PathLike") -> bool:
    """True for a temporary file made by :func:`atomic_path` (``.<name>.<random>.tmp``)."""
    name = Path(path).name
    return name.startswith(".") and name.endswith(".tmp") and name.count(".") >= 3


def remove_stale_temps(directory: "str | os.PathLike", recursive: bool = True) -> list[Path]:
    """Delete temporary files left by a killed writer under ``directory``; returns what was removed.

    Call it only when no other process is writing there (e.g. when a campaign resumes).
    """
    d = Path(directory)
    if not d.is_dir():
        return []
    found = [p for p in (d.rglob(".*.tmp") if recursive else d.glob(".*.tmp")) if p.is_file() and is_temp_file(p)]
    for p in found:
        p.unlink(missing_ok=True)
    return found


def atomic_write_bytes(path: "str | os.PathLike", data: bytes, overwrite: bool = True) -> Path:
    """Write ``data`` to ``path`` atomically."""
    with atomic_path(path, overwrite=overwrite) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def atomic_write_text(path: "str | os.PathLike", text: str, overwrite: bool = True) -> Path:
    """Write UTF-8 ``text`` to ``path`` atomically."""
    return atomic_write_bytes(path, text.encode("utf-8"), overwrite=overwrite)


def atomic_write_json(path: "str | os.PathLike", obj, overwrite: bool = True) -> Path:
    """Write ``obj`` as indented JSON (NaN/inf become null) atomically."""
    return atomic_write_text(path, json.dumps(to_jsonable(obj), indent=2, sort_keys=True) + "\n",
                             overwrite=overwrite)


def to_jsonable(obj):
    """Convert numpy scalars/arrays and non-finite floats (-> None) into plain JSON values."""
    import math

    import numpy as np

    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, (np.bool_, bool)):
        return bool(obj)
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (np.floating, float)):
        f = float(obj)
        return f if math.isfinite(f) else None
    if isinstance(obj, Path):
        return str(obj)
    return obj
