"""A campaign's encounter set, sampled in pieces on the campaign's executor (paper Table 6, CPA at
T/2): one piece per worker, and pieces of at most :data:`SAMPLE_PIECE` encounters, so that a large set
shows progress and each worker's memory stays bounded."""

from __future__ import annotations

import concurrent.futures as cf
from typing import Callable

import numpy as np

from daa_sil.study.campaign.config import CampaignConfig


#: fewest encounters worth a piece of their own in :func:`sample_campaign_encounters`
MIN_SAMPLE_PART = 500
#: most encounters of one piece when sampling on an executor (about 10 s of a core, 0.1-0.6 GB):
#: a large set is sampled piece by piece, with progress and its memory bounded per worker
SAMPLE_PIECE = 20_000


def sample_campaign_encounters(config: CampaignConfig, executor: "cf.Executor | None" = None, parts: int = 1,
                               on_piece: "Callable[[int], None] | None" = None):
    """The campaign's encounter set (paper Table 6, CPA at T/2), sampled in ``parts`` pieces of
    consecutive encounters on ``executor`` when given (one piece per worker: sampling 10,000 encounters
    takes about 9 s of one core, a fifth of a five-group campaign's wall time, while the others waited),
    and in pieces of at most :data:`SAMPLE_PIECE` encounters; ``on_piece(n)`` is called as each is done.

    Each encounter is drawn from its own random stream and its geometry is computed element-wise, so
    the pieces concatenated are the set sampled at once (``tests/test_encounters.py``)."""
    from daa_sil.models import encounters as enc_mod  # lazy: start-up time

    kw = dict(seed=config.seed, preset=config.preset, duration_s=config.duration_s, dt_s=config.dt_s,
              t_cpa_s=config.duration_s / 2.0,  # paper: CPA at T/2
              n_intruders=config.n_intruders, **config.effective_reading.encounter_overrides())
    n = config.n_encounters
    pieces = max(int(parts), -(-n // SAMPLE_PIECE))
    bounds = np.linspace(0, n, max(1, min(pieces, n // MIN_SAMPLE_PART)) + 1).astype(np.int64)
    if executor is None or bounds.size <= 2:
        encs = enc_mod.sample_encounters(n, **kw)
        if on_piece is not None:
            on_piece(n)
        return encs
    futs, told = [], set()
    for lo, hi in zip(bounds[:-1], bounds[1:]):
        futs.append(executor.submit(sample_encounter_piece, int(hi - lo), int(lo), kw))
        if on_piece is not None and futs[-1].done():  # an executor that runs a task as it is submitted
            told.add(futs[-1])
            on_piece(len(futs[-1].result()))
    if on_piece is not None:
        for f in cf.as_completed([f for f in futs if f not in told]):
            on_piece(len(f.result()))
    return enc_mod.concat_encounters([f.result() for f in futs])


def sample_encounter_piece(n: int, start: int, kw: dict):
    """Encounters ``start .. start+n-1`` on a worker, which loads the compiled kernels first (it does for
    its chunks anyway): the realised-CPA integration then flies the compiled ``advance``, the same numbers
    (2,000 encounters: 1.8 -> 0.7 s CPU)."""
    from daa_sil.daa import kernels  # lazy: start-up time
    from daa_sil.models import encounters as enc_mod  # lazy: start-up time

    kernels.get()
    return enc_mod.sample_encounters(n, start=start, **kw)


__all__ = ["MIN_SAMPLE_PART", "SAMPLE_PIECE", "sample_campaign_encounters", "sample_encounter_piece"]
