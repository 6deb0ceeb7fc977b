"""Building maps and families, serially in memory (:func:`build_family`) or one process per map
into a directory (:func:`build_members`). Which family a ``--waitmap`` value names, and the cache
that keeps it, are :mod:`.source` and :mod:`.cache` (both above this module).

The maps of a family are independent, so :func:`build_members` builds them in up to
``min(cores, maps)`` processes at once, each map written atomically as soon as it is finished: an
interrupted build keeps the maps it finished. Each process runs the same :func:`build_map` as the
serial build, so the arrays are bit-identical (``tests/test_waitmap_cache.py``).
"""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path
from typing import Callable, Sequence

from ..errors import DaaSilError, error_class
from daa_sil.runtime.spawned import die_with_parent, start_spawned, usable_cpus
from .grid import Grid
from .lookup import WaitMap, WaitMapFamily
from .model import PAPER_TURN_RATES, MdpParams
from .solve import value_iteration, wait_time
from .store import map_filename, save
from .transitions import build_transitions
import multiprocessing as mp
from multiprocessing.connection import wait


def build_map(grid: Grid, params: MdpParams, turn_rate_deg: float = 0.0) -> WaitMap:
    """Build transitions, solve the MDP and compute wait times for one conditioning turn rate."""
    t0 = time.perf_counter()
    tr = build_transitions(grid, params, turn_rate_deg)
    t1 = time.perf_counter()
    _, q, stats = value_iteration(tr, params)
    evade = (q < 0.0) & ~tr.lowc  # Q_evade = 0 (R_e = 0, OUT terminal)
    t2 = time.perf_counter()
    wf = wait_time(tr, evade, params)
    t3 = time.perf_counter()
    st = stats.to_dict()
    st.update(build_s=t1 - t0, wait_time_s=t3 - t2, total_s=t3 - t0, nnz_spatial=int(tr.spatial.nnz),
              nnz_kinematic=int(tr.kin.nnz), evade_fraction=float(evade.mean()),
              lowc_fraction=float(tr.lowc.mean()),
              threat_fraction=float(((wf.p_lowc >= params.p_min) & ~evade & ~tr.lowc).mean()))
    shp = grid.shape
    return WaitMap(grid=grid, params=params, turn_rate_deg=float(turn_rate_deg), wait_s=wf.wait_s.reshape(shp),
                   p_lowc=wf.p_lowc.reshape(shp), t_lowc=wf.t_lowc.reshape(shp),
                   q_wait=q.reshape(shp), lowc=tr.lowc.reshape(shp), stats=st)


def build_family(grid: Grid, params: MdpParams, turn_rates=PAPER_TURN_RATES,
                 progress: "Callable[[float], None] | None" = None) -> WaitMapFamily:
    """One map per conditioning turn rate (deg/s); ``progress(rate)`` is called after each map."""
    maps = []
    for r in sorted(float(t) for t in turn_rates):
        maps.append(build_map(grid, params, r))
        if progress:
            progress(r)
    return WaitMapFamily(maps)


#: below this many states a map builds in well under the ~1 s a builder process needs to start
#: (interpreter, numpy, scipy), so such families build in this process
MIN_STATES_FOR_PROCESSES = 150_000


def default_workers(n_maps: int, states: int = MIN_STATES_FOR_PROCESSES) -> int:
    """Processes for building ``n_maps`` maps of ``states`` states: ``min(usable cores, n_maps)``,
    or 1 (this process) for maps smaller than :data:`MIN_STATES_FOR_PROCESSES`."""
    if states < MIN_STATES_FOR_PROCESSES:
        return 1
    return max(1, min(usable_cpus(), int(n_maps)))


#: bytes per state of one map being built (transitions, value iteration, wait times): measured 280-520
#: per state (paper grid 72,000 states 517, alerting 1.16 M 280, 2.3 M 304; RSS over the process's own)
BUILD_STATE_BYTES = 520
#: bytes per state of a finished map held in memory (four float64 arrays and the LoWC flags)
MAP_STATE_BYTES = 40
#: what a builder process holds before its map: the interpreter, numpy and scipy (measured 60-100 MB)
BUILDER_BASE_BYTES = 120 * 2**20


def build_memory(grid: Grid, n_maps: int, workers: "int | None" = None):
    """The estimated peak memory of building ``n_maps`` maps of ``grid`` in ``workers`` processes
    (default :func:`default_workers`) and loading the family: a
    :class:`daa_sil.runtime.resources.MemoryEstimate` to ``check()`` before anything is allocated."""
    from daa_sil.runtime.resources import MemoryEstimate  # lazy: start-up time

    n = default_workers(n_maps, grid.size) if workers is None else max(1, min(int(workers), int(n_maps)))
    builders = n * (BUILDER_BASE_BYTES + grid.size * BUILD_STATE_BYTES)
    return MemoryEstimate(f"building {n_maps} wait map{'s' if n_maps != 1 else ''} of {grid.size:,} states",
                          ((f"{n} builder{'s' if n > 1 else ''} x {grid.size:,} states", builders),
                           ("the finished maps", grid.size * n_maps * MAP_STATE_BYTES)))


def build_members(grid: Grid, params: MdpParams, turn_rates: Sequence[float], directory: "str | os.PathLike",
                  workers: "int | None" = None,
                  progress: "Callable[[float], None] | None" = None) -> list[Path]:
    """Build one map per turn rate (deg/s) into ``directory`` (file :func:`~.store.map_filename`),
    each written atomically as soon as it is finished, in ``workers`` processes (default
    :func:`default_workers`; 1 builds in this process). ``progress(rate)`` is called as each map is
    written. On Ctrl-C or an error the processes still building are stopped; the maps already
    written stay. Returns the paths in the order of ``turn_rates``."""
    d = Path(directory)
    rates = [float(r) for r in turn_rates]
    n = default_workers(len(rates), grid.size) if workers is None else max(1, min(int(workers), len(rates)))
    if n == 1:
        for r in rates:
            save(build_map(grid, params, r), d / map_filename(r), overwrite=True)
            if progress:
                progress(r)
    else:
        _build_in_processes(grid, params, rates, d, n, progress)
    return [d / map_filename(r) for r in rates]


def _build_in_processes(grid: Grid, params: MdpParams, rates: list, d: Path, n: int, progress) -> None:
    """``n`` spawned builder processes, each taking the next turn rate as soon as it is free; a
    builder answers each ``(rate, path)`` with ``("ok",)`` or ``("error", class name, message)``."""

    ctx = mp.get_context("spawn")  # no fork of a process that may hold threads (progress bars, the SIL)
    pending, builders, busy = list(rates), [], {}
    try:
        for _ in range(n):
            conn, child = ctx.Pipe()
            proc = ctx.Process(target=_builder_process, args=(os.getpid(), grid, params, child), daemon=True,
                               name=PROCESS_NAME)
            start_spawned(proc)
            child.close()
            builders.append((proc, conn))
        for proc, conn in builders:
            if pending:
                r = pending.pop(0)
                conn.send((r, d / map_filename(r)))
                busy[conn] = (proc, r)
        while busy:
            ready = wait(list(busy) + [proc.sentinel for proc, _ in busy.values()])
            for conn in [c for c in busy if c in ready or busy[c][0].sentinel in ready]:
                proc, r = busy.pop(conn)
                try:
                    msg = conn.recv()
                except (EOFError, OSError):  # ended without a word (killed, crashed)
                    msg = None
                if msg is None or msg[0] != "ok":
                    raise error_class(msg[1] if msg else "")(
                        msg[2] if msg else f"building the {r:+g} deg/s wait map failed: its process ended "
                                           f"with exit code {proc.exitcode}")
                if progress:
                    progress(r)
                if pending:
                    r = pending.pop(0)
                    conn.send((r, d / map_filename(r)))
                    busy[conn] = (proc, r)
    finally:
        for proc, conn in builders:  # done: they exit on EOF; Ctrl-C or an error: stop them now
            if busy:
                proc.terminate()
            conn.close()
        for proc, _ in builders:
            proc.join()


def _builder_process(parent_pid: int, grid: Grid, params: MdpParams, conn) -> None:
    """Body of one builder process: build and save each ``(rate, path)`` received, answer each, and
    exit when the parent closes the pipe. SIGTERM (the parent stopping it) raises SystemExit, so a
    half-written temporary is removed on the way out."""
    die_with_parent(parent_pid, PROCESS_NAME)
    signal.signal(signal.SIGTERM, _exit_on_sigterm)
    while True:
        try:
            rate, path = conn.recv()
        except (EOFError, OSError):
            return
        try:
            save(build_map(grid, params, rate), path, overwrite=True)
            msg: tuple = ("ok",)
        except DaaSilError as exc:
            msg = ("error", type(exc).__name__, str(exc))
        except MemoryError:
            msg = ("error", "OutputError", f"out of memory building the {rate:+g} deg/s wait map")
        except Exception as exc:  # noqa: BLE001 -- reported to the parent, which raises it as one line
            msg = ("error", "DaaSilError", f"building the {rate:+g} deg/s wait map failed: "
                                          f"{type(exc).__name__}: {exc}")
        try:
            conn.send(msg)
        except OSError:  # the parent is gone or stopped listening
            return


def _exit_on_sigterm(signum, frame) -> None:
    raise SystemExit(128 + signum)


#: the name a builder process shows to ``ps`` and ``pgrep`` on Linux (at most 15 characters)
PROCESS_NAME = "daa-sil-waitmap"
