"""The ground station's per-step logic as a batched sans-IO object (step 1 of the step order).

:class:`GroundCore` is the counterpart of :class:`daa_sil.onboard.OnboardCore` (step 2): fast-time
(:func:`daa_sil.study.simulation.fasttime.simulate`) runs it for N encounters and the SIL GCS process
(:class:`gcs.node.GcsNode`) for N = 1, so given the same inputs both run the same step-1 code. At sim
time ``t_k`` :meth:`GroundCore.step`:

1. refreshes the remote pilot's display (:class:`daa_sil.models.pilot_display.PilotDisplay`) of the
   encounters whose ground station has received newer telemetry: the alert level the vehicle sent with
   it, well clear and the DAA bands of the observed (delayed) states, computed on the ground as the
   paper's pilot model does;
2. steps the remote-pilot model (:class:`daa_sil.models.pilot.PilotModel`) on what each pilot sees and
   returns its output (the command to send, if any).

Sans-IO: no sockets, no clock; the caller supplies ``t`` and the observed states and moves the bytes.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from daa_sil.geometry.kinematics import AircraftState
from daa_sil.models.pilot import PilotModel, PilotOutput
from daa_sil.models.pilot_config import PilotConfig
from daa_sil.models.pilot_display import PilotDisplay


class GroundCore:
    """The remote pilots of N encounters and their displays (step 1; module docstring)."""

    def __init__(self, n: int, seeds: "Sequence | None", pilot_cfg: "PilotConfig | None", daa_cfg,
                 plan: "AircraftState | None" = None):
        """``seeds``: the pilot stream of each encounter; ``plan`` (N,): the course each pilot returns to
        after the conflict."""
        self.pilot = PilotModel(n, seeds, pilot_cfg, plan=plan, daa_cfg=daa_cfg)
        self.display = PilotDisplay(n, daa_cfg, self.pilot.cfg.alert_level_min)

    def step(self, t: float, own: AircraftState, intr: "AircraftState | None", fresh: np.ndarray,
             alert: np.ndarray) -> PilotOutput:
        """One step at sim time ``t`` (s). ``own`` (N,) and ``intr`` (N, M) are the states each pilot sees
        (nan before any telemetry; ``intr`` None when no intruder is known yet and nothing is fresh);
        ``fresh`` (R,) the indices of the encounters whose telemetry is newer than at the last step and
        ``alert`` (R,) the vehicle's alert level sent with it."""
        fresh = np.asarray(fresh, np.int64)
        if fresh.size:
            self.display.refresh(fresh, own[fresh], intr[fresh], alert)
        return self.pilot.step(t, own, self.display.guidance(), intr)


__all__ = ["GroundCore"]
