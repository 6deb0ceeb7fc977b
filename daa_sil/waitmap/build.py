"""Building maps and families, and the on-disk cache behind :func:`default_family`.

Cache: ``$DAA_SIL_CACHE`` (or ``~/.cache/daa-sil``) ``/waitmaps/<hash>/`` where ``<hash>`` is the
content hash of the grid, all parameters, the turn-rate list and the file format. A family is built
in a private temporary directory and renamed into place in one step, so concurrent processes either
see a complete family or none; the loser of a race discards its copy and loads the winner's.
"""

from __future__ import annotations

import os
import shutil
import tempfile
import time
from pathlib import Path
from typing import Callable

from ..errors import FileFormatError
from .grid import Grid, resolve_grid
from .lookup import WaitMap, WaitMapFamily
from .model import PAPER_TURN_RATES, MdpParams, params_hash
from .solve import value_iteration, wait_time
from .store import load_family, save_family
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


#: named wait-map configurations: grid preset and wait-time horizon H (s). ``alerting`` is the
#: default: the paper's +-1,500 m box holds about 9 % of the states the agent decides at, so on
#: the paper grid most decisions read a clamped edge value; the alerting grid covers the DO-365
#: alerting region, and its horizon is long enough to reach LoWC from the edge of the box.
MAP_PRESETS = {"paper": ("paper", 60.0), "alerting": ("alerting", 120.0), "fine": ("fine", 60.0)}
DEFAULT_MAP = "alerting"


def cache_dir() -> Path:
    """``$DAA_SIL_CACHE`` or ``~/.cache/daa-sil``."""
    env = os.environ.get("DAA_SIL_CACHE")
    return Path(env) if env else Path.home() / ".cache" / "daa-sil"


def map_params(grid: "str | None", preset: str = "paper", **overrides) -> tuple[Grid, MdpParams]:
    """Grid and parameters of a named map preset (or any grid spec, with H = 60 s), plus overrides."""
    name = DEFAULT_MAP if grid is None else grid
    gname, horizon = MAP_PRESETS.get(str(name), (name, 60.0))
    params = MdpParams(preset=preset, horizon=horizon)
    if overrides:
        params = params.with_(**overrides)
    return resolve_grid(gname), params


def default_family(preset: str = "paper", grid: "Grid | str | None" = None, params: "MdpParams | None" = None,
                   turn_rates=PAPER_TURN_RATES, progress: "Callable[[float], None] | None" = None) -> WaitMapFamily:
    """Load the cached family for these settings, building (and caching) it on first use.

    ``grid`` is a map preset (:data:`MAP_PRESETS`, default :data:`DEFAULT_MAP`), a grid spec or a
    Grid; ``params`` overrides the preset's parameters (its threshold preset is replaced by ``preset``).
    """
    if isinstance(grid, Grid):
        g, p = grid, MdpParams(preset=preset)
    else:
        g, p = map_params(grid, preset)
    if params is not None:
        p = params.with_(preset=preset)
    key = params_hash(g.to_dict(), p, turn_rates)
    root = cache_dir() / "waitmaps"
    final = root / key[:24]
    if (final / "family.json").is_file():
        try:
            return load_family(final)
        except FileFormatError:
            shutil.rmtree(final, ignore_errors=True)  # corrupt cache entry: rebuild
    fam = build_family(g, p, turn_rates, progress=progress)
    root.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{key[:24]}.", dir=root))
    try:
        save_family(fam, tmp, family_hash=key)
        try:
            os.rename(tmp, final)
        except OSError:  # another process finished first (or a stale entry): use theirs
            if (final / "family.json").is_file():
                return load_family(final)
            shutil.rmtree(final, ignore_errors=True)
            os.rename(tmp, final)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return fam


def is_cached(source: "str | os.PathLike | None", preset: str = "paper", gamma: "float | None" = None,
              turn_rates=PAPER_TURN_RATES) -> bool:
    """True if :func:`family_for` would load the family (a directory, or a built cache entry)."""
    g, p = check_source(source, preset, gamma)
    if g is None:
        return True
    return (cache_dir() / "waitmaps" / params_hash(g.to_dict(), p, turn_rates)[:24] / "family.json").is_file()


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
