"""The wait-map cache: ``$DAA_SIL_CACHE`` (or ``~/.cache/daa-sil``) ``/waitmaps/<key>/``, where
``<key>`` is the first 24 hex digits of the family hash (grid, every parameter, the turn-rate list
and the file format, :func:`~daa_sil.waitmap.model.params_hash`).

An entry holds one ``waitmap_turn*.npz`` per turn rate and ``family.json`` (written last). It is
used only after :func:`~daa_sil.waitmap.family_files.load_family` has checked it against what this family
must be: the index against the expected turn rates and family hash, every map against the index
(size, declared content hash, zip CRC-32 of every array). On any mismatch the entry is repaired
with a one-line warning: maps that still prove whole (SHA-256 recomputed, same grid, parameters and
turn rate) are kept, the others are built again, and the index is rewritten.

Building writes each map atomically as soon as it is finished (:func:`~.build.build_members`), so
Ctrl-C during a first build keeps the finished maps and the next run builds only the rest. One
process at a time builds or repairs an entry (an exclusive ``flock`` on its ``.lock`` file);
others wait for it, then load its result. Readers take no lock: maps and index are replaced
atomically, and a reader that meets a half-repaired entry fails its check and waits for the lock.
"""

from __future__ import annotations

import contextlib
import os
import shutil
from pathlib import Path
from typing import Callable, Iterator, Sequence

from ..errors import FileFormatError, OutputError, UsageError, warn
from ..files import remove_stale_temps
from .grid import Grid
from .lookup import WaitMapFamily
from .model import MdpParams, params_hash
from .build import build_members
from .family_files import FAMILY_INDEX, check_family, load_family, write_family_index
from .store import load, map_filename, read_meta
import json
import fcntl


def cache_dir() -> Path:
    """``$DAA_SIL_CACHE`` or ``~/.cache/daa-sil``."""
    env = os.environ.get("DAA_SIL_CACHE")
    return Path(env) if env else Path.home() / ".cache" / "daa-sil"


def entry_path(key: str) -> Path:
    """The cache directory of the family with hash ``key``."""
    return cache_dir() / "waitmaps" / key[:24]


def entry_ready(key: str, turn_rates: Sequence[float]) -> bool:
    """True if the entry passes the cheap check (:func:`~.family_files.check_family`; milliseconds)."""
    try:
        check_family(entry_path(key), turn_rates, key)
    except (FileFormatError, UsageError):
        return False
    return True


def cached_family(grid: Grid, params: MdpParams, turn_rates: Sequence[float],
                  progress: "Callable[[float], None] | None" = None,
                  workers: "int | None" = None) -> WaitMapFamily:
    """The family of these settings from the cache, built, completed or repaired first if needed."""
    key = params_hash(grid.to_dict(), params, turn_rates)
    entry = entry_path(key)
    rates = [float(r) for r in turn_rates]
    try:
        return load_family(entry, rates, key)
    except (FileFormatError, UsageError):
        pass  # not there, incomplete or damaged: repaired below, under the entry's lock
    try:
        entry.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"cannot create the wait-map cache {entry}: {exc.strerror or exc}") from None
    with _entry_lock(entry):
        problem = None
        if (entry / FAMILY_INDEX).exists():
            try:
                return load_family(entry, rates, key)  # another process finished or repaired it meanwhile
            except (FileFormatError, UsageError) as exc:
                problem = str(exc)
            (entry / FAMILY_INDEX).unlink()
        remove_stale_temps(entry, recursive=False)  # left by a builder that was killed mid-write
        _remove_old_build_dirs(entry)
        kept, todo = _sort_members(entry, grid, params, rates)
        if problem is not None:
            warn(f"wait-map cache entry {entry} failed its check ({problem}); "
                 f"rebuilding {len(todo)} of {len(rates)} maps, keeping {len(kept)}")
        elif kept:
            warn(f"wait-map cache entry {entry} was left by an interrupted build: keeping its {len(kept)} "
                 f"finished maps, building the other {len(todo)}")

        build_members(grid, params, todo, entry, workers=workers, progress=progress)
        members = [(r, entry / map_filename(r), read_meta(entry / map_filename(r))["content_hash"]) for r in rates]
        write_family_index(entry, members, key, rates)
        return load_family(entry, rates, key)


def _sort_members(entry: Path, grid: Grid, params: MdpParams, rates: list) -> tuple[list, list]:
    """``(kept, to build)`` turn rates: a map file is kept when it loads with its SHA-256 recomputed
    and is the map of this grid, these parameters and that turn rate; any other is deleted."""
    axes, pdict = grid.to_dict()["axes"], params.to_dict()
    kept, todo = [], []
    for r in rates:
        f = entry / map_filename(r)
        if f.exists():
            try:
                wm = load(f)
                if (wm.turn_rate_deg == r and wm.grid.to_dict()["axes"] == axes
                        and _same_json(wm.params.to_dict(), pdict)):
                    kept.append(r)
                    continue
            except (FileFormatError, UsageError):
                pass
            f.unlink(missing_ok=True)
        todo.append(r)
    return kept, todo


def _same_json(a: dict, b: dict) -> bool:
    return json.dumps(a, sort_keys=True) == json.dumps(b, sort_keys=True)


def _remove_old_build_dirs(entry: Path) -> None:
    """Temporary family directories (``.<key>.<random>``) of builders from before per-map writes."""
    for d in entry.parent.glob(f".{entry.name}.*"):
        if d.is_dir():
            shutil.rmtree(d, ignore_errors=True)


@contextlib.contextmanager
def _entry_lock(entry: Path) -> Iterator[None]:
    """Hold an exclusive ``flock`` on the entry's ``.lock`` file (none where ``fcntl`` is missing);
    say so once if another process holds it."""
    try:
        pass
    except ImportError:  # not POSIX: concurrent builders write identical files atomically
        yield
        return
    path = entry / ".lock"
    try:
        fh = open(path, "a+b")
    except OSError as exc:
        raise OutputError(f"cannot lock the wait-map cache entry {entry}: {exc.strerror or exc}") from None
    with fh:
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            warn(f"another process is building the wait maps in {entry}; waiting for it")
            fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)
