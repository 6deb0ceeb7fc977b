"""Fast-time Monte Carlo campaigns over the paper's groups (Table 2), chunked over executors.

One code path for every executor: batches of chunks (each task several chunks of several groups
side by side, :mod:`daa_sil.study.campaign_plan`) are submitted to a
:class:`concurrent.futures.Executor` and collected with ``as_completed``, whichever executor it is:

* ``workers=1`` -- in-process (one worker thread, so the progress bar stays live);
* ``workers=K`` -- :class:`~concurrent.futures.ProcessPoolExecutor` (fork; the wait maps are loaded
  once in the parent and inherited);
* ``scheduler="local-dask"`` -- a local Dask ``LocalCluster`` with ``workers`` processes;
* ``scheduler="tcp://host:8786"`` -- an existing Dask cluster, ``Client(addr).get_executor(pure=False)``
  (``pure=False``: otherwise identical arguments would map to one key and run once).

Determinism: the encounter set is generated once from the campaign seed and saved as
``DIR/encounters.parquet``; every random stream of encounter ``i`` (pilot, uplink and downlink delay)
comes from the encounter's own seed (:func:`encounter_seeds`), the same for every group (common
random numbers), never from the chunk, and the DAA gives every encounter what a call of its own
gives. Results therefore do not depend on chunking, batching, worker count, executor or
interruption: a killed campaign resumed with ``resume=True`` skips complete chunks (each checked
against its checksum file; a damaged one is named in a warning and computed again) and ends with
exactly the tables of an uninterrupted run. The chunk size names the result files, so it is
recorded (``campaign.json``) and checked on resume.

Layout of ``DIR``::

    campaign.json                      config, versions, preset, seed, status
    encounters.parquet                 the encounter set (daa_sil.models.encounters format)
    <group>/decisions-<chunk>.parquet  per-decision rows of one chunk
    <group>/encounters-<chunk>.parquet per-encounter rows of one chunk
    <group>/chunk-<chunk>.sha256       SHA-256 of the chunk's two tables (sha256sum format), written
                                       last: a chunk is done when it exists and both tables match it

Each file is written atomically by the driver (workers only compute and return Arrow tables, so a
remote Dask cluster needs no shared file system).
"""

from __future__ import annotations

import concurrent.futures as cf
import functools
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import pyarrow as pa

from daa_sil.errors import FileFormatError, UsageError, warn
from daa_sil.files import atomic_write_json, ensure_dir, remove_stale_temps
from daa_sil.config.groups import GroupSpec, parse_groups
from daa_sil.study.campaign_files import (software_versions, check_out_dir, chunk_done, chunk_paths, chunk_problem,
                                         load_campaign_json, write_chunk)
from daa_sil.study.executors import make_executor
from daa_sil.study.campaign_files import CAMPAIGN_FORMAT, ChunkResult
from daa_sil.study.campaign_config import CampaignConfig
from daa_sil.study.campaign_plan import DEFAULT_BATCH_ROWS, plan_batches


# --- configuration --------------------------------------------------------------------------------


def encounter_seeds(campaign_seed: int, encounter_ids: np.ndarray) -> np.ndarray:
    """Per-encounter seeds (int64 >= 0): ``SeedSequence(campaign_seed, spawn_key=(i,))`` hashed to 63 bits
    (:func:`daa_sil.models.encounters.encounter_seed`). ``SeedSequence(seed_i)`` is the root of every random
    stream of encounter ``i`` in every group (:func:`daa_sil.models.streams.encounter_streams`), so one
    encounter can be replayed (e.g. in the SIL) from its ``seed`` column alone."""
    from daa_sil.models.encounters import encounter_seed

    return encounter_seed(int(campaign_seed), encounter_ids)


# --- tasks (run in a worker) -----------------------------------------------------------------------
@dataclass
class BatchTask:
    """Chunks of groups simulated side by side in one batch: the work unit sent to an executor (small,
    picklable).
    ``units`` are ``(group, chunk)``; ``encounters``/``seeds`` hold each chunk's subset once."""

    units: list
    config: CampaignConfig
    encounters: dict  # chunk -> EncounterSet subset for [lo, hi)
    seeds: dict  # chunk -> (n,) int64 per-encounter seeds


@functools.lru_cache(maxsize=4)
def _wait_family(source: str, preset: str, gamma: "float | None" = None):
    """The wait-map family of a campaign, loaded once per process (builds the cache if needed)."""
    from daa_sil import waitmap

    return waitmap.family_for(source, preset=preset, gamma=gamma)


def campaign_family(config: CampaignConfig):
    """The wait-map family a campaign's map groups read (None if no group uses the map)."""
    return _wait_family(config.map_source, config.preset, config.gamma) if config.uses_map else None


def campaign_wait_lookup(cfg: CampaignConfig, daa_cfg):
    """The wait function a campaign's map groups read: its family under the reading's outside-the-box
    rule (:func:`daa_sil.wait_function.make_wait_lookup`)."""
    from daa_sil.wait_function import make_wait_lookup

    return make_wait_lookup(campaign_family(cfg), cfg=daa_cfg, outside=cfg.effective_reading.outside)


def simulate_group(cfg: CampaignConfig, group: str, encounters, seeds: np.ndarray, record_steps: bool = False):
    """Fly ``encounters`` (with their ``seeds``) as group ``group`` of campaign ``cfg``: the one place a
    campaign's settings (policy, link legs of the reading's latency rule, pilot, DAA, wait maps and
    the reading's outside-the-box rule) become a :func:`daa_sil.study.fasttime.simulate` call. Used by
    the campaign runner and by ``daa-sil viz replay``. Returns ``(encounters, decisions, steplog)``."""
    from .fasttime import simulate

    legs = cfg.link_legs(group)
    daa_cfg = cfg.daa_config()
    lookup = campaign_wait_lookup(cfg, daa_cfg) if cfg.group(group).uses_map else None
    return simulate(encounters, cfg.policy(group), legs.up, legs.down, cfg.pilot_config(), daa_cfg=daa_cfg,
                    wait_lookup=lookup, seeds=seeds, preset=cfg.preset, duration_s=cfg.duration_s, dt=cfg.dt_s,
                    group=group, record_steps=record_steps, link_legs=legs)


def run_batch(task: BatchTask) -> list[ChunkResult]:
    """Simulate the units of a batch together (pure function of the task; safe in any worker); each
    unit's tables are those of :func:`simulate_group` of the unit alone
    (:func:`daa_sil.study.fasttime.simulate_parts`)."""
    from .fasttime import SimPart, simulate_parts

    t0 = time.perf_counter()
    cfg = task.config
    parts = []
    for g, c in task.units:
        legs = cfg.link_legs(g)
        parts.append(SimPart(task.encounters[c], cfg.policy(g), legs.up, legs.down, task.seeds[c], g, link_legs=legs))
    daa_cfg = cfg.daa_config()
    lookup = campaign_wait_lookup(cfg, daa_cfg) if any(cfg.group(g).uses_map for g, _ in task.units) else None
    tables = simulate_parts(parts, cfg.pilot_config(), daa_cfg=daa_cfg, wait_lookup=lookup,
                            preset=cfg.preset, duration_s=cfg.duration_s, dt=cfg.dt_s)
    spent = time.perf_counter() - t0
    rows = sum(len(p.encounters) for p in parts)
    return [ChunkResult(g, c, enc, dec, spent * len(p.encounters) / rows, len(p.encounters))
            for (g, c), p, (enc, dec) in zip(task.units, parts, tables)]


# --- files ----------------------------------------------------------------------------------------


# --- executors ------------------------------------------------------------------------------------


# --- the runner -----------------------------------------------------------------------------------
@dataclass
class CampaignSummary:
    """What a run did: chunks computed/skipped/found damaged, wall time (s), encounter-steps simulated."""

    out_dir: Path
    config: CampaignConfig
    chunks_total: int
    chunks_skipped: int
    chunks_run: int
    wall_s: float
    compute_s: float
    encounter_steps: int
    groups: dict = field(default_factory=dict)
    chunks_damaged: list = field(default_factory=list)  # "<group>/<chunk>" found damaged and computed again


def _progress(enabled: bool):
    from rich.console import Console
    from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn,
                               TimeRemainingColumn)

    return Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TextColumn("encounters"),
                    TimeElapsedColumn(), TimeRemainingColumn(), console=Console(stderr=True),
                    disable=not enabled)


#: fewest encounters worth a piece of their own in :func:`sample_campaign_encounters`
MIN_SAMPLE_PART = 500


def sample_campaign_encounters(config: CampaignConfig, executor: "cf.Executor | None" = None, parts: int = 1):
    """The campaign's encounter set (paper Table 6, CPA at T/2), sampled in ``parts`` pieces of
    consecutive encounters on ``executor`` when given (one piece per worker: sampling 10,000 encounters
    takes about 9 s of one core, a fifth of a five-group campaign's wall time, while the others waited).

    Each encounter is drawn from its own random stream and its geometry is computed element-wise, so
    the pieces concatenated are the set sampled at once (``tests/test_encounters.py``)."""
    from daa_sil.models import encounters as enc_mod

    kw = dict(seed=config.seed, preset=config.preset, duration_s=config.duration_s, dt_s=config.dt_s,
              t_cpa_s=config.duration_s / 2.0,  # paper: CPA at T/2
              n_intruders=config.n_intruders, **config.effective_reading.encounter_overrides())
    n = config.n_encounters
    bounds = np.linspace(0, n, max(1, min(int(parts), n // MIN_SAMPLE_PART)) + 1).astype(np.int64)
    if executor is None or bounds.size <= 2:
        return enc_mod.sample_encounters(n, **kw)
    futs = [executor.submit(sample_encounter_piece, int(hi - lo), int(lo), kw) for lo, hi in zip(bounds[:-1], bounds[1:])]
    return enc_mod.concat_encounters([f.result() for f in futs])


def sample_encounter_piece(n: int, start: int, kw: dict):
    """Encounters ``start .. start+n-1`` on a worker, which loads the compiled kernels first (it does for
    its chunks anyway): the realised-CPA integration then flies the compiled ``advance``, the same numbers
    (2,000 encounters: 1.8 -> 0.7 s CPU)."""
    from daa_sil.daa import kernels
    from daa_sil.models import encounters as enc_mod

    kernels.get()
    return enc_mod.sample_encounters(n, start=start, **kw)


def prepare_campaign(config: CampaignConfig, out_dir: "str | os.PathLike", resume: bool = False,
                     executor: "cf.Executor | None" = None, parts: int = 1):
    """Validate, create ``DIR``, write or check ``campaign.json`` and the encounter set.

    Returns ``(out_dir, config, encounter_set)``. On resume the stored config must equal ``config``.
    A new encounter set is sampled in ``parts`` pieces on ``executor`` (:func:`sample_campaign_encounters`).
    """
    from daa_sil.models.encounter_files import load_encounters, save_encounters

    config.validate()
    out = check_out_dir(out_dir, resume)
    meta_path = out / "campaign.json"
    enc_path = out / "encounters.parquet"
    if resume and meta_path.is_file():
        stored = CampaignConfig.from_dict(load_campaign_json(out)["config"], str(meta_path))
        if stored != config:
            diff = [k for k in config.to_dict() if config.to_dict()[k] != stored.to_dict()[k]]
            raise UsageError(f"--resume: {meta_path} was made with different settings ({', '.join(diff)}); "
                             f"pass the same options or omit them")
        if not enc_path.is_file():
            raise FileFormatError(f"{enc_path} is missing; cannot resume this campaign")
        stored_map = load_campaign_json(out).get("waitmap")
        fam = campaign_family(config)
        if stored_map and fam is not None and stored_map.get("content_hashes") != _describe_family(fam)["content_hashes"]:
            raise UsageError(f"--resume: the wait maps of {config.map_source!r} are not the ones this campaign started with "
                             f"(their content hashes differ: rebuilt with other code or parameters); start a new campaign")
        encs = load_encounters(enc_path)
        if len(encs) != config.n_encounters:
            raise FileFormatError(f"{enc_path} holds {len(encs)} encounters, campaign.json says {config.n_encounters}")
        return out, config, encs
    fam = campaign_family(config)  # built (or loaded) before anything is written
    ensure_dir(out)
    encs = sample_campaign_encounters(config, executor, parts)
    save_encounters(encs, enc_path)  # atomic
    meta = {"format": CAMPAIGN_FORMAT, "config": config.to_dict(), "resolved_config": config.resolved(),
            "versions": software_versions(),
            "preset": config.preset, "seed": config.seed, "status": "running",
            "seeds": {"campaign": config.seed,
                      "encounters": "encounter i: SeedSequence(campaign, spawn_key=(i,)); its 'seed' column in "
                                    "encounters.parquet roots the pilot, uplink and downlink streams of every group"},
            "groups": {g.name: g.to_dict() for g in config.effective_groups},
            "waitmap": ({"source": config.map_source, **_describe_family(fam)} if fam is not None else None),
            "layout": {"encounters": "<group>/encounters-<chunk>.parquet",
                       "decisions": "<group>/decisions-<chunk>.parquet",
                       "checksums": "<group>/chunk-<chunk>.sha256", "chunk_size": config.chunk_size}}
    atomic_write_json(meta_path, meta)
    return out, config, encs


def _describe_family(fam) -> dict:
    from daa_sil.waitmap import describe

    return describe(fam)


def run_campaign(config: CampaignConfig, out_dir: "str | os.PathLike", *, workers: int = 1,
                 scheduler: "str | None" = None, resume: bool = False, progress: bool = True,
                 on_chunk: "Callable[[ChunkResult], None] | None" = None,
                 batch_rows: int = DEFAULT_BATCH_ROWS) -> CampaignSummary:
    """Run (or resume) a campaign into ``out_dir``; see the module docstring for the layout.
    ``batch_rows``: encounter rows per task (:mod:`daa_sil.study.campaign_plan`; results do not
    depend on it)."""
    if not isinstance(workers, int) or workers < 1:
        raise UsageError(f"--workers must be a positive integer, got {workers!r}")
    plan_batches([], workers, batch_rows)  # validates batch_rows before anything starts
    t_start = time.perf_counter()
    config.validate()
    check_out_dir(out_dir, resume)
    # the executor starts before anything is written: a missing or unreachable scheduler leaves no files
    with make_executor(workers, scheduler) as ex:
        summary = _run_with(ex, config, out_dir, scheduler, resume, progress, on_chunk, workers, batch_rows)
    summary.wall_s = time.perf_counter() - t_start
    return summary


def _run_with(ex: cf.Executor, config: CampaignConfig, out_dir, scheduler, resume: bool, progress: bool,
              on_chunk, workers: int, batch_rows: int) -> CampaignSummary:
    out, config, encs = prepare_campaign(config, out_dir, resume, executor=ex, parts=workers)
    if resume:
        remove_stale_temps(out)  # temporaries of a writer killed mid-write
    seeds = np.asarray(encs.seed, dtype=np.int64)
    todo, skipped, damaged, unsummed = [], 0, [], []
    for c in range(config.n_chunks):  # (chunk, group) order: every task gets a mix of groups
        for g in config.group_names:
            why = chunk_problem(out, g, c)
            if why is None:
                skipped += 1
                continue
            lo, hi = config.chunk_range(c)
            todo.append((g, c, hi - lo))
            if why != "missing":
                damaged.append(f"{g}/{c}")
                warn(f"chunk {c} of group {g} in {out} is damaged ({why}); computing it again")
            elif chunk_paths(out, g, c)[0].is_file():
                unsummed.append(f"{g}/{c}")
    if unsummed:
        warn(f"{len(unsummed)} chunk(s) have tables but no checksum file (the writer was stopped before it, or an "
             f"older daa-sil wrote them): computing {', '.join(unsummed[:5])}{' ...' if len(unsummed) > 5 else ''} again")
    if any(config.group(g).uses_map for g, _, _ in todo) and scheduler is None:
        campaign_family(config)  # build/load once here; forked workers inherit it
    summary = CampaignSummary(out, config, config.n_chunks * len(config.group_names), skipped, 0, 0.0, 0.0, 0,
                              chunks_damaged=damaged)
    steps_per_enc = int(round(config.duration_s / config.dt_s))
    futs: dict[cf.Future, list] = {}
    subsets: dict = {}
    for units in plan_batches(todo, workers, batch_rows, min_tasks=2 * workers):
        chunks = sorted({c for _, c, _ in units})
        for c in chunks:
            if c not in subsets:
                lo, hi = config.chunk_range(c)
                subsets[c] = encs.subset(np.arange(lo, hi))
        task = BatchTask([(g, c) for g, c, _ in units], config, {c: subsets[c] for c in chunks},
                         {c: seeds[slice(*config.chunk_range(c))] for c in chunks})
        futs[ex.submit(run_batch, task)] = task.units
    todo_set = {(g, c) for g, c, _ in todo}
    with _progress(progress) as prog:
        bars = {}
        for g in config.group_names:
            done = sum(config.chunk_range(c)[1] - config.chunk_range(c)[0]
                       for c in range(config.n_chunks) if (g, c) not in todo_set)
            bars[g] = prog.add_task(f"group {g:5s}", total=config.n_encounters, completed=done)
        for fut in cf.as_completed(list(futs)):
            futs.pop(fut)
            for res in fut.result():
                write_chunk(out, res)
                summary.chunks_run += 1
                summary.compute_s += res.compute_s
                summary.encounter_steps += res.n * steps_per_enc
                prog.advance(bars[res.group], res.n)
                if on_chunk is not None:
                    on_chunk(res)
    meta = load_campaign_json(out)
    meta["status"] = "complete"
    atomic_write_json(out / "campaign.json", meta)
    return summary


__all__ = ["GroupSpec", "parse_groups", "campaign_family", "CampaignConfig", "encounter_seeds", "campaign_wait_lookup",
           "BatchTask", "ChunkResult", "run_batch", "simulate_group", "chunk_paths", "chunk_done", "write_chunk",
           "load_campaign_json", "check_out_dir", "make_executor", "prepare_campaign", "run_campaign",
           "sample_campaign_encounters", "sample_encounter_piece", "MIN_SAMPLE_PART",
           "CampaignSummary"]
