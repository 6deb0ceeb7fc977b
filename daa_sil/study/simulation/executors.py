"""Executors for a campaign's chunks: in this process, a local process pool (fork), or a Dask cluster
(``pip install 'daa-sil[dist]'``). Results do not depend on the executor (every draw is seeded per
encounter).

Signals and stopping (every executor):

* ``workers=1`` runs each task in the calling thread when it is submitted (:class:`InlineExecutor`):
  Ctrl-C interrupts the task itself, and no thread is left for the interpreter to wait for at exit.
* Pool workers ignore Ctrl-C (the terminal sends it to the whole process group; the driver stops
  them), take SIGTERM's default action, and die with the driver, also when it is killed with SIGKILL:
  each arms the kernel's parent-death signal first thing (:func:`daa_sil.runtime.spawned.die_with_parent`,
  as the wait-map builders do). They are forked with Ctrl-C ignored, so none is ever without it.
* When the block that uses the executor is left by an exception (Ctrl-C, SIGTERM, an error), the
  futures are cancelled and the workers stopped at once (SIGTERM, then SIGKILL after
  :data:`STOP_WAIT_S`), with Ctrl-C, SIGTERM and SIGHUP ignored meanwhile, so a second Ctrl-C cannot
  cut the stop short or leave the interpreter waiting for a busy worker.
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import os
import signal
from typing import Iterator

from daa_sil.errors import UsageError
from daa_sil.runtime.spawned import STOP_SIGNALS, die_with_parent, signals_ignored
import multiprocessing as mp
import logging

DASK_HINT = "pip install 'daa-sil[dist]'"
#: the name a pool worker shows to ``ps`` and ``pgrep`` (at most 15 characters)
WORKER_NAME = "daa-sil-worker"
#: seconds a stopped worker gets between SIGTERM and SIGKILL (it holds no file: the driver writes)
STOP_WAIT_S = 2.0


class InlineExecutor(cf.Executor):
    """Runs each task in the calling thread as it is submitted and returns a finished future
    (``workers=1``). An ``Exception`` goes into the future as in any executor; Ctrl-C and other
    ``BaseException`` propagate from :meth:`submit` at once."""

    def submit(self, fn, /, *args, **kwargs) -> cf.Future:
        fut: cf.Future = cf.Future()
        try:
            result = fn(*args, **kwargs)
        except Exception as exc:  # noqa: BLE001 -- delivered through the future, as a pool does
            fut.set_exception(exc)
        else:
            fut.set_result(result)
        return fut


def init_worker(parent_pid: int) -> None:
    """First thing in a pool worker: ignore Ctrl-C, default SIGTERM/SIGHUP (not the driver's handlers,
    which a fork copies), die with the driver and be called :data:`WORKER_NAME`."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    for s in STOP_SIGNALS[1:]:
        signal.signal(s, signal.SIG_DFL)
    die_with_parent(parent_pid, WORKER_NAME)


def stop_pool(ex: cf.ProcessPoolExecutor) -> None:
    """Cancel what has not started and stop the workers now: SIGTERM, SIGKILL after :data:`STOP_WAIT_S`."""
    procs = list((getattr(ex, "_processes", None) or {}).values())  # the stdlib keeps no public list
    ex.shutdown(wait=False, cancel_futures=True)
    for p in procs:
        if p.is_alive():
            p.terminate()
    for p in procs:
        p.join(STOP_WAIT_S)
        if p.is_alive():
            p.kill()
            p.join(STOP_WAIT_S)
    # let the pool's manager thread finish closing its wake-up pipe before the interpreter exits: on
    # Python 3.11 the exit hook can write to it while the thread closes it ("Bad file descriptor")
    manager = getattr(ex, "_executor_manager_thread", None)  # the stdlib keeps no public handle
    if manager is not None:
        manager.join(STOP_WAIT_S)


def start_pool(workers: int) -> cf.ProcessPoolExecutor:
    """A fork pool of ``workers`` processes, started now with Ctrl-C ignored (a fork pool starts all its
    workers at the first submit; :func:`init_worker` then sets their signals)."""

    ex = cf.ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("fork"), initializer=init_worker,
                                initargs=(os.getpid(),))
    try:
        with signals_ignored((signal.SIGINT,)):
            ex.submit(os.getpid).result()
    except BaseException:
        stop_pool(ex)
        raise
    return ex


@contextlib.contextmanager
def make_executor(workers: int = 1, scheduler: "str | None" = None) -> Iterator[cf.Executor]:
    """The executor for ``workers``/``scheduler`` (see the module docstring); shut down on exit."""
    if scheduler:
        yield from _dask_executor(workers, scheduler)
        return
    if workers <= 1:
        yield InlineExecutor()
        return
    ex = start_pool(workers)
    try:
        yield ex
    except BaseException:
        with signals_ignored():
            stop_pool(ex)
        raise
    else:
        ex.shutdown(wait=True)


def _dask_executor(workers: int, scheduler: str) -> Iterator[cf.Executor]:
    try:
        from dask.distributed import Client, LocalCluster  # lazy: optional dependency
    except ImportError:
        raise UsageError(f"--scheduler needs dask.distributed, which is not installed: {DASK_HINT}") from None
    stack = contextlib.ExitStack()
    try:
        if scheduler == "local-dask":
            with signals_ignored((signal.SIGINT,)):  # its processes start with Ctrl-C ignored (the driver stops them)
                cluster = stack.enter_context(LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                                           host="127.0.0.1", dashboard_address=None,
                                                           silence_logs=logging.ERROR))
            client = stack.enter_context(Client(cluster))
        else:
            try:
                client = stack.enter_context(Client(scheduler, timeout="10s"))
            except (OSError, TimeoutError, ValueError) as exc:
                raise UsageError(f"cannot connect to Dask scheduler {scheduler!r}: {exc}") from None
        ex = client.get_executor(pure=False)
    except BaseException:
        with signals_ignored():
            stack.close()
        raise
    try:
        yield ex
    except BaseException:
        with signals_ignored():  # cancel the futures and close the local cluster (its workers with it)
            ex.shutdown(wait=False)
            stack.close()
        raise
    else:
        ex.shutdown(wait=False)
        stack.close()


__all__ = ["DASK_HINT", "WORKER_NAME", "STOP_WAIT_S", "InlineExecutor", "init_worker", "stop_pool",
           "start_pool", "make_executor"]
