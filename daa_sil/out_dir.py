"""An output directory held by one writer at a time, and where an output goes when its directory can
no longer take it.

* :func:`claim_out_dir`: the command that writes ``DIR`` holds an exclusive ``flock`` on
  ``DIR/.daa-sil.lock`` (its pid inside) for as long as it runs, and removes the file when it is
  done. A second command into a busy directory, or into one that holds anything but the lock file
  (unless it continues its own work, ``campaign run --resume``, or replaces it, ``--force``), is
  refused in one line before anything is written; a directory created for a refused command is
  removed again. The kernel drops the lock when its holder dies (also on SIGKILL), so a lock file a
  killed command left behind never blocks anyone.
* :func:`write_or_rescue`: an output whose directory became unwritable while the job ran (a
  permission change, a removed or remounted directory) is written to :func:`rescue_path` instead,
  and a warning line says where.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import shutil
import tempfile
from pathlib import Path
from typing import Callable, Iterator

from .errors import OutputError, UsageError, warn
from .files import shown
import fcntl
from .files import check_output_path, ensure_dir

#: the lock file of an output directory (ignored when deciding whether the directory is empty)
LOCK_NAME = ".daa-sil.lock"
#: environment variable naming the directory rescued outputs go to (default: the temporary directory)
RESCUE_ENV = "DAA_SIL_RESCUE"


def holder_pid(directory: "str | os.PathLike") -> "int | None":
    """The pid written in ``directory``'s lock file (None if there is none or it is unreadable)."""
    try:
        text = (Path(directory) / LOCK_NAME).read_text(encoding="ascii").strip()
    except (OSError, UnicodeDecodeError):
        return None
    return int(text) if text.isdigit() else None


def contents(directory: "str | os.PathLike") -> list[str]:
    """Names in ``directory`` other than its lock file (sorted; [] if it does not exist)."""
    try:
        return sorted(n for n in os.listdir(directory) if n != LOCK_NAME)
    except FileNotFoundError:
        return []


def busy_message(directory: Path, option: str) -> str:
    pid = holder_pid(directory)
    return (f"{option} {shown(directory)} is in use by another daa-sil process" + (f" (pid {pid})" if pid else "")
            + f"; wait for it to finish or choose another {option}")


def check_not_busy(directory: "str | os.PathLike", option: str = "--out") -> None:
    """A one-line UsageError if another process holds ``directory`` now (a look before any work; the
    claim itself is :func:`claim_out_dir`)."""
    lock = Path(directory) / LOCK_NAME
    try:
        fh = open(lock, "rb")
    except (ImportError, OSError):  # no lock file (or no fcntl): nobody holds it
        return
    with fh:
        try:
            fcntl.flock(fh, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            if holder_pid(directory) == os.getpid():  # this process holds it (claimed, then checked again)
                return
            raise UsageError(busy_message(Path(directory), option)) from None
        except OSError:
            return


@contextlib.contextmanager
def claim_out_dir(directory: "str | os.PathLike", option: str = "--out", *, keep: bool = False,
                  replace: "Callable[[Path], None] | None" = None,
                  hint: str = "choose a new directory or pass --force to replace what is there") -> Iterator[Path]:
    """Hold ``directory`` (created if missing) for this process while the block runs.

    Refused with a one-line :class:`UsageError` (exit 2), leaving the file system as it was, when
    another process holds it, or when it holds anything but the lock file and neither ``keep`` (the
    command continues what is there) nor ``replace`` (called with the directory under the lock to
    clear the previous run's outputs: ``--force``) is given. ``hint`` ends the not-empty message.
    """

    path = check_output_path(directory, option, directory=True)  # name, length, kind, writable: one line
    top = _first_missing(path)
    ensure_dir(path)
    lock = path / LOCK_NAME
    made_lock = not lock.exists()
    fh = None
    try:
        fh = _lock(lock, path, option)
        found = contents(path)
        if found and not keep:
            if replace is None:
                more = f" and {len(found) - 1} more" if len(found) > 1 else ""
                raise UsageError(f"{option} {shown(path)} is not empty (it holds {shown(found[0], 40)}{more}); {hint}")
            replace(path)
        fh.seek(0)
        fh.truncate()
        fh.write(f"{os.getpid()}\n".encode("ascii"))
        fh.flush()
    except BaseException:
        if made_lock:
            with contextlib.suppress(OSError):
                lock.unlink(missing_ok=True)
        if fh is not None:
            fh.close()
        _undo(top)
        raise
    try:
        yield path
    finally:
        with contextlib.suppress(OSError):  # (a directory that became unwritable keeps it: harmless, unlocked)
            lock.unlink(missing_ok=True)  # still holding it: a claimer that opened this file finds it gone
        fh.close()


def _lock(lock: Path, directory: Path, option: str):
    """Open ``lock`` and take an exclusive ``flock`` without waiting; the open file.

    A holder removes the file before it lets go, so a claimer that opened the file just before and
    got the lock just after holds a removed file: it checks that the path still names what it locked
    and tries again if not."""

    for _ in range(10):
        try:
            fh = open(lock, "a+b")
        except OSError as exc:
            raise OutputError(f"cannot lock output directory {shown(directory)}: {exc.strerror or exc}") from None
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            fh.close()
            raise UsageError(busy_message(directory, option)) from None
        try:
            same = os.stat(lock).st_ino == os.fstat(fh.fileno()).st_ino
        except FileNotFoundError:
            same = False
        if same:
            return fh
        fh.close()
    raise UsageError(busy_message(directory, option))


def _first_missing(path: Path) -> "Path | None":
    """The topmost component of ``path`` that does not exist yet (None if ``path`` exists)."""
    top = None
    p = path.absolute()
    while not p.exists():
        top, p = p, p.parent
    return top


def _undo(top: "Path | None") -> None:
    """Remove the directories a refused claim made."""
    if top is not None:
        shutil.rmtree(top, ignore_errors=True)


def rescue_path(path: "str | os.PathLike") -> Path:
    """Where :func:`write_or_rescue` saves ``path`` when its directory cannot take it:
    ``$DAA_SIL_RESCUE`` (default: the temporary directory) ``/daa-sil-rescue-<uid>/<16 hex digits of
    the absolute directory>/<name>``, the same place for the same target, so a supervisor can find
    what its child saved."""
    target = Path(os.path.abspath(path))
    key = hashlib.sha256(os.fsencode(str(target.parent))).hexdigest()[:16]
    base = Path(os.environ.get(RESCUE_ENV) or tempfile.gettempdir())
    uid = os.getuid() if hasattr(os, "getuid") else 0
    return base / f"daa-sil-rescue-{uid}" / key / target.name


def write_or_rescue(path: "str | os.PathLike", write: Callable[[Path], object], what: str, say: bool = True) -> Path:
    """``write(path)`` (an atomic writer that raises :class:`OutputError`); when that fails, ``write``
    to :func:`rescue_path` instead and (``say``) warn in one line naming both. Returns where it was
    written; raises the original error if the rescue fails too."""
    try:
        write(Path(path))
        return Path(path)
    except OutputError as exc:
        alt = rescue_path(path)
        try:
            write(alt)
        except OutputError:
            raise exc from None
        if say:
            warn(f"{exc}; the {what} is saved in {alt} instead")
        return alt


__all__ = ["LOCK_NAME", "RESCUE_ENV", "holder_pid", "contents", "busy_message", "check_not_busy", "claim_out_dir", "rescue_path", "write_or_rescue"]
