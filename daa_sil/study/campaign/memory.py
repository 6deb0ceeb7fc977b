"""A campaign's peak memory, estimated from its sizes before anything is sampled, built or started
(:class:`daa_sil.runtime.resources.MemoryEstimate`; ``campaign run`` and ``campaign sweep`` refuse one that
does not fit the machine unless ``--allow-large``).

The parts, each an upper bound measured on the 2-core benchmark machine (RSS, ``/usr/bin/time``):

* the encounter set, held by the driver: 0.68 kB per encounter with one intruder, 3.4 kB with eight
  (RSS after sampling 100,000 and 40,000 encounters), and a second copy while it is written to
  ``encounters.parquet``: 2 x (:data:`ENCOUNTER_BYTES` + M x :data:`INTRUDER_BYTES`);
* sampling it, one piece of at most :data:`~daa_sil.study.campaign.sampling.SAMPLE_PIECE` encounters
  per worker at a time: 6.5 kB per encounter of a piece with one intruder, 31 kB with eight
  (:data:`SAMPLE_BYTES` + M x :data:`SAMPLE_INTRUDER_BYTES`);
* a task in a worker: its encounter rows x the steps of an encounter x (:data:`ROW_STEP_BYTES` + M x
  :data:`ROW_STEP_INTRUDER_BYTES`) (measured 0.39 GB for 4,000 rows and 0.90 GB for 10,000 rows of
  240 steps, 1.06 GB for 4,000 rows of 960 steps, including the process), plus the process itself;
* the wait maps the map groups read, :data:`daa_sil.waitmap.build.MAP_STATE_BYTES` per state and
  map (shared by forked workers), and their first build when they are not cached yet
  (:func:`daa_sil.waitmap.build.build_memory`).
"""

from __future__ import annotations

from daa_sil.runtime.resources import PROCESS_BASE_BYTES, MemoryEstimate
from daa_sil.study.campaign.sampling import SAMPLE_PIECE
from daa_sil.waitmap.build import MAP_STATE_BYTES
from daa_sil.waitmap.build import build_memory
from daa_sil.waitmap.model import PAPER_TURN_RATES
from daa_sil.waitmap.source import check_source, is_cached

#: bytes per encounter of the encounter set the driver holds, and per intruder of it
ENCOUNTER_BYTES = 1_000
INTRUDER_BYTES = 500
#: bytes per encounter of a piece being sampled, and per intruder of it
SAMPLE_BYTES = 3_000
SAMPLE_INTRUDER_BYTES = 3_600
#: bytes per encounter row and simulated step of a task, and per intruder of it
ROW_STEP_BYTES = 200
ROW_STEP_INTRUDER_BYTES = 40


def task_rows(config, workers: int, batch_rows: int) -> int:
    """The most encounter rows one task holds: about ``batch_rows``, plus one unit (a chunk of a
    group) since units are never split, and never more than the campaign's rows."""
    total = config.n_encounters * len(config.groups)
    return int(min(total, batch_rows + min(config.chunk_size, config.n_encounters)))


def campaign_memory(config, workers: int, batch_rows: int, *, remote: bool = False) -> MemoryEstimate:
    """The estimated peak memory of running ``config`` on ``workers`` local processes (1: in this
    process) with ``batch_rows`` rows per task; ``remote``: the tasks run on a Dask cluster elsewhere,
    so only the driver's part counts here."""
    m = int(config.n_intruders)
    steps = int(round(config.duration_s / config.dt_s))
    n = config.n_encounters
    piece = min(n, SAMPLE_PIECE) * (SAMPLE_BYTES + m * SAMPLE_INTRUDER_BYTES)
    parts = [(f"encounter set ({n:,} x {m} intruder{'s' if m > 1 else ''})", 2 * n * (ENCOUNTER_BYTES + m * INTRUDER_BYTES)),
             ("sampling it", (1 if remote else max(1, workers)) * piece)]
    maps, build = _map_parts(config)
    parts += maps
    task = task_rows(config, workers, batch_rows) * steps * (ROW_STEP_BYTES + m * ROW_STEP_INTRUDER_BYTES)
    if remote:
        parts.append(("driver", PROCESS_BASE_BYTES))
    elif workers <= 1:
        parts.append(("one task in this process", PROCESS_BASE_BYTES + task))
    else:
        parts += [("driver", PROCESS_BASE_BYTES),
                  (f"{workers} workers x {(PROCESS_BASE_BYTES + task) / 2**30:.1f} GiB", workers * (PROCESS_BASE_BYTES + task))]
    parts += build
    return MemoryEstimate("this campaign", tuple(parts))


def _map_parts(config) -> tuple[list, list]:
    """``(loaded maps, first build)`` parts of a campaign whose groups read a wait map ([] otherwise)."""
    if not config.uses_map:
        return [], []

    grid, _ = check_source(config.map_source, config.preset, config.gamma)
    if grid is None:  # a directory from 'waitmap build': its size is what its files hold, loaded once
        return [], []
    rates = len(PAPER_TURN_RATES)
    loaded = [(f"wait maps ({grid.size:,} states x {rates})", grid.size * rates * MAP_STATE_BYTES)]
    if is_cached(config.map_source, config.preset, config.gamma):
        return loaded, []
    return loaded, list(build_memory(grid, rates).parts[:1])  # the finished maps: ``loaded`` above


__all__ = ["ENCOUNTER_BYTES", "INTRUDER_BYTES", "SAMPLE_BYTES", "SAMPLE_INTRUDER_BYTES", "ROW_STEP_BYTES", "ROW_STEP_INTRUDER_BYTES",
           "task_rows", "campaign_memory"]
