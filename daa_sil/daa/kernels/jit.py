"""How the DAA kernels are compiled: numba, without fastmath, numpy's error model, cached on disk.

* **Exactness.** No ``fastmath`` (so no reassociation and no fused multiply-add: every ``a * b + c``
  is rounded twice, as numpy's one-operation-per-call loops do), ``error_model="numpy"`` (a division by
  zero gives inf / nan instead of raising). The kernels write every expression in the operation
  order of the numpy reference they replace (``docs/daa.md``, "Compiled kernels").
* **Cache.** Compiled machine code is written to ``$NUMBA_CACHE_DIR`` when that is set, else to
  ``$XDG_CACHE_HOME/daa-sil-numba`` (``~/.cache/daa-sil-numba``), in a subdirectory named after a
  hash of the kernel sources and the numba / llvmlite / numpy / Python versions. numba keys its own
  cache on each kernel file's time stamp only, so a change in a helper another file calls would
  otherwise go unnoticed; the hash makes any change start a fresh directory. numba writes each
  entry to a temporary file and renames it, so processes that compile at the same time (three SIL
  processes on a cold machine) each compile and the last rename wins, with identical contents.
* **When.** Every kernel has explicit signatures, so it is compiled (or loaded from the cache) when
  its module is imported, never in the middle of a step. :mod:`daa_sil.daa.kernels` imports them all
  under an exclusive file lock in the cache directory (:func:`compile_lock`): of processes starting
  together on a cold machine one compiles and the others then load its cache, instead of each
  compiling on the same cores; the lock is released when its holder exits, however it exits.
  ``python -m daa_sil.daa.kernels`` compiles ahead of time (CI does, after installing) and prints
  where the cache is and how long it took.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import sys
from pathlib import Path

import llvmlite
import numba
import numpy as np

_HERE = Path(__file__).resolve().parent


def source_hash() -> str:
    """16 hex digits identifying the kernel sources and the compiler stack they were built with."""
    h = hashlib.sha256()
    for p in sorted(_HERE.glob("*.py")):
        h.update(p.name.encode())
        h.update(p.read_bytes())
    h.update(f"{numba.__version__} {llvmlite.__version__} {np.__version__} {sys.version}".encode())
    return h.hexdigest()[:16]


def cache_dir() -> Path:
    """Directory the compiled kernels are cached in (see the module docstring)."""
    base = os.environ.get("NUMBA_CACHE_DIR")
    if not base:
        xdg = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
        base = os.path.join(xdg, "daa-sil-numba")
    return Path(base) / source_hash()


def _configure_cache() -> Path:
    path = cache_dir()
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError:  # unwritable: numba then compiles in memory on every start (slower, same results)
        return path
    numba.config.CACHE_DIR = str(path)
    return path


CACHE_DIR = _configure_cache()


@contextlib.contextmanager
def compile_lock():
    """Exclusive lock on ``CACHE_DIR/.compile.lock`` while held (no lock where that cannot be had)."""
    try:
        import fcntl

        fh = open(CACHE_DIR / ".compile.lock", "a+b")
    except (ImportError, OSError):
        yield
        return
    with fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def kernel(signatures):
    """Decorator: compile eagerly for ``signatures`` with the project's settings (module docstring)."""
    return numba.njit(signatures, cache=True, fastmath=False, error_model="numpy", nogil=True)


#: decorator for the scalar helpers the kernels call (compiled into each kernel, not on their own)
inline = numba.njit(cache=False, fastmath=False, error_model="numpy")
