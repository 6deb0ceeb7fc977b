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
import stat
import tempfile
from pathlib import Path
from typing import Iterator

from .errors import OutputError, UsageError
import math

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


#: bytes the temporary name of an atomic write adds to its target's name (``.NAME.XXXXXXXX.tmp``)
TEMP_NAME_EXTRA = 14
#: bytes kept free below the system's path limit for what a command writes inside an output directory
#: (``logs/vehicle.log``, ``ID-2-projl/.decisions-00000.parquet.XXXXXXXX.tmp``, ...)
PATH_ROOM = 64


def shown(text: str, limit: int = 160) -> str:
    """``text`` for a one-line message: undecodable bytes escaped, a long name cut in its middle."""
    try:
        safe = os.fsencode(str(text)).decode("utf-8", "backslashreplace")  # a stray byte shows as \\xff
    except UnicodeEncodeError:
        safe = str(text).encode("utf-8", "backslashreplace").decode("utf-8")
    return safe if len(safe) <= limit else f"{safe[:limit // 2]}...{safe[-(limit // 2 - 3):]}"


def _limit(path: "str | os.PathLike", name: str, default: int) -> int:
    try:
        return int(os.pathconf(path, name))
    except (OSError, ValueError):
        return default


def check_output_path(path: "str | os.PathLike", option: str, *, directory: bool = False) -> Path:
    """Check, before any work, that ``path`` can be written as an output (a directory when
    ``directory``, else a file written atomically); creates nothing. Returns ``Path(path)``.

    * the name is UTF-8 (every format we write, every message and the child processes' command lines
      carry it) and holds no NUL: otherwise a one-line :class:`UsageError`;
    * every component not yet there fits the file system's name limit (``NAME_MAX``, 255 bytes on
      most; an output file leaves room for its temporary name, :data:`TEMP_NAME_EXTRA`) and the whole
      path its path limit: UsageError (exit 2), before any call that would fail with ``ENAMETOOLONG``;
    * no component is a regular file, an existing target is of the right kind, and the nearest
      existing directory lets a file be created (probed with a file that is removed at once, since
      ``os.access`` says yes to root on read-only mounts): :class:`OutputError` (exit 1).
    """
    text = os.fsdecode(os.fspath(path))
    if not text:
        raise UsageError(f"{option} is empty; give a path")
    if "\0" in text:
        raise UsageError(f"{option} {shown(text)}: a path cannot hold a NUL byte")
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        raise UsageError(f"{option} {shown(text)}: the name is not valid UTF-8 (the step log, result.json and "
                         f"every message record it as text); choose a UTF-8 name") from None
    full = Path(os.path.abspath(text))
    path_max = _limit("/", "PC_PATH_MAX", 4096)
    if len(os.fsencode(str(full))) + PATH_ROOM > path_max:
        raise UsageError(f"{option} {shown(text)}: the path is {len(os.fsencode(str(full)))} bytes long; this system "
                         f"takes {path_max} with room for the files inside ({path_max - PATH_ROOM} at most)")
    kind = "directory" if directory else "file"
    here, parts = Path(full.anchor), full.parts[1:]
    missing: tuple = ()
    for i, name in enumerate(parts):
        nxt, last = here / name, i == len(parts) - 1
        try:
            st = os.stat(nxt)
        except FileNotFoundError:
            missing = parts[i:]
            break
        except OSError as exc:
            if exc.errno == errno.ENAMETOOLONG:
                raise UsageError(f"{option} {shown(text)}: the name {shown(name, 40)} is {len(os.fsencode(name))} "
                                 f"bytes long; the file system takes at most {_limit(here, 'PC_NAME_MAX', 255)}") from None
            raise OutputError(f"cannot create output {kind} {shown(text)}: {exc.strerror or exc}") from None
        if not last and not stat.S_ISDIR(st.st_mode):
            raise OutputError(f"cannot create output {kind} {shown(text)}: {nxt} is a file (Not a directory)")
        if last and directory and not stat.S_ISDIR(st.st_mode):
            raise OutputError(f"cannot create output directory {shown(text)}: it exists and is not a directory")
        if last and not directory and stat.S_ISDIR(st.st_mode):
            raise UsageError(f"{option} {shown(text)} is a directory, not a file path")
        here = nxt if stat.S_ISDIR(st.st_mode) else here
    name_max = _limit(here, "PC_NAME_MAX", 255)
    checked = missing or (() if directory else parts[-1:])
    for i, name in enumerate(checked):
        room = TEMP_NAME_EXTRA if (not directory and i == len(checked) - 1) else 0
        if len(os.fsencode(name)) + room > name_max:
            what = f"at most {name_max - room} for an output file (its temporary name adds {room})" if room else \
                f"at most {name_max}"
            raise UsageError(f"{option} {shown(text)}: the name {shown(name, 40)} is {len(os.fsencode(name))} bytes "
                             f"long; the file system takes {what}")
    try:  # a file can be created where the output goes (or, for a new path, in its nearest existing directory)
        fd, probe = tempfile.mkstemp(prefix=".daa-sil-probe.", suffix=".tmp", dir=here)
    except OSError as exc:
        why = exc.strerror or str(exc)
        if here == full:
            raise OutputError(f"output directory {shown(text)} is not writable: {why}") from None
        raise OutputError(f"cannot create output {kind} {shown(text)}: {here} is not writable ({why})") from None
    os.close(fd)
    os.unlink(probe)
    return Path(text)


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


def local_file(path: "str | os.PathLike", mode: str = "rb"):
    """A pyarrow file of the local ``path`` (``pq.write_table(table, local_file(p, "wb"))``).

    pyarrow reads a string path with a colon in it (``run-12:30/steplog.parquet``) as a URI and
    fails ("Unrecognized filesystem type in URI"); a file object is never parsed, so an output
    directory is a path whatever characters it holds."""
    import pyarrow as pa  # lazy: start-up time

    return pa.OSFile(os.fspath(path), mode)


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

    import numpy as np  # lazy: start-up time

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
