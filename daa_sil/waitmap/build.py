"""Building maps and families, serially in memory (:func:`build_family`) or one process per map
into a directory (:func:`build_members`), and the named map presets behind ``--waitmap``.

The maps of a family are independent, so :func:`build_members` builds them in up to
``min(cores, maps)`` processes at once, each map written atomically as soon as it is finished: an
interrupted build keeps the maps it finished. Each process runs the same :func:`build_map` as the
serial build, so the arrays are bit-identical (``tests/test_waitmap_cache.py``). The on-disk cache
behind :func:`default_family` is :mod:`.cache`.
"""

from __future__ import annotations

import os
import signal
import sys
import time
import types
from pathlib import Path
from typing import Callable, Sequence

from ..config.settings import WAITMAP
from ..errors import DaaSilError, error_class
from .grid import Grid, resolve_grid
from .lookup import WaitMap, WaitMapFamily
from .model import PAPER_TURN_RATES, MdpParams, params_hash
from .solve import value_iteration, wait_time
from .store import load_family, map_filename, save
from .transitions import build_transitions


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
    try:
        cores = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        cores = os.cpu_count() or 1
    return max(1, min(cores, int(n_maps)))


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
    import multiprocessing as mp
    from multiprocessing.connection import wait

    ctx = mp.get_context("spawn")  # no fork of a process that may hold threads (progress bars, the SIL)
    pending, builders, busy = list(rates), [], {}
    try:
        for _ in range(n):
            conn, child = ctx.Pipe()
            proc = ctx.Process(target=_builder_process, args=(os.getpid(), grid, params, child), daemon=True,
                               name=PROCESS_NAME)
            _start_builder(proc)
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


def _start_builder(proc) -> None:
    """Start ``proc`` (spawn context) as a builder that needs nothing from this process's main script.

    * SIGINT is ignored from the child's first instruction (a spawned interpreter keeps an inherited
      SIG_IGN), so Ctrl-C reaches only this process, which stops the builders itself.
    * ``spawn`` normally re-runs the parent's main script in the child. A script that calls
      :func:`default_family` without an ``if __name__ == "__main__"`` guard would then wait in the
      child for the cache lock its parent holds (a deadlock), and ``python - < script`` has no
      script to re-run at all. The builder needs only this module, so the main module is hidden
      while the child's start-up data is taken.
    """
    main = sys.modules.get("__main__")
    sys.modules["__main__"] = types.ModuleType("__main__")
    try:
        old = signal.signal(signal.SIGINT, signal.SIG_IGN)
    except ValueError:  # not the main thread: signals are the main thread's business
        old = None
    try:
        proc.start()
    finally:
        if old is not None:
            signal.signal(signal.SIGINT, old)
        if main is not None:
            sys.modules["__main__"] = main


def _builder_process(parent_pid: int, grid: Grid, params: MdpParams, conn) -> None:
    """Body of one builder process: build and save each ``(rate, path)`` received, answer each, and
    exit when the parent closes the pipe. SIGTERM (the parent stopping it) raises SystemExit, so a
    half-written temporary is removed on the way out."""
    _die_with_parent(parent_pid)
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


def _die_with_parent(parent_pid: int) -> None:
    """Linux: have the kernel SIGKILL this process when its parent dies (``PR_SET_PDEATHSIG``), name
    it :data:`PROCESS_NAME`, and exit at once if the parent is already gone. Elsewhere a daemonic
    child is stopped when its parent exits normally; a killed parent leaves it to finish its one map
    and exit."""
    if sys.platform.startswith("linux"):
        try:
            import ctypes

            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(1, int(signal.SIGKILL), 0, 0, 0)  # 1 = PR_SET_PDEATHSIG
            libc.prctl(15, ctypes.c_char_p(PROCESS_NAME.encode()), 0, 0, 0)  # 15 = PR_SET_NAME: pgrep finds it
        except (OSError, AttributeError):
            pass
    if os.getppid() != parent_pid:
        os._exit(1)


#: named wait-map configurations: grid preset and wait-time horizon H (s). ``alerting`` is the
#: default: the paper's +-1,500 m box holds about 9 % of the states the agent decides at, so on
#: the paper grid most decisions read a clamped edge value; the alerting grid covers the DO-365
#: alerting region, and its horizon is long enough to reach LoWC from the edge of the box.
MAP_PRESETS = {"paper": ("paper", 60.0), "alerting": ("alerting", 120.0), "fine": ("fine", 60.0)}
DEFAULT_MAP = WAITMAP.default


def map_params(grid: "str | None", preset: str = "paper", **overrides) -> tuple[Grid, MdpParams]:
    """Grid and parameters of a named map preset (or any grid spec, with H = 60 s), plus overrides."""
    name = DEFAULT_MAP if grid is None else grid
    gname, horizon = MAP_PRESETS.get(str(name), (name, 60.0))
    params = MdpParams(preset=preset, horizon=horizon)
    if overrides:
        params = params.with_(**overrides)
    return resolve_grid(gname), params


def default_family(preset: str = "paper", grid: "Grid | str | None" = None, params: "MdpParams | None" = None,
                   turn_rates=PAPER_TURN_RATES, progress: "Callable[[float], None] | None" = None,
                   workers: "int | None" = None) -> WaitMapFamily:
    """Load the cached family for these settings, building (and caching) it on first use, or
    repairing it (:mod:`.cache`); ``workers`` as in :func:`build_members`.

    ``grid`` is a map preset (:data:`MAP_PRESETS`, default :data:`DEFAULT_MAP`), a grid spec or a
    Grid; ``params`` overrides the preset's parameters (its threshold preset is replaced by ``preset``).
    """
    if isinstance(grid, Grid):
        g, p = grid, MdpParams(preset=preset)
    else:
        g, p = map_params(grid, preset)
    if params is not None:
        p = params.with_(preset=preset)
    from .cache import cached_family

    return cached_family(g, p, turn_rates, progress=progress, workers=workers)


def is_cached(source: "str | os.PathLike | None", preset: str = "paper", gamma: "float | None" = None,
              turn_rates=PAPER_TURN_RATES) -> bool:
    """True if :func:`family_for` would load the family (a directory, or a built cache entry)."""
    from .cache import entry_ready

    g, p = check_source(source, preset, gamma)
    if g is None:
        return True
    return entry_ready(params_hash(g.to_dict(), p, turn_rates), turn_rates)


def family_for(source: "str | os.PathLike | None", preset: str = "paper", gamma: "float | None" = None,
               progress: "Callable[[float], None] | None" = None) -> WaitMapFamily:
    """The wait-map family of a ``--waitmap`` value: a family directory written by ``waitmap build``,
    or a map preset / grid spec (built and cached). ``preset`` is the run's LoWC threshold preset;
    a directory built for another preset is refused. ``gamma`` overrides the discount (presets only)."""
    from ..errors import UsageError

    if source is not None and Path(str(source)).is_dir():
        if gamma is not None:
            raise UsageError("--gamma applies to a map preset, not to a prebuilt wait-map directory")
        fam = load_family(source)
        if fam.params.preset != preset:
            raise UsageError(f"wait maps in {source} were built for the {fam.params.preset!r} threshold preset; "
                             f"this run uses {preset!r} (rebuild with 'daa-sil waitmap build --preset {preset}')")
        return fam
    g, p = check_source(source, preset, gamma)
    return default_family(preset, g, p, progress=progress)


def check_source(source: "str | os.PathLike | None", preset: str = "paper", gamma: "float | None" = None):
    """Validate a ``--waitmap`` value without building anything: ``(grid, params)`` of a map preset or
    grid spec, or ``(None, None)`` for an existing directory; one-line UsageError otherwise."""
    from ..errors import UsageError

    if source is not None and Path(str(source)).is_dir():
        return None, None
    name = DEFAULT_MAP if source is None else str(source)
    try:
        return map_params(name, preset, **({"gamma": float(gamma)} if gamma is not None else {}))
    except UsageError:
        raise UsageError(f"--waitmap {name!r} is not a map preset ({', '.join(MAP_PRESETS)}), a grid spec "
                         f"(paper,dx=24,...), a grid YAML file or a directory from 'daa-sil waitmap build'") from None


def describe(fam: WaitMapFamily) -> dict:
    """What a run records about its wait maps: grid, every parameter, turn rates and content hashes."""
    return {"grid": fam.grid.to_dict(), "params": fam.params.to_dict(),
            "turn_rates_deg": [float(r) for r in fam.turn_rates_deg],
            "content_hashes": [m.content_hash for m in fam.maps]}
