"""Executors for a campaign's chunks: in-process, a local process pool (fork), or a Dask cluster
(``pip install 'daa-sil[dist]'``). Results do not depend on the executor (every draw is seeded per
encounter)."""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
from typing import Iterator

from daa_sil.errors import UsageError

DASK_HINT = "pip install 'daa-sil[dist]'"


@contextlib.contextmanager
def make_executor(workers: int = 1, scheduler: "str | None" = None) -> Iterator[cf.Executor]:
    """The executor for ``workers``/``scheduler`` (see the module docstring); shut down on exit."""
    if scheduler:
        try:
            from dask.distributed import Client, LocalCluster
        except ImportError:
            raise UsageError(f"--scheduler needs dask.distributed, which is not installed: {DASK_HINT}") from None
        with contextlib.ExitStack() as stack:
            if scheduler == "local-dask":
                cluster = stack.enter_context(LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                                           host="127.0.0.1", dashboard_address=None))
                client = stack.enter_context(Client(cluster))
            else:
                try:
                    client = stack.enter_context(Client(scheduler, timeout="10s"))
                except (OSError, TimeoutError, ValueError) as exc:
                    raise UsageError(f"cannot connect to Dask scheduler {scheduler!r}: {exc}") from None
            ex = client.get_executor(pure=False)
            try:
                yield ex
            finally:
                ex.shutdown(wait=False)
        return
    if workers <= 1:
        ex: cf.Executor = cf.ThreadPoolExecutor(max_workers=1, thread_name_prefix="daa-sil-campaign")
    else:
        import multiprocessing as mp

        ex = cf.ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("fork"))
    try:
        yield ex
    except BaseException:
        ex.shutdown(wait=False, cancel_futures=True)
        raise
    else:
        ex.shutdown(wait=True)
