"""A validated scenario as the core's inputs: delay models, the ownship state and a one-encounter
:class:`daa_sil.models.encounters.EncounterSet` (the conversion the SIL vehicle and fast-time parity
runs share)."""

from __future__ import annotations

import math
from dataclasses import replace

from daa_sil.config.settings import STEP
from daa_sil.errors import FileFormatError, UsageError

from .schema import Scenario
import numpy as np
from daa_sil.geometry.kinematics import AircraftState
from daa_sil.models import encounters as enc
from daa_sil.models.encounter_geometry import encounter_from_geometry


def delay_spec_string(spec) -> str:
    """A scenario delay spec (str or dict) as the ``--delay`` string of ``daa-sil shim``."""
    from daa_sil.models import delay_spec  # lazy: start-up time

    return spec if isinstance(spec, str) else delay_spec.delay_model_from_dict(spec).spec()


def link_legs(sc: Scenario):
    """The scenario link's :class:`daa_sil.models.link_rule.LinkLegs`: ``up`` / ``down`` one-way, or the
    ``round_trip`` split evenly (each link half of one draw per epoch, from the uplink stream)."""
    from daa_sil.models import delay_spec, link_rule  # lazy: start-up time

    def build(spec):
        return delay_spec.parse_delay_spec(spec) if isinstance(spec, str) else delay_spec.delay_model_from_dict(spec)

    if sc.link.round_trip is not None:
        return link_rule.link_legs(build(sc.link.round_trip), "round-trip")
    up = build(sc.link.up)
    return link_rule.link_legs(up, "one-way", build(sc.link.down) if sc.link.down is not None else up)


def delay_models(sc: Scenario):
    """``(up, down)`` :class:`daa_sil.models.latency.DelayModel` each link applies (a round trip's
    halves for ``link.round_trip``; :func:`link_legs` also says whether they share one stream)."""
    legs = link_legs(sc)
    return legs.up, legs.down


def ownship_state(sc: Scenario):
    """The ownship at t = 0 as an ``(1,)`` :class:`daa_sil.geometry.kinematics.AircraftState`."""


    o = sc.ownship
    return AircraftState(np.array([o.x_m]), np.array([o.y_m]), np.array([o.alt_m]), np.array([o.gs_mps]),
                         np.array([math.radians(o.track_deg)]), np.array([o.vs_mps]))


def encounter_set(sc: Scenario, encounter_id: int = 0):
    """The scenario as a one-encounter :class:`daa_sil.models.encounters.EncounterSet` (N = 1, M intruders).

    ``cpa`` intruders are placed by :func:`daa_sil.models.encounter_geometry.encounter_from_geometry` against the
    scenario's (unmaneuvered) ownship; ``initial`` intruders start as given. Scripts become the
    set's segments. This is the one conversion the SIL vehicle and fast-time parity runs share.
    """


    own = ownship_state(sc)
    m = len(sc.intruders)
    s_max = max(1, max(len(i.maneuvers) for i in sc.intruders))
    seg = [np.full((1, m, s_max), np.nan)] * 2 + [np.zeros((1, m, s_max)) for _ in range(3)]
    seg = [a.copy() for a in seg]
    states = []
    try:
        for j, spec in enumerate(sc.intruders):
            mv = [(x.start_s, x.end_s, x.turn_rate_dps, x.accel_mps2, x.vertical_accel_mps2) for x in spec.maneuvers]
            for k, (st, en, w, a, av) in enumerate(mv):
                seg[0][0, j, k], seg[1][0, j, k] = st, en
                seg[2][0, j, k], seg[3][0, j, k], seg[4][0, j, k] = math.radians(w), a, av
            if spec.cpa is not None:
                one = encounter_from_geometry(
                    [replace(spec.cpa, maneuvers=mv)],
                    own=own, duration_s=sc.duration_s, dt_s=STEP.default, encounter_id=encounter_id, seed=sc.seed,
                    realised=False)  # only the placed state is kept: its realised CPA is never read
                states.append(one.intr[:, 0])
            else:
                i = spec.initial
                states.append(AircraftState(np.array([i.x_m]), np.array([i.y_m]), np.array([i.alt_m]),
                                            np.array([i.gs_mps]), np.array([math.radians(i.track_deg)]),
                                            np.array([i.vs_mps])))
    except UsageError as exc:
        raise FileFormatError(f"{sc.source}: intruders[{j}]: {exc}") from None
    intr = AircraftState(*(np.stack([getattr(s_, f) for s_ in states], axis=1) for f in ("x", "y", "z", "gs", "trk", "vs")))
    return enc.EncounterSet(own=own, intr=intr, seg_start_s=seg[0], seg_end_s=seg[1], seg_turn_rate=seg[2],
                            seg_accel=seg[3], seg_vaccel=seg[4], encounter_id=np.array([encounter_id], np.int64),
                            seed=np.array([sc.seed], np.int64), params={}, root_seed=None,
                            duration_s=float(sc.duration_s), dt_s=STEP.default, config={"source": f"scenario:{sc.name}"})
