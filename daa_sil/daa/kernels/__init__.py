"""Compiled (numba) kernels of the DAA's hot loops; the rules are in :mod:`daa_sil.daa.kernels.jit`.

The numpy functions they replace stay as ``*_reference`` in their modules and are the test oracles
(``tests/test_daa_kernels.py``: identical results on random and adversarial inputs). Nothing is
compiled, and numba is not imported, until the first kernel is needed: :func:`get` then compiles every
kernel under the cache's file lock (on two cores, part of them in a helper process), or loads it from a
complete cache without that lock (a process that imports the DAA without computing bands -- the shim, a
report -- pays nothing).
"""

from __future__ import annotations

import contextlib
import importlib
import os
import sys
import time
from types import SimpleNamespace

from daa_sil.runtime.jit_cache import READY_MARKER, cache_dir, is_warm, mark_ready
import multiprocessing as mp
import signal

_MODULES = ("elementwise", "evaluate", "motion", "regions", "resolve", "axis_pass", "select", "flight",
            "command_plan", "recovery")
#: a cold cache: compiled first, here, as the helper's modules import them (the helper then loads them)
SHARED_MODULES = ("motion", "flight")
#: a cold cache: compiled by a helper process while this one compiles the rest (:func:`compile_part`)
HELPER_MODULES = ("resolve", "command_plan", "select")
#: the helper process's name (``ps``, ``pgrep``)
HELPER_NAME = "daa-kernels"
#: s the helper may take before it is stopped and its part compiled here (it takes ~30 s on two cores)
HELPER_TIMEOUT_S = 1800.0
#: where the kernels are cached (:func:`daa_sil.runtime.jit_cache.cache_dir`)
CACHE_DIR = cache_dir()
#: s this process waited for another one's compilation, and spent compiling / loading the kernels
#: (None until :func:`get` has run)
LOCK_WAIT_S: "float | None" = None
LOAD_S: "float | None" = None
#: exit status of the helper process that compiled part of a cold cache (None: no helper ran)
HELPER_RC: "int | None" = None
_KERNELS: "SimpleNamespace | None" = None
#: False once :func:`skip_blas_probe` was called in this process
_BLAS_PROBE = True


def skip_blas_probe() -> None:
    """Load the kernels, in this process, without numba's probe for scipy's BLAS.

    When numba first loads its array functions -- for a cached kernel too -- it checks whether
    ``scipy.linalg.cython_blas`` imports, and importing ``scipy.linalg`` costs 0.15-0.25 s of
    start-up on the benchmark machine. No kernel here uses linear algebra. The SIL's vehicle and GCS
    (``python -m vehicle``, ``python -m gcs``) call this before anything else: in such a process
    numba's own linear algebra (``np.dot``, ``np.linalg`` inside jitted code) is unavailable to
    other jitted code; scipy itself is untouched and imports normally afterwards.
    """
    global _BLAS_PROBE
    _BLAS_PROBE = False


@contextlib.contextmanager
def without_scipy_linalg():
    """While loading: ``import scipy.linalg`` fails at once (unless it is already imported)."""
    if _BLAS_PROBE or "scipy.linalg" in sys.modules:
        yield
        return
    sys.modules["scipy.linalg"] = None  # type: ignore[assignment]  (the import system's "not importable")
    try:
        yield
    finally:
        if "scipy.linalg" in sys.modules and sys.modules["scipy.linalg"] is None:
            del sys.modules["scipy.linalg"]


def _load(clear: bool) -> tuple[float, float]:
    """Import (so compile, or load from the cache) every kernel module; ``clear``: delete the cache's
    entries first. Under the compile lock unless the cache is complete (its ``ready`` file): loading
    only reads, so the SIL's vehicle and GCS load side by side instead of one after the other. A
    process that waited for the lock finds the cache complete and loads. Returns (s waited for the
    lock, s compiling / loading)."""
    from daa_sil.daa.kernels.jit import compile_lock  # lazy: start-up time

    t0 = time.perf_counter()
    warm = not clear and is_warm(CACHE_DIR)
    with contextlib.nullcontext() if warm else compile_lock():
        t1 = time.perf_counter()
        if clear:
            for f in list(CACHE_DIR.rglob("*.nbi")) + list(CACHE_DIR.rglob("*.nbc")) + [CACHE_DIR / READY_MARKER]:
                f.unlink(missing_ok=True)
        else:
            warm = is_warm(CACHE_DIR)  # (another process compiled while this one waited)
        with without_scipy_linalg():
            if warm:
                _import(_MODULES)
            else:
                _compile_everything()
                try:  # every kernel is cached now (daa_sil.runtime.jit_cache.is_warm)
                    mark_ready(CACHE_DIR)
                except OSError:
                    pass
    return t1 - t0, time.perf_counter() - t1


def _import(names) -> None:
    for name in names:
        importlib.import_module(f"{__name__}.{name}")


def _compile_everything() -> None:
    """A cold cache: compile every kernel, the lazy ones too ("ready" means every kernel is in it), with
    :data:`HELPER_MODULES` in a helper process when one can be started: their kernels and the rest take
    about the same time, so two cores compile in ~38 s what one compiles in 54-63 s (docs/daa.md). The
    kernels are the same whichever process compiled them; no file of the cache is written by both."""
    _import(SHARED_MODULES)
    helper = _start_helper()
    mine = [m for m in _MODULES if m not in HELPER_MODULES]
    try:
        _import(m for m in mine if m not in SHARED_MODULES)
        if helper is None:
            _import(HELPER_MODULES)
        for k in lazy_kernels(mine if helper is not None else _MODULES):
            k.compile()
        if helper is not None:
            _finish_helper(*helper)
            _import(HELPER_MODULES)  # loaded from the helper's entries (compiled here if it failed)
            for k in lazy_kernels(HELPER_MODULES):
                k.compile()
    finally:
        if helper is not None and helper[0].is_alive():  # interrupted: the helper goes too
            helper[0].kill()
            helper[0].join()


def _start_helper():
    """The helper process compiling :data:`HELPER_MODULES` (spawned: it imports these sources, with this
    process's ``sys.path``, and dies with this process; it ends before this call returns, so the thread
    that started it outlives it) and the pipe it reports on; None on one core, in a daemonic process (a
    Dask worker), with a cache it could not fill, or if it cannot be started."""

    from daa_sil.runtime.spawned import start_spawned, usable_cpus  # lazy: start-up time

    if usable_cpus() < 2 or mp.current_process().daemon:  # (a daemonic process may not have children: Dask's)
        return None
    if not os.access(CACHE_DIR, os.W_OK):
        return None
    ctx = mp.get_context("spawn")
    conn, child = ctx.Pipe(duplex=False)
    try:
        proc = ctx.Process(target=compile_part, args=(os.getpid(), HELPER_MODULES, str(CACHE_DIR), child),
                           daemon=True, name=HELPER_NAME)
        start_spawned(proc)
    except Exception:  # noqa: BLE001  (no helper: this process compiles everything, as on one core)
        conn.close()
        return None
    finally:
        child.close()
    return proc, conn


def _finish_helper(proc, conn) -> None:
    """Wait for the helper (at most :data:`HELPER_TIMEOUT_S`); if it failed, say so in one line (this process
    then compiles its part)."""
    global HELPER_RC
    with conn:
        proc.join(HELPER_TIMEOUT_S)
        if proc.is_alive():
            proc.kill()
            proc.join()
            why = f"no answer in {HELPER_TIMEOUT_S:g} s"
        else:
            try:
                why = conn.recv() if conn.poll() else "no message"
            except (EOFError, OSError):
                why = "no message"
    HELPER_RC = proc.exitcode
    if HELPER_RC != 0:
        print(f"daa-sil: the kernel compilation helper failed (exit {HELPER_RC}: {why}); compiling its part here",
              file=sys.stderr)


def compile_part(parent_pid: int, names, cache: str, conn) -> None:
    """The helper process of a cold cache: compile the kernel modules ``names`` and their lazy kernels into
    the cache (the process that started it holds the compile lock and loads them afterwards). Exits 1 with
    a one-line reason on ``conn`` if it fails, or if it would not write to ``cache``, the parent's."""

    from daa_sil.runtime.spawned import die_with_parent  # lazy: start-up time

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's (it stops this process)
    die_with_parent(parent_pid, HELPER_NAME)
    try:
        if str(CACHE_DIR) != cache:
            raise RuntimeError(f"its cache would be {CACHE_DIR}, not {cache}")
        skip_blas_probe()
        with without_scipy_linalg():
            _import(names)
            for k in lazy_kernels(names):  # (only these modules': no cache file is written by both processes)
                k.compile()
    except Exception as exc:  # noqa: BLE001  (reported by the parent in one line)
        conn.send(" ".join(f"{type(exc).__name__}: {exc}".split())[:300])
        conn.close()
        sys.exit(1)
    conn.close()


def lazy_kernels(modules=_MODULES) -> list:
    """The :class:`~daa_sil.daa.kernels.jit.LazyKernel` objects of the imported kernel ``modules`` (names; default
    all)."""
    from daa_sil.daa.kernels.jit import LazyKernel  # lazy: start-up time

    mods = [m for m in (sys.modules.get(f"{__name__}.{name}") for name in modules) if m is not None]
    return [v for m in mods for name, v in vars(m).items() if name.endswith("_into") and isinstance(v, LazyKernel)]


def get() -> SimpleNamespace:
    """Every kernel (attributes named as in the kernel modules), compiled or loaded on the first call."""
    global _KERNELS, LOCK_WAIT_S, LOAD_S
    if _KERNELS is not None:
        return _KERNELS
    try:
        LOCK_WAIT_S, LOAD_S = _load(clear=False)
    except Exception as exc:  # noqa: BLE001  (a damaged cache entry: say so, drop the cache, compile again)
        for name in _MODULES:
            sys.modules.pop(f"{__name__}.{name}", None)
        print(f"daa-sil: the compiled-kernel cache {CACHE_DIR} could not be read ({type(exc).__name__}: {exc}); "
              f"recompiling", file=sys.stderr)
        LOCK_WAIT_S, LOAD_S = _load(clear=True)
    # numba's typing of an array argument imports numpy.ma (to refuse masked arrays) at the first call of
    # any kernel: 20-35 ms that would otherwise fall in the first DAA step (a realtime deadline), not here
    import numpy.ma  # lazy: start-up time; noqa: F401
    ns = SimpleNamespace()
    for name in _MODULES:
        mod = sys.modules[f"{__name__}.{name}"]
        for attr in dir(mod):
            if attr.endswith("_into"):
                setattr(ns, attr, getattr(mod, attr))
    _KERNELS = ns
    return ns


def loaded() -> "SimpleNamespace | None":
    """The kernels if this process has loaded them already (:func:`get`), else None: for code that uses
    them only where they are there anyway and never starts numba itself (truth motion, which scenario
    loading and encounter sampling also call)."""
    return _KERNELS


def get_unfused():
    """The kernels of the unfused resolution (:mod:`daa_sil.daa.kernels.unfused`; ``UndecidedPieces`` with
    ``fused=False``, which only the tests take), compiled or loaded on first use -- after :func:`get`,
    under the compile lock -- so that no other process pays for them."""
    name = f"{__name__}.unfused"
    if name not in sys.modules:
        get()
        from daa_sil.daa.kernels.jit import compile_lock  # lazy: start-up time

        with compile_lock(), without_scipy_linalg():
            importlib.import_module(name)
    return sys.modules[name]


__all__ = ["CACHE_DIR", "LOAD_S", "LOCK_WAIT_S", "get", "get_unfused", "lazy_kernels", "loaded", "skip_blas_probe",
           "without_scipy_linalg"]
