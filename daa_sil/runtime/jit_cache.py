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

#: the kernels' sources (hashed: a change anywhere in them starts a fresh cache directory), as imported: not
#: resolved, since numba files its entries under each source file's absolute, unresolved directory
KERNEL_DIR = Path(os.path.abspath(__file__)).parent.parent / "daa" / "kernels"
#: file written into the cache directory once every kernel is in it
READY_MARKER = "ready"
#: how long a cold compilation takes, as measured on the 2-vCPU benchmark VM (said to a user who waits for it)
COLD_COMPILE_TIME = "17-40 s on two cores, about a minute on one"


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


def mark_ready(directory: "Path | None" = None) -> None:
    """Record that every kernel is cached in ``directory`` (default :func:`cache_dir`)."""
    ((directory or cache_dir()) / READY_MARKER).touch()


def is_warm(directory: "Path | None" = None) -> bool:
    """True when every kernel is in the cache ``directory`` (default :func:`cache_dir`): a process will load
    them instead of compiling."""
    return ((directory or cache_dir()) / READY_MARKER).is_file()
