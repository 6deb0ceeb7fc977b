"""Where the DAA's compiled kernels are cached, and whether that cache is complete, without importing numba
(the SIL driver asks before it starts the processes that use them). The rules are in
:mod:`daa_sil.daa.kernels.jit`."""

from __future__ import annotations

import functools
import hashlib
import os
import sys
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

#: the kernels' sources (hashed: a change anywhere in them starts a fresh cache directory)
KERNEL_DIR = Path(__file__).resolve().parent / "daa" / "kernels"
#: file written into the cache directory once every kernel is in it (it holds :func:`source_stamps`)
READY_MARKER = "ready"


def _version(dist: str) -> str:
    try:
        return version(dist)
    except PackageNotFoundError:
        return "-"


@functools.lru_cache(maxsize=1)
def source_hash() -> str:
    """16 hex digits identifying the kernel sources, where they are, and the numba / llvmlite / numpy / Python
    versions; computed once per process (reading the installed versions' metadata costs ~25 ms, and the SIL
    nodes asked twice while starting). numba files its entries under each source file's directory, so a
    second checkout of the same sources has none of the first one's: it gets its own directory."""
    h = hashlib.sha256(str(KERNEL_DIR).encode())
    for p in sorted(KERNEL_DIR.glob("*.py")):
        h.update(p.name.encode())
        h.update(p.read_bytes())
    h.update(" ".join([_version("numba"), _version("llvmlite"), _version("numpy"), sys.version]).encode())
    return h.hexdigest()[:16]


def cache_dir() -> Path:
    """``$NUMBA_CACHE_DIR`` (or ``$XDG_CACHE_HOME/daa-sil-numba``, default ``~/.cache/daa-sil-numba``) /
    :func:`source_hash`."""
    base = os.environ.get("NUMBA_CACHE_DIR")
    if not base:
        xdg = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
        base = os.path.join(xdg, "daa-sil-numba")
    return Path(base) / source_hash()


def source_stamps() -> str:
    """Each kernel source file's name, modification time and size, one per line: what numba checks its
    cache entries against (a file touched without a change -- a branch switched and back -- makes numba
    compile that file's kernels again)."""
    lines = []
    for p in sorted(KERNEL_DIR.glob("*.py")):
        st = p.stat()
        lines.append(f"{p.name} {st.st_mtime!r} {st.st_size}\n")
    return "".join(lines)


def mark_ready() -> None:
    """Record that every kernel is cached for the sources as they are now (written whole, then renamed)."""
    path = cache_dir() / READY_MARKER
    tmp = path.with_name(f".{READY_MARKER}.{os.getpid()}")
    tmp.write_text(source_stamps())
    os.replace(tmp, path)


def is_warm() -> bool:
    """True when every kernel is in the cache for the sources as they are now (a process will load them instead
    of compiling): the ``ready`` file :func:`mark_ready` wrote holds the sources' current stamps."""
    try:
        return (cache_dir() / READY_MARKER).read_text() == source_stamps()
    except OSError:
        return False
