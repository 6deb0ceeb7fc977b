"""Encounter model of Tabassum & Bai §IV (paper Table 6) and encounter sets on disk.

Ownship: straight and level, due north at 55 m/s from the origin (``own_alt_m`` up). Intruders
(``M >= 1`` per encounter, each drawn independently) follow paper Table 6:

==============  ==========================================  =====================================
parameter       distribution (truncated by **rejection**)    our reading
==============  ==========================================  =====================================
speed           N(100, 30) within [70, 400] m/s              constant ground speed
vertical vel.   N(0, 10) within [-10, 10] m/s                constant vertical speed
ia              30 % exactly 180 deg, else U[0, 180] deg     the intruder's **initial** track
                                                             relative to the ownship track,
                                                             counter-clockwise, on a random side
                                                             (``ia_sign``): track = -sign*ia
hma             N(0, 110) within [-110, 110] deg             bearing *hint* of the intruder at CPA
                                                             (counter-clockwise from the nose); see below
HMD             U[0, 2750] m                                 horizontal range at CPA
VMD             U[-915, 915] m                               intruder minus ownship altitude at CPA
turn rate       U[-5, 5] deg/s                               compass sense (+ = right)
advance rate a  N(0.5, 0.5) within [0, 0.8]                  the turn starts at ``a*T``
==============  ==========================================  =====================================

Interpretations of what the paper leaves open (all configurable in :class:`EncounterConfig`):

* **CPA time.** Not given in the paper; the CPA is placed at ``t_cpa_s = T/2 = 120 s``. The CPA is
  the time of minimum *horizontal* range of the unmaneuvered ownship and the scripted intruder.
* **hma.** With the CPA a stationary point of the range, the CPA position is perpendicular to the
  relative velocity, so its bearing is fixed up to the side (``docs/models.md``, "Encounters"). We
  read hma as a bearing hint that picks the side: of the two admissible CPA positions we take the
  one whose bearing is closest to hma. The realised bearing is stored (``cpa_bearing_deg``).
* **Turn.** One constant-rate turn per intruder from ``a*T`` for ``max_turn_deg / |rate|`` s
  (default 90 deg of heading change), ended at ``T``. Schedules act on the simulator's step grid:
  a segment ``[start, end)`` is active in the step starting at ``t_k`` iff ``start <= t_k < end``.
* **Placement.** The rigid-motion construction of ``docs/models.md`` ("Encounters"), without the rotation because
  ia fixes the initial track: the intruder template is integrated with :func:`kinematics.advance`
  on the step grid (exactly what the simulator does), then translated so that at ``t_cpa`` the
  intruder is ``HMD`` from the ownship perpendicular to the relative velocity and ``VMD`` above it.
* **Validation / rejection.** Each candidate is integrated on a ``check_dt`` (0.1 s) grid over
  ``[0, T]``; it is accepted iff the realised minimum horizontal range occurs within
  ``cpa_tol_s`` of ``t_cpa`` and is not below ``HMD - cpa_tol_m`` (a turn can create an earlier or
  later, closer pass, or make ``t_cpa`` a maximum), and iff the start is neither inside the
  well-clear volume nor predicted (straight line) to violate it within ``warning_time_s`` (the
  DAIDALUS warning alerting time, 25 s). Rejected candidates are redrawn whole, so accepted
  encounters follow Table 6 *conditioned on* these checks; ``n_rejected`` records the redraws.
  Realised HMD / VMD / t_cpa are stored next to the sampled values.

Randomness: encounter ``i`` uses ``Generator(PCG64(SeedSequence(seed).spawn(n)[i]))`` (built as
``SeedSequence(seed, spawn_key=(i,))``), so an encounter does not depend on chunking.
"""

from __future__ import annotations

import os
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Sequence

import numpy as np

from daa_sil.config.settings import DURATION, STANDARD_PRESET, STEP
from daa_sil.errors import UsageError
from daa_sil.geometry.frames import wrap_2pi
from daa_sil.geometry.kinematics import AircraftState
from daa_sil.geometry.thresholds import get_thresholds
from daa_sil.geometry.units import DEG
from daa_sil.geometry.wellclear import time_to_violation, wcv
from daa_sil.models.intruder_flight import place_intruders, realised_cpa, segment_controls

FORMAT_NAME = "daa-sil-encounters"
FORMAT_VERSION = 1

#: per-intruder sampled/realised parameters stored in ``EncounterSet.params`` (all (N, M) float)
PARAM_NAMES = ("speed_mps", "vs_mps", "ia_deg", "ia_sign", "hma_deg", "hmd_m", "vmd_m", "turn_rate_dps",
               "advance", "t_cpa_s", "hmd_real_m", "vmd_real_m", "t_cpa_real_s", "cpa_bearing_deg",
               "n_rejected")
#: the fields of an :class:`EncounterSet` that hold the intruders' maneuver segments
SEGMENT_FIELDS = ("seg_start_s", "seg_end_s", "seg_turn_rate", "seg_accel", "seg_vaccel")


@dataclass(frozen=True)
class EncounterConfig:
    """Encounter-model parameters (paper Table 6 defaults). Speeds m/s, angles deg, times s."""

    n_intruders: int = 1
    duration_s: float = DURATION.default
    dt_s: float = STEP.default
    own_speed_mps: float = 55.0
    own_alt_m: float = 1500.0
    speed: tuple = (100.0, 30.0, 70.0, 400.0)  #: Gaussian mean, sd, lo, hi
    vs: tuple = (0.0, 10.0, -10.0, 10.0)
    p_head_on: float = 0.30
    ia_max_deg: float = 180.0
    hma: tuple = (0.0, 110.0, -110.0, 110.0)
    hmd_max_m: float = 2750.0
    vmd_max_m: float = 915.0
    turn_rate_max_dps: float = 5.0
    advance: tuple = (0.5, 0.5, 0.0, 0.8)
    t_cpa_s: float = 120.0
    max_turn_deg: float = 90.0
    preset: str = STANDARD_PRESET.default
    warning_time_s: float = 25.0
    check_dt_s: float = 0.1
    cpa_tol_s: float = 1.0
    cpa_tol_m: float = 1.0
    max_rounds: int = 200

    def validate(self) -> "EncounterConfig":
        get_thresholds(self.preset)
        if int(self.n_intruders) < 1:
            raise UsageError(f"n_intruders must be >= 1, got {self.n_intruders!r}")
        if not (0 < self.t_cpa_s < self.duration_s):
            raise UsageError(f"t_cpa_s must be within (0, duration_s={self.duration_s:g}), got {self.t_cpa_s!r}")
        for name in ("speed", "vs", "hma", "advance"):
            mu, sd, lo, hi = getattr(self, name)
            if not (sd > 0 and lo < hi):
                raise UsageError(f"{name} must be (mean, sd > 0, lo, hi > lo), got {getattr(self, name)!r}")
        if self.dt_s <= 0 or self.check_dt_s <= 0 or self.check_dt_s > self.dt_s:
            raise UsageError("dt_s and check_dt_s must be positive with check_dt_s <= dt_s")
        return self


def encounter_seed(root_seed: int, encounter_ids) -> np.ndarray:
    """Per-encounter int64 seeds: ``SeedSequence(root_seed, spawn_key=(i,))`` hashed to 63 bits
    (the same definition as :func:`daa_sil.study.campaign.run.encounter_seeds`)."""
    ids = np.asarray(encounter_ids, dtype=np.int64).ravel()
    out = np.empty(ids.size, dtype=np.int64)
    for k, i in enumerate(ids):
        w = np.random.SeedSequence(int(root_seed), spawn_key=(int(i),)).generate_state(1, np.uint64)[0]
        out[k] = int(w >> np.uint64(1))
    return out


# --------------------------------------------------------------------------------------------------
@dataclass
class EncounterSet:
    """N encounters with M intruders each (arrays; SI units, compass radians).

    ``own`` (N,) and ``intr`` (N, M) are the states at t = 0; intruder scripts are S segments
    ``seg_*`` of shape (N, M, S): ``[start, end)`` s, turn rate rad/s (+ = right), along-track and
    vertical acceleration m/s^2 (nan start = unused). ``params`` holds the sampled and realised
    parameters (:data:`PARAM_NAMES`, (N, M)); ``encounter_id`` the spawn index, ``seed`` the
    per-encounter seed (:func:`encounter_seed`), ``root_seed`` the campaign seed (None for
    hand-built encounters).
    """

    own: AircraftState
    intr: AircraftState
    seg_start_s: np.ndarray
    seg_end_s: np.ndarray
    seg_turn_rate: np.ndarray
    seg_accel: np.ndarray
    seg_vaccel: np.ndarray
    encounter_id: np.ndarray
    seed: np.ndarray
    params: dict = field(default_factory=dict)
    root_seed: "int | None" = None
    duration_s: float = DURATION.default
    dt_s: float = STEP.default
    config: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.own.shape[0])

    @property
    def n(self) -> int:
        return len(self)

    @property
    def m(self) -> int:
        """Intruders per encounter."""
        return int(self.intr.shape[1])

    def intruder_controls(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(turn_rate rad/s, accel m/s^2, vertical_accel m/s^2)``, each (N, M), for the step
        starting at sim time ``t`` s; advance intruders with
        :data:`daa_sil.models.intruder_flight.INTRUDER_PERFORMANCE`."""
        return segment_controls(tuple(getattr(self, f) for f in SEGMENT_FIELDS), t)

    @property
    def intruder_turns(self) -> np.ndarray:
        """(N,) bool: some intruder turns before its CPA (turn onset < realised t_cpa)."""
        tc = self.params.get("t_cpa_real_s", np.full(self.intr.shape, self.duration_s))
        turning = (self.seg_turn_rate != 0) & (self.seg_start_s < tc[..., None])
        return turning.any(axis=(1, 2))

    def subset(self, idx) -> "EncounterSet":
        """The encounters at positions ``idx`` (int array, slice or bool mask)."""
        idx = np.arange(len(self))[idx] if not isinstance(idx, np.ndarray) or idx.dtype == bool else idx
        idx = np.asarray(idx, dtype=np.int64)
        return replace(self, own=self.own[idx], intr=self.intr[idx],
                       **{k: getattr(self, k)[idx] for k in SEGMENT_FIELDS},
                       encounter_id=self.encounter_id[idx], seed=self.seed[idx],
                       params={k: v[idx] for k, v in self.params.items()})


def concat_encounters(sets: Sequence[EncounterSet]) -> EncounterSet:
    """Concatenate encounter sets with the same M and S along the encounter axis."""
    if not sets:
        raise UsageError("concat_encounters needs at least one encounter set")
    a = sets[0]
    cat = np.concatenate
    return replace(a, own=AircraftState(*(cat([getattr(s.own, f) for s in sets]) for f in "x y z gs trk vs".split())),
                   intr=AircraftState(*(cat([getattr(s.intr, f) for s in sets]) for f in "x y z gs trk vs".split())),
                   **{k: cat([getattr(s, k) for s in sets]) for k in SEGMENT_FIELDS},
                   encounter_id=cat([s.encounter_id for s in sets]), seed=cat([s.seed for s in sets]),
                   params={k: cat([s.params[k] for s in sets]) for k in a.params})


def _start_ok(own0: AircraftState, init: AircraftState, cfg: EncounterConfig) -> np.ndarray:
    op, ov = own0.position(), own0.velocity()
    if init.x.ndim == 2:
        op, ov = op[:, None, :], ov[:, None, :]
    s, v = op - init.position(), ov - init.velocity()
    th = get_thresholds(cfg.preset)
    return ~wcv(s, v, th) & ~np.isfinite(time_to_violation(s, v, th, cfg.warning_time_s))


def _trunc_first(z: np.ndarray, mu: float, sd: float, lo: float, hi: float) -> np.ndarray:
    """First in-range value along the last axis of ``mu + sd*z`` (rejection); nan if none."""
    x = mu + sd * z
    ok = (x >= lo) & (x <= hi)
    first = np.argmax(ok, axis=-1)
    val = np.take_along_axis(x, first[..., None], axis=-1)[..., 0]
    return np.where(ok.any(axis=-1), val, np.nan)


_K = 48  # normal candidates per truncated parameter and round (P(all rejected) < 1e-11)


def _draw_round(rngs, m: int) -> dict:
    """One candidate parameter set per (encounter, intruder) from each encounter's generator.

    Draw order per encounter and round (part of the reproducibility contract): normals (m, 4, K)
    for speed, vs, hma, advance; then uniforms (m, 6) for head-on, ia, side, HMD, VMD, turn rate.
    """
    z = np.stack([r.standard_normal((m, 4, _K)) for r in rngs])
    u = np.stack([r.random((m, 6)) for r in rngs])
    return {"z": z, "u": u}


def _candidates(d: dict, cfg: EncounterConfig) -> dict:
    z, u = d["z"], d["u"]
    p = {"speed_mps": _trunc_first(z[:, :, 0], *cfg.speed), "vs_mps": _trunc_first(z[:, :, 1], *cfg.vs),
         "hma_deg": _trunc_first(z[:, :, 2], *cfg.hma), "advance": _trunc_first(z[:, :, 3], *cfg.advance)}
    head_on = u[..., 0] < cfg.p_head_on
    p["ia_deg"] = np.where(head_on, 180.0, u[..., 1] * cfg.ia_max_deg)
    p["ia_sign"] = np.where(u[..., 2] < 0.5, 1.0, -1.0)
    p["hmd_m"] = u[..., 3] * cfg.hmd_max_m
    p["vmd_m"] = (2.0 * u[..., 4] - 1.0) * cfg.vmd_max_m
    p["turn_rate_dps"] = (2.0 * u[..., 5] - 1.0) * cfg.turn_rate_max_dps
    return p


def _segments_from_params(p: dict, cfg: EncounterConfig) -> tuple:
    t1 = p["advance"] * cfg.duration_s
    rate = p["turn_rate_dps"] * DEG
    dur = np.where(np.abs(rate) > 0, cfg.max_turn_deg * DEG / np.maximum(np.abs(rate), 1e-300), np.inf)
    t2 = np.minimum(t1 + dur, cfg.duration_s)
    z = np.zeros_like(t1)
    return tuple(a[..., None] for a in (t1, t2, rate, z, z))


def initial_ownships(n: int, cfg: EncounterConfig) -> AircraftState:
    """``n`` ownships at the origin, flying north level at ``cfg``'s altitude (m) and speed (m/s)."""
    z = np.zeros(n)
    return AircraftState(z, z, z + cfg.own_alt_m, z + cfg.own_speed_mps, z, z)


def sample_encounters(n: int, seed: int = 0, start: int = 0, config: "EncounterConfig | None" = None,
                      **overrides) -> EncounterSet:
    """Sample encounters ``start .. start+n-1`` of the campaign ``seed`` (paper Table 6).

    ``overrides`` replace :class:`EncounterConfig` fields (e.g. ``n_intruders=2``). Vectorised over
    encounters; only the random draws loop over the per-encounter generators.
    """
    cfg = replace(config or EncounterConfig(), **overrides).validate()
    if not isinstance(n, (int, np.integer)) or n < 0:
        raise UsageError(f"number of encounters must be a non-negative integer, got {n!r}")
    if not isinstance(seed, (int, np.integer)) or seed < 0:
        raise UsageError(f"seed must be a non-negative integer, got {seed!r}")
    m = int(cfg.n_intruders)
    ids = np.arange(start, start + n, dtype=np.int64)
    rngs = [np.random.Generator(np.random.PCG64(np.random.SeedSequence(int(seed), spawn_key=(int(i),))))
            for i in ids]
    own0 = initial_ownships(n, cfg)
    out = {k: np.full((n, m), np.nan) for k in PARAM_NAMES}
    out["n_rejected"] = np.zeros((n, m))
    init = AircraftState(*(np.full((n, m), np.nan) for _ in range(6)))
    segs = [np.full((n, m, 1), np.nan) for _ in range(5)]
    pending = np.ones((n, m), dtype=bool)
    for _round in range(cfg.max_rounds):
        enc = np.flatnonzero(pending.any(axis=1))
        if enc.size == 0:
            break
        p = _candidates(_draw_round([rngs[i] for i in enc], m), cfg)
        own_e = own0[enc]
        ok = np.all([np.isfinite(v) for v in p.values()], axis=0)
        p = {k: np.nan_to_num(v) for k, v in p.items()}
        seg = _segments_from_params(p, cfg)
        trk0 = wrap_2pi(own_e.trk[:, None] - p["ia_sign"] * p["ia_deg"] * DEG)
        hint = -p["hma_deg"] * DEG  # hma is counter-clockwise; bearings here are clockwise
        cand, bearing = place_intruders(own_e, p["speed_mps"], p["vs_mps"], trk0, seg, cfg.t_cpa_s, p["hmd_m"],
                               p["vmd_m"], hint, cfg.dt_s)
        r_h, r_v, r_t = realised_cpa(own_e, cand, seg, cfg.duration_s, cfg.dt_s, cfg.check_dt_s)
        ok &= (np.abs(r_t - cfg.t_cpa_s) <= cfg.cpa_tol_s) & (r_h >= p["hmd_m"] - cfg.cpa_tol_m)
        ok &= _start_ok(own_e, cand, cfg)
        take = ok & pending[enc]
        out["n_rejected"][enc] += (~ok & pending[enc])
        p.update(t_cpa_s=np.full(take.shape, cfg.t_cpa_s), hmd_real_m=r_h, vmd_real_m=r_v, t_cpa_real_s=r_t,
                 cpa_bearing_deg=-bearing / DEG)
        ei, ej = np.nonzero(take)
        gi = enc[ei]
        for k in PARAM_NAMES:
            if k != "n_rejected":
                out[k][gi, ej] = p[k][ei, ej]
        for f in ("x", "y", "z", "gs", "trk", "vs"):
            getattr(init, f)[gi, ej] = getattr(cand, f)[ei, ej]
        for a, b in zip(segs, seg):
            a[gi, ej] = b[ei, ej]
        pending[gi, ej] = False
    if pending.any():
        i = int(ids[np.flatnonzero(pending.any(axis=1))[0]])
        raise UsageError(f"encounter {i}: no valid geometry after {cfg.max_rounds} draws; relax the encounter config")
    return EncounterSet(own=own0, intr=init, seg_start_s=segs[0], seg_end_s=segs[1], seg_turn_rate=segs[2],
                        seg_accel=segs[3], seg_vaccel=segs[4], encounter_id=ids,
                        seed=encounter_seed(seed, ids), params=out, root_seed=int(seed),
                        duration_s=float(cfg.duration_s), dt_s=float(cfg.dt_s), config=_cfg_dict(cfg))


def _cfg_dict(cfg: EncounterConfig) -> dict:
    return {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(cfg).items()}


__all__ = ["EncounterConfig", "EncounterSet", "INTRUDER_PERFORMANCE", "PARAM_NAMES", "sample_encounters",
           "concat_encounters", "encounter_seed"]
