"""What ``daa-sil run`` prepares before it starts any process: the compiled DAA kernels and the
vehicle's wait maps, when their caches are cold (so the children load them instead of building them
against their start-up timeouts)."""

from __future__ import annotations

import time
from typing import Callable


def prepare_kernels(say: "Callable[[str], None] | None") -> None:
    """Compile the DAA kernels here when their cache is cold, before the vehicle and the GCS start: they
    then load them instead of compiling on the same cores against their READY timeouts (docs/daa.md,
    "Compiled kernels"). Nothing is imported when the cache is warm."""
    from daa_sil.runtime.jit_cache import COLD_COMPILE_TIME, cache_dir, is_warm  # lazy: start-up time

    if is_warm():
        return
    t = time.monotonic()
    if say:
        say(f"compiling the DAA kernels (first run: {COLD_COMPILE_TIME}; cached in {cache_dir()}) ...")
    from daa_sil.daa import kernels  # lazy: start-up time

    kernels.get()

    if say:
        say(f"DAA kernels ready ({time.monotonic() - t:.1f} s)")


def prepare_waitmap(sc, source: "str | None", say: "Callable[[str], None] | None", allow_large: bool = False) -> None:
    """Build the vehicle's wait maps before any process starts if they are not cached yet, so the
    vehicle loads them from the cache; a bad ``--waitmap`` is a one-line usage error here. A cached
    family is not loaded here: the vehicle loads it once and checks every map's content hash (a
    broken file is its one-line error, relayed by the run). ``say`` gets progress lines."""
    if sc.allocation.wait != "map":
        return
    from daa_sil import waitmap  # lazy: start-up time
    from daa_sil.config.run_config import default_wait_maps  # lazy: start-up time
    from daa_sil.waitmap.build import build_memory  # lazy: start-up time
    from daa_sil.waitmap.model import PAPER_TURN_RATES  # lazy: start-up time
    from daa_sil.waitmap.source import check_source  # lazy: start-up time

    t = time.monotonic()
    source, horizon = (source, None) if source else default_wait_maps()  # the vehicle's, when none is named
    if waitmap.is_cached(source, preset="paper", horizon=horizon):
        return  # the vehicle loads (and verifies) it: loading it here too cost ~0.3 s of every run
    grid, _ = check_source(source, "paper")
    if grid is not None:  # a grid to build: its memory first (one line, nothing built)
        build_memory(grid, len(PAPER_TURN_RATES)).check(allow_large, "use a smaller --waitmap grid")
    if say:
        say(f"loading the MDP wait maps ({source}; the first run builds and caches them) ...")
    progress = (lambda r: say(f"  built the {r:+g} deg/s map ({time.monotonic() - t:.0f} s)")) if say else None
    waitmap.family_for(source, preset="paper", progress=progress, horizon=horizon)
    if say:
        say(f"wait maps ready ({time.monotonic() - t:.1f} s)")


__all__ = ["prepare_kernels", "prepare_waitmap"]
