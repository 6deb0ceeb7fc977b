"""The random streams of one encounter: children of ``SeedSequence(seed)``, one per consumer.

Fast-time (:func:`daa_sil.study.simulation.fasttime.simulate`), the SIL GCS (its pilot model) and the SIL shim
(its delay processes) derive the same streams from an encounter's seed, so a SIL run sees draw for
draw what fast-time gives that encounter. A light module on purpose: the GCS and the shim import
it without the fast-time machinery.
"""

from __future__ import annotations

import numpy as np

#: stream indices under an encounter's seed
STREAM_PILOT, STREAM_UP, STREAM_DOWN = 0, 1, 2


def encounter_streams(seed: int) -> list[np.random.SeedSequence]:
    """``[pilot, uplink, downlink]`` SeedSequences of one encounter (children of ``SeedSequence(seed)``).

    The delay streams are the *delay-process* seeds: a SIL shim replaying encounter ``seed`` uses
    ``DelayProcess(model, streams[STREAM_UP], epoch_s)`` for the uplink (same draws).
    """
    return [np.random.SeedSequence(int(seed), spawn_key=(k,)) for k in (STREAM_PILOT, STREAM_UP, STREAM_DOWN)]


__all__ = ["STREAM_DOWN", "STREAM_PILOT", "STREAM_UP", "encounter_streams"]
