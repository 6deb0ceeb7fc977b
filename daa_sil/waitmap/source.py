"""Which wait-map family a ``--waitmap`` value names: a named map preset (:data:`MAP_PRESETS`), a
grid spec, or a directory written by ``waitmap build`` (:func:`family_for`), and what a run records
about it (:func:`describe`). Presets and grid specs are built once and kept by :mod:`.cache`.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Callable

from ..config.settings import WAITMAP
from ..errors import UsageError
from .cache import cached_family, entry_ready
from .grid import Grid, resolve_grid
from .lookup import WaitMapFamily
from .model import PAPER_TURN_RATES, MdpParams, params_hash
from .family_files import load_family


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
    return cached_family(g, p, turn_rates, progress=progress, workers=workers)


def is_cached(source: "str | os.PathLike | None", preset: str = "paper", gamma: "float | None" = None,
              turn_rates=PAPER_TURN_RATES, horizon: "float | None" = None) -> bool:
    """True if :func:`family_for` would load the family (a directory, or a built cache entry)."""
    g, p = check_source(source, preset, gamma, horizon)
    if g is None:
        return True
    return entry_ready(params_hash(g.to_dict(), p, turn_rates), turn_rates)


def family_for(source: "str | os.PathLike | None", preset: str = "paper", gamma: "float | None" = None,
               progress: "Callable[[float], None] | None" = None, horizon: "float | None" = None) -> WaitMapFamily:
    """The wait-map family of a ``--waitmap`` value: a family directory written by ``waitmap build``,
    or a map preset / grid spec (built and cached). ``preset`` is the run's LoWC threshold preset;
    a directory built for another preset is refused. ``gamma`` overrides the discount and ``horizon``
    the wait-time horizon H (s; a reading's ``wait_horizon_s``), both for presets only."""
    if source is not None and Path(str(source)).is_dir():
        if gamma is not None:
            raise UsageError("--gamma applies to a map preset, not to a prebuilt wait-map directory")
        if horizon is not None:
            raise UsageError("a reading's wait_horizon_s applies to a map preset, not to a prebuilt wait-map directory")
        fam = load_family(source)
        if fam.params.preset != preset:
            raise UsageError(f"wait maps in {source} were built for the {fam.params.preset!r} threshold preset; "
                             f"this run uses {preset!r} (rebuild with 'daa-sil waitmap build --preset {preset}')")
        return fam
    g, p = check_source(source, preset, gamma, horizon)
    return default_family(preset, g, p, progress=progress)


def check_source(source: "str | os.PathLike | None", preset: str = "paper", gamma: "float | None" = None,
                 horizon: "float | None" = None):
    """Validate a ``--waitmap`` value without building anything: ``(grid, params)`` of a map preset or
    grid spec (with ``gamma`` / ``horizon`` H, s, overriding the preset's), or ``(None, None)`` for an
    existing directory; one-line UsageError otherwise."""
    if source is not None and Path(str(source)).is_dir():
        return None, None
    name = DEFAULT_MAP if source is None else str(source)
    over = {"gamma": float(gamma)} if gamma is not None else {}
    if horizon is not None:
        over["horizon"] = float(horizon)
    try:
        return map_params(name, preset, **over)
    except UsageError:
        raise UsageError(f"--waitmap {name!r} is not a map preset ({', '.join(MAP_PRESETS)}), a grid spec "
                         f"(paper,dx=24,...), a grid YAML file or a directory from 'daa-sil waitmap build'") from None


def describe(fam: WaitMapFamily) -> dict:
    """What a run records about its wait maps: grid, every parameter, turn rates and content hashes."""
    return {"grid": fam.grid.to_dict(), "params": fam.params.to_dict(),
            "turn_rates_deg": [float(r) for r in fam.turn_rates_deg],
            "content_hashes": [m.content_hash for m in fam.maps]}


__all__ = ["MAP_PRESETS", "DEFAULT_MAP", "map_params", "default_family", "is_cached", "family_for", "check_source",
           "describe"]
