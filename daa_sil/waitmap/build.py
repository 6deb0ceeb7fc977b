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

import numpy as np

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
    w, pl, pa = wait_time(tr, evade, params)
    t3 = time.perf_counter()
    st = stats.to_dict()
    st.update(build_s=t1 - t0, wait_time_s=t3 - t2, total_s=t3 - t0, nnz_spatial=int(tr.spatial.nnz),
              nnz_kinematic=int(tr.kin.nnz), evade_fraction=float(evade.mean()),
              lowc_fraction=float(tr.lowc.mean()))
    shp = grid.shape
    return WaitMap(grid=grid, params=params, turn_rate_deg=float(turn_rate_deg), wait_s=w.reshape(shp),
                   p_lowc=pl.reshape(shp), p_act=pa.reshape(shp), q_wait=q.reshape(shp),
                   q_evade=np.zeros(shp), lowc=tr.lowc.reshape(shp), stats=st)


def build_family(grid: Grid, params: MdpParams, turn_rates=PAPER_TURN_RATES,
                 progress: "Callable[[float], None] | None" = None) -> WaitMapFamily:
    """One map per conditioning turn rate (deg/s); ``progress(rate)`` is called after each map."""
    maps = []
    for r in sorted(float(t) for t in turn_rates):
        maps.append(build_map(grid, params, r))
        if progress:
            progress(r)
    return WaitMapFamily(maps)


def cache_dir() -> Path:
    """``$DAA_SIL_CACHE`` or ``~/.cache/daa-sil``."""
    env = os.environ.get("DAA_SIL_CACHE")
    return Path(env) if env else Path.home() / ".cache" / "daa-sil"


def default_family(preset: str = "paper", grid: "Grid | str | None" = "paper", params: "MdpParams | None" = None,
                   turn_rates=PAPER_TURN_RATES) -> WaitMapFamily:
    """Load the cached family for these settings, building (and caching) it on first use."""
    g = resolve_grid(grid)
    p = params.with_(preset=preset) if params is not None else MdpParams(preset=preset)
    key = params_hash(g.to_dict(), p, turn_rates)
    root = cache_dir() / "waitmaps"
    final = root / key[:24]
    if (final / "family.json").is_file():
        try:
            return load_family(final)
        except FileFormatError:
            shutil.rmtree(final, ignore_errors=True)  # corrupt cache entry: rebuild
    fam = build_family(g, p, turn_rates)
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
