"""How the DAA kernels are compiled: numba, without fastmath, numpy's error model, cached on disk.

* **Exactness.** No ``fastmath`` (so no reassociation and no fused multiply-add: every ``a * b + c``
  is rounded twice, as numpy's one-operation-per-call loops do), ``error_model="numpy"`` (a division by
  zero gives inf / nan instead of raising). The kernels write every expression in the operation
  order of the numpy reference they replace (``docs/daa.md``, "Compiled kernels").
* **Cache.** Compiled machine code is written to ``$NUMBA_CACHE_DIR`` when that is set, else to
  ``$XDG_CACHE_HOME/daa-sil-numba`` (``~/.cache/daa-sil-numba``), in a subdirectory named after a
  hash of the kernel sources, their directory and the numba / llvmlite / numpy / Python versions
  (:mod:`daa_sil.runtime.jit_cache`, which answers without importing numba; a ``ready`` file there says every
  kernel is cached). numba keys its own entries on each kernel file's contents and directory only, so
  a change in a helper another file calls would otherwise go unnoticed, and a second checkout would
  find the first one's ``ready`` file without its entries; the hash makes either a fresh directory. numba
  writes each entry to a temporary file and renames it, so processes that compile at the same time
  (three SIL processes on a cold machine) each compile and the last rename wins, with identical
  contents.
* **When.** Every kernel has explicit signatures, so it is compiled (or loaded from the cache) when
  its module is imported, never in the middle of a step -- except the few ``lazy`` ones that only some
  configurations call (the unfused evaluator, the cylinder recovery, the resolution search): those
  are loaded at their first call (~7 ms each from the cache), so that a SIL process does not load
  kernels its configuration never calls at every start (the vehicle loads the search while it
  starts: it blends whenever the pilot's command is unsafe); a cold cache still gets them all
  (:func:`daa_sil.daa.kernels.get` compiles them with the others, so the ``ready`` file keeps meaning
  "everything is cached"). Nothing imports them, or numba, until the first DAA computation of a
  process calls :func:`daa_sil.daa.kernels.get`, which imports them all under an exclusive file lock
  in the cache directory (:func:`compile_lock`): of processes starting together on a cold machine one
  compiles and the others then load its cache, instead of each compiling on the same cores; the lock
  is released when its holder exits, however it exits. The holder compiles with a helper process on
  two cores or more (:func:`daa_sil.daa.kernels.compile_part`: no cache file is written by both). Once
  the cache is complete (its ``ready`` file) loading takes no lock: it only reads, and processes
  starting together (the SIL's vehicle and GCS) then load side by side instead of one after the
  other.
  ``python -m daa_sil.daa.kernels`` compiles ahead of time (the test suite does before its first test; the SIL driver
  does when the cache is cold, before it starts the vehicle and the GCS) and prints where the cache is
  and how long it took.
"""

from __future__ import annotations

import contextlib
import functools
from pathlib import Path

import numba

from daa_sil.runtime.jit_cache import cache_dir
import fcntl
from daa_sil.daa import kernels


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


#: the project's compilation settings (module docstring)
OPTIONS = {"cache": True, "fastmath": False, "error_model": "numpy", "nogil": True}


class LazyKernel:
    """A kernel compiled for its ``signatures`` (or loaded from the cache) at its first call, or when
    :meth:`compile` is called; then exactly the dispatcher ``kernel(signatures)`` makes."""

    def __init__(self, signatures, py_func):
        self.signatures, self.py_func = signatures, py_func
        self.dispatcher = None  #: the compiled kernel once loaded
        functools.update_wrapper(self, py_func)

    def compile(self):
        """The compiled kernel (compiled or loaded now if it was not yet)."""
        if self.dispatcher is None:
            with kernels.without_scipy_linalg():  # (as the eager kernels load: no BLAS probe)
                self.dispatcher = numba.njit(self.signatures, **OPTIONS)(self.py_func)
        return self.dispatcher

    def __call__(self, *args):
        d = self.dispatcher
        return (d if d is not None else self.compile())(*args)


def kernel(signatures, *, lazy: bool = False):
    """Decorator: compile eagerly for ``signatures`` with the project's settings (module docstring);
    ``lazy``: at the first call instead (:class:`LazyKernel`)."""
    if lazy:
        return lambda fn: LazyKernel(signatures, fn)
    return numba.njit(signatures, **OPTIONS)


#: decorator for the scalar helpers the kernels call (compiled into each kernel, not on their own)
inline = numba.njit(cache=False, fastmath=False, error_model="numpy")
#: as :data:`inline`, inlined into the caller by numba itself (no call, so no reference counting of the
#: arrays passed: a helper taking arrays that a kernel calls in its innermost loop)
inline_ir = numba.njit(cache=False, fastmath=False, error_model="numpy", inline="always")
