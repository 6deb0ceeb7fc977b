"""Fast-time Monte Carlo campaigns over the paper's groups (Table 2), chunked over executors.

One code path for every executor: batches of chunks (each task several chunks of several groups
side by side, :mod:`daa_sil.study.campaign.plan`) are submitted to a
:class:`concurrent.futures.Executor` and collected with ``as_completed``, whichever executor it is:

* ``workers=1`` -- in this process, in the calling thread (a task runs as it is submitted, so Ctrl-C
  interrupts it and nothing is left running; :class:`~daa_sil.study.simulation.executors.InlineExecutor`);
* ``workers=K`` -- :class:`~concurrent.futures.ProcessPoolExecutor` (fork; the wait maps are loaded
  once in the parent and inherited);
* ``scheduler="local-dask"`` -- a local Dask ``LocalCluster`` with ``workers`` processes;
* ``scheduler="tcp://host:8786"`` -- an existing Dask cluster, ``Client(addr).get_executor(pure=False)``
  (``pure=False``: otherwise identical arguments would map to one key and run once).

Tasks are submitted a few at a time (:func:`in_flight`: one in this process, two per local worker,
all at once on Dask), so the driver holds only their encounters. Ctrl-C, SIGTERM or an error stop
the workers at once (:mod:`daa_sil.study.simulation.executors`); what was written stays, and ``resume=True``
continues from it.

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
from daa_sil.study.campaign.files import (software_versions, check_out_dir, chunk_done, chunk_paths, chunk_problem,
                                         load_campaign_json, write_chunk)
from daa_sil.study.simulation.executors import make_executor
from daa_sil.study.campaign.files import CAMPAIGN_FORMAT, ChunkResult
from daa_sil.study.campaign.config import CampaignConfig
from daa_sil.study.campaign.plan import DEFAULT_BATCH_ROWS, plan_batches
from daa_sil.study.campaign.sampling import (MIN_SAMPLE_PART, SAMPLE_PIECE, sample_campaign_encounters,
                                             sample_encounter_piece)
from daa_sil import waitmap
from daa_sil.config.readings import Reading
from daa_sil.waitmap import describe
from daa_sil.study.campaign.files import remove_campaign


# --- configuration --------------------------------------------------------------------------------


def encounter_seeds(campaign_seed: int, encounter_ids: np.ndarray) -> np.ndarray:
    """Per-encounter seeds (int64 >= 0): ``SeedSequence(campaign_seed, spawn_key=(i,))`` hashed to 63 bits
    (:func:`daa_sil.models.encounters.encounter_seed`). ``SeedSequence(seed_i)`` is the root of every random
    stream of encounter ``i`` in every group (:func:`daa_sil.models.streams.encounter_streams`), so one
    encounter can be replayed (e.g. in the SIL) from its ``seed`` column alone."""
    from daa_sil.models.encounters import encounter_seed  # lazy: start-up time

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
def _wait_family(source: str, preset: str, gamma: "float | None" = None, horizon: "float | None" = None):
    """The wait-map family of a campaign, loaded once per process (builds the cache if needed)."""

    return waitmap.family_for(source, preset=preset, gamma=gamma, horizon=horizon)


def campaign_family(config: CampaignConfig):
    """The wait-map family a campaign's map groups read (None if no group uses the map): the reading's
    grid and horizon, the campaign's discount."""
    if not config.uses_map:
        return None
    return _wait_family(config.map_source, config.preset, config.gamma, config.map_horizon)


def campaign_wait_lookup(cfg: CampaignConfig, daa_cfg):
    """The wait function a campaign's map groups read: its family under the reading's outside-the-box
    rule (:func:`daa_sil.agent.wait_function.make_wait_lookup`)."""
    from daa_sil.agent.wait_function import make_wait_lookup  # lazy: start-up time

    return make_wait_lookup(campaign_family(cfg), cfg=daa_cfg, outside=cfg.effective_reading.outside)


def simulate_group(cfg: CampaignConfig, group: str, encounters, seeds: np.ndarray, record_steps: bool = False):
    """Fly ``encounters`` (with their ``seeds``) as group ``group`` of campaign ``cfg``: the one place a
    campaign's settings (policy, link legs of the reading's latency rule, pilot, DAA, wait maps and
    the reading's outside-the-box rule) become a :func:`daa_sil.study.simulation.fasttime.simulate` call. Used by
    the campaign runner and by ``daa-sil viz replay``. Returns ``(encounters, decisions, steplog)``."""
    from daa_sil.study.simulation.fasttime import simulate  # lazy: start-up time

    run = cfg.resolve()
    g = run.groups[group]
    lookup = campaign_wait_lookup(cfg, run.daa) if g.uses_map else None
    return simulate(encounters, g.policy, g.legs.up, g.legs.down, run.pilot, daa_cfg=run.daa,
                    wait_lookup=lookup, seeds=seeds, preset=run.preset, duration_s=run.duration_s, dt=run.dt_s,
                    group=group, record_steps=record_steps, link_legs=g.legs, epoch_s=run.epoch_s)


def run_batch(task: BatchTask) -> list[ChunkResult]:
    """Simulate the units of a batch together (pure function of the task; safe in any worker); each
    unit's tables are those of :func:`simulate_group` of the unit alone
    (:func:`daa_sil.study.simulation.fasttime.simulate_parts`)."""
    from daa_sil.study.simulation.fasttime import SimPart, simulate_parts  # lazy: start-up time

    t0 = time.perf_counter()
    cfg = task.config
    run = cfg.resolve()
    parts = []
    for g, c in task.units:
        rg = run.groups[g]
        parts.append(SimPart(task.encounters[c], rg.policy, rg.legs.up, rg.legs.down, task.seeds[c], g, link_legs=rg.legs))
    lookup = campaign_wait_lookup(cfg, run.daa) if any(run.groups[g].uses_map for g, _ in task.units) else None
    tables = simulate_parts(parts, run.pilot, daa_cfg=run.daa, wait_lookup=lookup,
                            preset=run.preset, duration_s=run.duration_s, dt=run.dt_s, epoch_s=run.epoch_s)
    spent = time.perf_counter() - t0
    rows = sum(len(p.encounters) for p in parts)
    return [ChunkResult(g, c, enc, dec, spent * len(p.encounters) / rows, len(p.encounters))
            for (g, c), p, (enc, dec) in zip(task.units, parts, tables)]


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
    from rich.console import Console  # lazy: start-up time
    from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn,
                               TimeRemainingColumn)  # lazy: start-up time

    return Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TextColumn("encounters"),
                    TimeElapsedColumn(), TimeRemainingColumn(), console=Console(stderr=True),
                    disable=not enabled)


def prepare_campaign(config: CampaignConfig, out_dir: "str | os.PathLike", resume: bool = False,
                     executor: "cf.Executor | None" = None, parts: int = 1,
                     on_piece: "Callable[[int], None] | None" = None):
    """Validate, create ``DIR``, write or check ``campaign.json`` and the encounter set.

    Returns ``(out_dir, config, encounter_set)``. On resume the stored config must equal ``config``.
    A new encounter set is sampled in ``parts`` pieces on ``executor`` (:func:`sample_campaign_encounters`,
    which calls ``on_piece``).
    """
    from daa_sil.models.encounter_files import load_encounters, save_encounters  # lazy: start-up time

    config.validate()
    out = check_out_dir(out_dir, resume)
    meta_path = out / "campaign.json"
    enc_path = out / "encounters.parquet"
    if resume and meta_path.is_file():
        stored = CampaignConfig.from_dict(load_campaign_json(out)["config"], str(meta_path))
        if stored != config:
            diff = config.differences(stored)
            raise UsageError(f"--resume: {meta_path} was made with different settings ({', '.join(diff)}); "
                             f"pass the same options or omit them")
        changed = reading_changes(load_campaign_json(out)["config"].get("readings"), config)
        if changed:
            raise UsageError(f"--resume: reading {config.reading!r} has other settings than when {meta_path} was "
                             f"made ({', '.join(changed)}); start a new campaign")
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
    encs = sample_campaign_encounters(config, executor, parts, on_piece)
    save_encounters(encs, enc_path)  # atomic
    from daa_sil.config.basis import basis_records  # lazy: start-up time

    meta = {"format": CAMPAIGN_FORMAT, "config": config.to_dict(), "resolved_config": config.resolved(),
            "basis": basis_records(config.effective_reading),
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


def reading_changes(stored: "dict | None", config: CampaignConfig) -> list[str]:
    """Settings of the campaign's reading that differ from the ones ``campaign.json`` recorded
    (``config.readings``; a setting it lacks counts at its old default). Empty when they agree."""
    if not isinstance(stored, dict):
        return []

    now = config.effective_reading.to_dict()
    then = {**Reading(name=now["name"]).to_dict(), **stored}
    return [k for k in now if k not in ("name", "description") and now[k] != then.get(k)]


def _describe_family(fam) -> dict:
    return describe(fam)


def run_campaign(config: CampaignConfig, out_dir: "str | os.PathLike", *, workers: int = 1,
                 scheduler: "str | None" = None, resume: bool = False, progress: bool = True,
                 on_chunk: "Callable[[ChunkResult], None] | None" = None,
                 batch_rows: int = DEFAULT_BATCH_ROWS, allow_large: bool = False, force: bool = False) -> CampaignSummary:
    """Run (or resume) a campaign into ``out_dir``; see the module docstring for the layout.
    ``batch_rows``: encounter rows per task (:mod:`daa_sil.study.campaign.plan`; results do not
    depend on it). Before anything is sampled, built, started or written: the configuration's ranges,
    ``workers`` (:func:`daa_sil.runtime.resources.check_workers`), ``out_dir`` (a path that can be written,
    not held by another process, empty unless ``resume``; ``force`` replaces a previous campaign's
    files there) and the estimated peak memory (:func:`~daa_sil.study.campaign.memory.campaign_memory`;
    ``allow_large`` runs it even beyond the machine's memory)."""
    from daa_sil.out_dir import claim_out_dir  # lazy: start-up time
    from daa_sil.runtime.resources import check_workers  # lazy: start-up time
    from daa_sil.study.campaign.memory import campaign_memory  # lazy: start-up time

    remote = bool(scheduler) and scheduler != "local-dask"
    if not remote:
        check_workers(workers)
    plan_batches([], workers if isinstance(workers, int) else 1, batch_rows)  # validates batch_rows first
    t_start = time.perf_counter()
    config.validate()
    check_out_dir(out_dir, resume, force)
    campaign_memory(config, workers, batch_rows, remote=remote).check(
        allow_large, "use fewer --encounters, --intruders, --workers or --batch-rows, a shorter --duration"
        + (" or a smaller --waitmap grid" if config.uses_map else ""))
    # the executor starts before anything is written: a missing or unreachable scheduler leaves no files
    with make_executor(workers, scheduler) as ex, \
            claim_out_dir(out_dir, keep=resume, replace=remove_campaign if force else None,
                          hint="pass --resume to continue the campaign there, --force to replace it, or "
                               "choose a new directory"):
        summary = _run_with(ex, config, out_dir, scheduler, resume, progress, on_chunk, workers, batch_rows)
    summary.wall_s = time.perf_counter() - t_start
    return summary


def _run_with(ex: cf.Executor, config: CampaignConfig, out_dir, scheduler, resume: bool, progress: bool,
              on_chunk, workers: int, batch_rows: int) -> CampaignSummary:
    with _progress(progress) as prog:
        sampling = (prog.add_task("sampling   ", total=config.n_encounters)
                    if progress and not (resume and (Path(out_dir) / "encounters.parquet").is_file()) else None)
        out, config, encs = prepare_campaign(config, out_dir, resume, executor=ex, parts=workers,
                                             on_piece=(lambda n: prog.advance(sampling, n)) if sampling is not None
                                             else None)
        if sampling is not None:
            prog.remove_task(sampling)
        return _run_chunks(ex, prog, config, out, encs, scheduler, resume, on_chunk, workers, batch_rows)


def _run_chunks(ex: cf.Executor, prog, config: CampaignConfig, out: Path, encs, scheduler, resume: bool,
                on_chunk, workers: int, batch_rows: int) -> CampaignSummary:
    """Submit the campaign's tasks, a bounded number at a time (:func:`in_flight`), and write each
    chunk as it comes back."""
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
    todo_set = {(g, c) for g, c, _ in todo}
    tasks = iter(plan_batches(todo, workers, batch_rows, min_tasks=2 * workers))
    limit = in_flight(workers, scheduler)
    futs: dict[cf.Future, list] = {}

    def submit_more() -> None:
        while limit is None or len(futs) < limit:
            units = next(tasks, None)
            if units is None:
                return
            chunks = sorted({c for _, c, _ in units})
            task = BatchTask([(g, c) for g, c, _ in units], config,
                             {c: encs.subset(np.arange(*config.chunk_range(c))) for c in chunks},
                             {c: seeds[slice(*config.chunk_range(c))] for c in chunks})
            futs[ex.submit(run_batch, task)] = task.units

    bars = {}
    for g in config.group_names:
        done = sum(config.chunk_range(c)[1] - config.chunk_range(c)[0]
                   for c in range(config.n_chunks) if (g, c) not in todo_set)
        bars[g] = prog.add_task(f"group {g:5s}", total=config.n_encounters, completed=done)
    submit_more()
    while futs:
        finished, _ = cf.wait(list(futs), return_when=cf.FIRST_COMPLETED)
        for fut in finished:
            futs.pop(fut)
            for res in fut.result():
                write_chunk(out, res)
                summary.chunks_run += 1
                summary.compute_s += res.compute_s
                summary.encounter_steps += res.n * steps_per_enc
                prog.advance(bars[res.group], res.n)
                if on_chunk is not None:
                    on_chunk(res)
        submit_more()
    meta = load_campaign_json(out)
    meta["status"] = "complete"
    atomic_write_json(out / "campaign.json", meta)
    return summary


def in_flight(workers: int, scheduler: "str | None") -> "int | None":
    """Tasks submitted at a time: one in this process (``workers=1``: submitting runs it), two per
    worker in a local pool (so none waits for the driver), all at once on a Dask cluster (None)."""
    if scheduler:
        return None
    return 1 if workers <= 1 else 2 * workers


__all__ = ["GroupSpec", "parse_groups", "campaign_family", "CampaignConfig", "encounter_seeds", "campaign_wait_lookup",
           "BatchTask", "ChunkResult", "run_batch", "simulate_group", "chunk_paths", "chunk_done", "write_chunk",
           "load_campaign_json", "check_out_dir", "make_executor", "prepare_campaign", "run_campaign",
           "sample_campaign_encounters", "sample_encounter_piece", "MIN_SAMPLE_PART", "SAMPLE_PIECE", "in_flight",
           "CampaignSummary"]
