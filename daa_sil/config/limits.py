"""Ranges that more than one input checks, defined once (a later issue moves them into the typed
configuration)."""

from __future__ import annotations

#: W_T, the wait threshold of paper Eq. 11 (s): the agent waits only while the map's wait time
#: w(S) >= W_T. Every input of W_T checks this range: ``campaign run --wt``, a group's
#: ``wait_threshold_s`` (the group table and ``--groups FILE``), a run configuration's
#: ``allocation.wt``, a scenario's ``allocation.wait_threshold_s`` and the vehicle's ``DAA_WT``
#: parameter. 120 s loses nothing: the largest W_T the study sweeps is 16 s, and no map value
#: exceeds its horizon (60 s for the paper grid, 120 s for the alerting grid), so a larger W_T
#: could never be met and would mean "never wait".
WT_RANGE_S = (0.0, 120.0)
