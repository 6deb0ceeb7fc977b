"""One encounter from its CPA geometry (angle, HMD, time of CPA, speeds, VMD, scripted maneuvers):
the intruder placed so that it meets the unmaneuvered ownship as specified (scenario files, tests)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from daa_sil.config.settings import DURATION, STEP
from daa_sil.errors import UsageError
from daa_sil.geometry.frames import wrap_2pi, wrap_pi
from daa_sil.geometry.kinematics import AircraftState
from daa_sil.geometry.units import DEG
from daa_sil.models.encounters import PARAM_NAMES, EncounterConfig, EncounterSet, initial_ownships
from daa_sil.models.intruder_flight import fly_segments, place_intruders, realised_cpa


@dataclass
class IntruderGeometry:
    """One intruder defined by its CPA geometry (the scenario-file ``cpa`` block), SI + degrees.

    ``angle_deg``: intruder track minus ownship track (compass, 180 = head-on) at ``angle_at``
    (``"cpa"`` or ``"start"``); ``hmd_m`` signed, + = the intruder passes on the ownship's right
    (CPA bearing closest to +90 deg clockwise); ``maneuvers``: list of
    ``(start_s, end_s, turn_rate_dps, accel_mps2, vertical_accel_mps2)``.
    """

    angle_deg: float
    hmd_m: float
    t_cpa_s: float
    gs_mps: float
    vmd_m: float = 0.0
    vs_mps: float = 0.0
    maneuvers: Sequence = ()
    angle_at: str = "cpa"


def encounter_from_geometry(intruders: "Sequence[IntruderGeometry] | IntruderGeometry", *,
                            own: "AircraftState | None" = None, duration_s: float = DURATION.default, dt_s: float = STEP.default,
                            check_dt_s: float = 0.1, encounter_id: int = 0, seed: int = 0,
                            realised: bool = True) -> EncounterSet:
    """A one-encounter set (N = 1, M = len(intruders)) placed deterministically from CPA geometry.

    ``own``: the ownship at t = 0 (flies straight; default north at 55 m/s, 1500 m). Realised
    HMD/VMD/t_cpa over ``[0, duration_s]`` are stored in ``params`` (a turn may move the CPA; check
    ``t_cpa_real_s``); ``realised=False`` leaves them nan and skips that integration (``duration_s /
    check_dt_s`` single-aircraft steps: ~0.2 s for 240 s) for callers that only need the states,
    such as the SIL vehicle. Raises UsageError for a bad value.
    """
    geoms = [intruders] if isinstance(intruders, IntruderGeometry) else list(intruders)
    if not geoms:
        raise UsageError("encounter_from_geometry needs at least one intruder")
    own0 = own if own is not None else initial_ownships(1, EncounterConfig())
    own0 = AircraftState(*(np.atleast_1d(getattr(own0, f)).astype(float) for f in "x y z gs trk vs".split()))
    m = len(geoms)
    s_max = max(1, max(len(g.maneuvers) for g in geoms))
    seg = [np.full((1, m, s_max), np.nan) for _ in range(5)]
    for f in seg[2:]:
        f[:] = 0.0
    for j, g in enumerate(geoms):
        if g.angle_at not in ("cpa", "start"):
            raise UsageError(f"intruders[{j}].angle_at must be 'cpa' or 'start', got {g.angle_at!r}")
        if not (0 < g.t_cpa_s <= duration_s):
            raise UsageError(f"intruders[{j}].t_cpa_s must be within (0, {duration_s:g}], got {g.t_cpa_s!r}")
        if not g.gs_mps > 0:
            raise UsageError(f"intruders[{j}].gs_mps must be > 0, got {g.gs_mps!r}")
        for k, mv in enumerate(g.maneuvers):
            st, en, w, a, av = (list(mv) + [0.0] * 5)[:5]
            if not st < en:
                raise UsageError(f"intruders[{j}].maneuvers[{k}]: start_s must be < end_s, got {st!r}, {en!r}")
            seg[0][0, j, k], seg[1][0, j, k] = st, en
            seg[2][0, j, k], seg[3][0, j, k], seg[4][0, j, k] = w * DEG, a, av
    segt = tuple(seg)
    ang = np.array([[g.angle_deg * DEG for g in geoms]])
    tc = np.array([[g.t_cpa_s for g in geoms]])
    gs = np.array([[g.gs_mps for g in geoms]])
    vs = np.array([[g.vs_mps for g in geoms]])
    # initial track: for angle_at="cpa" subtract the scripted heading change up to t_cpa
    trk0 = own0.trk[:, None] + ang
    inits = []
    bearings = []
    for j, g in enumerate(geoms):
        sj = tuple(a[:, j:j + 1] for a in segt)
        t0j = trk0[:, j:j + 1]
        if g.angle_at == "cpa":
            z = np.zeros((1, 1))
            probe = fly_segments(AircraftState(z, z, z, gs[:, j:j + 1], z, vs[:, j:j + 1]), sj, g.t_cpa_s, dt_s, dt_s)
            t0j = wrap_2pi(t0j - wrap_pi(probe.trk))
        hint = np.full((1, 1), 90.0 * DEG if g.hmd_m >= 0 else -90.0 * DEG)
        init, b = place_intruders(own0, gs[:, j:j + 1], vs[:, j:j + 1], t0j, sj, g.t_cpa_s, abs(g.hmd_m),
                         g.vmd_m, hint, dt_s)
        inits.append(init)
        bearings.append(b)
    intr = AircraftState(*(np.concatenate([getattr(s, f) for s in inits], axis=1) for f in "x y z gs trk vs".split()))
    if realised:
        r_h, r_v, r_t = realised_cpa(own0, intr, segt, duration_s, dt_s, check_dt_s)
    else:
        r_h = r_v = r_t = np.full((1, m), np.nan)
    params = {k: np.full((1, m), np.nan) for k in PARAM_NAMES}
    params.update(speed_mps=gs, vs_mps=vs, hmd_m=np.abs([[g.hmd_m for g in geoms]]).astype(float),
                  vmd_m=np.array([[g.vmd_m for g in geoms]], float), t_cpa_s=tc, hmd_real_m=r_h, vmd_real_m=r_v,
                  t_cpa_real_s=r_t, cpa_bearing_deg=np.concatenate(bearings, axis=1) / DEG,
                  ia_deg=np.abs(wrap_pi(intr.trk - own0.trk[:, None])) / DEG,
                  ia_sign=-np.sign(wrap_pi(intr.trk - own0.trk[:, None])), n_rejected=np.zeros((1, m)))
    ids = np.array([encounter_id], dtype=np.int64)
    return EncounterSet(own=own0, intr=intr, seg_start_s=seg[0], seg_end_s=seg[1], seg_turn_rate=seg[2],
                        seg_accel=seg[3], seg_vaccel=seg[4], encounter_id=ids, seed=np.array([seed], np.int64),
                        params=params, root_seed=None, duration_s=float(duration_s), dt_s=float(dt_s),
                        config={"source": "geometry"})
