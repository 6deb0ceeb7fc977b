"""Batched fast-time simulation of N encounters (paper §IV), following the step order exactly.

At step ``k`` (``t_k = k dt``, ``dt = 1 s``, ``T = 240 s``; ``docs/architecture.md``):

1. **GCS / pilot** -- the pilot observes the newest telemetry whose downlink release time is
   ``<= t_k`` (per-encounter telemetry history + FIFO release rule of
   :func:`daa_sil.link.delayline.fifo_release`), its display (:class:`daa_sil.models.pilot_display.PilotDisplay`,
   the same one the SIL GCS uses) is refreshed from that view where it changed (DAA bands only
   where the observed alert reaches ``PilotConfig.alert_level_min``), and
   :meth:`daa_sil.models.pilot.PilotModel.step` decides. The GCS sends a packet every step (a heartbeat,
   plus the streamed command when the pilot has one) stamped ``t_k``; packets are released on the
   vehicle side at ``max(t_k + d_up(t_k), previous release)``.
2. **Vehicle** -- :meth:`daa_sil.onboard.OnboardCore.step` with the newest command released at or
   before ``t_k`` (``received`` iff a command was released since the previous step; the link is
   alive as of the newest released packet), which decides, publishes telemetry for ``t_k``
   (released to the GCS at ``max(t_k + d_down(t_k), previous)``), advances truth and evaluates
   LoWC/NMAC on ``[t_k, t_k + dt]`` between samples.

Everything is vectorised over encounters; the only Python loops are over steps (and a bounded
"release everything due" loop). Random streams per encounter ``i`` come from its seed
``encounters.seed[i]`` (:func:`encounter_streams`): the pilot, uplink and downlink delay
processes, identical for every group. Delay processes are piecewise constant per ``epoch_s``
(:class:`daa_sil.models.delay_process.BatchedDelay`), as in the SIL shim.

Results: :func:`simulate` returns the per-encounter and per-decision tables of the architecture
contract ("Campaign result tables") and, with ``record_steps=True``, the step log
(:mod:`daa_sil.steplog`).

Counting (per encounter, over the active steps, one decision each -- ``agent.py``):
``n_active_steps = n_wait + n_no_wait + n_pilot_exec + n_blend + n_daa_override + n_stale +
n_link_lost``; ``n_pilot_received = n_pilot_exec + n_blend + n_daa_override`` (fresh pilot commands
received during the active phase); ``n_blend_intent`` = blends of a pilot command that carries a
maneuver intent (an (axis, direction) -- not "hold" before the pilot's first maneuver);
``n_blend_intent = n_blend_exact + n_blend_axis + (intent blends matching neither) <= n_blend``.
Over the whole encounter (the ``whole`` counting window of :mod:`daa_sil.config.readings`):
``n_pilot_received_whole`` fresh pilot commands that reached the vehicle at any step, and
``n_pilot_exec_whole`` of them executed as sent (outside the active phase the ownship flies the
received command; inside, the ``pilot`` decisions). Decision provenance: ``n_by_map``,
``n_by_projl``, ``n_by_both`` count the no-wait decisions by ``decided_by``; ``n_lookup_in_box``
the wait/no-wait decisions whose map lookup was inside the map's box.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
import pyarrow as pa

from daa_sil import steplog as sl
from daa_sil.agent import (BY_BOTH, BY_MAP, BY_PROJL, CODE_NAMES, D_BLEND, D_DAA_OVERRIDE, D_LINK_LOST,
    D_NO_WAIT, D_PILOT, D_STALE, D_WAIT, AllocationPolicy, PilotInput, make_wait_lookup)
from daa_sil.daa.config import DaaConfig
from daa_sil.errors import UsageError
from daa_sil.geometry.kinematics import AircraftState, Command
from daa_sil.models.latency import DEFAULT_EPOCH_S, DelayModel
from daa_sil.models.link_rule import LinkLegs
from daa_sil.models.delay_process import batched_link_delays
from daa_sil.link.delayline import fifo_release
from daa_sil.onboard import OnboardCore, StepOutput
from daa_sil.models.pilot import PilotModel
from daa_sil.models.pilot_display import PilotDisplay
from daa_sil.models.pilot_config import PilotConfig
from daa_sil.geometry.thresholds import get_thresholds

#: stream indices under an encounter's seed
STREAM_PILOT, STREAM_UP, STREAM_DOWN = 0, 1, 2

_I = pa.int64()
ENCOUNTER_SCHEMA = pa.schema(
    [("group", pa.string()), ("encounter_id", _I), ("seed", _I), ("duration_s", pa.float64()),
     ("lowc", pa.bool_()), ("nmac", pa.bool_()), ("lowc_duration_s", pa.float64()), ("pi", pa.float64()),
     ("pi_paper", pa.float64()), ("min_range_m", pa.float64()), ("vsep_at_min_range_m", pa.float64()), ("dev_h_m", pa.float64()),
     ("dev_v_m", pa.float64()), ("n_active_steps", _I), ("n_wait", _I), ("n_no_wait", _I),
     ("n_pilot_received", _I), ("n_pilot_exec", _I), ("n_blend", _I), ("n_blend_exact", _I),
     ("n_blend_axis", _I), ("n_blend_intent", _I), ("n_daa_override", _I), ("n_stale", _I), ("n_link_lost", _I),
     ("n_by_map", _I), ("n_by_projl", _I), ("n_by_both", _I), ("n_lookup_in_box", _I),
     ("n_pilot_received_whole", _I), ("n_pilot_exec_whole", _I),
     ("intruder_turns", pa.bool_()), ("preset", pa.string())])

DECISION_SCHEMA = pa.schema(
    [("group", pa.string()), ("encounter_id", _I), ("t", pa.float64()), ("decision", pa.string()),
     ("rule", pa.string()), ("wait_s", pa.float64()), ("projl", pa.bool_()), ("decided_by", pa.string()),
     ("wait_p_lowc", pa.float64()), ("wait_in_box", pa.bool_()), ("wait_turn_dps", pa.float64()),
     ("wait_map_turn_dps", pa.float64()), ("sm_pilot", pa.float64()),
     ("sm_exec", pa.float64()), ("pilot_axis", pa.string()), ("pilot_dir", pa.string()),
     ("exec_axis", pa.string()), ("exec_dir", pa.string()), ("exact_match", pa.bool_())])

_DEC_FIELDS = ("decision", "rule", "wait_s", "projl", "decided_by", "wait_p_lowc", "wait_in_box", "wait_turn_dps",
               "wait_map_turn_dps", "sm_pilot", "sm_exec", "pilot_axis", "pilot_dir", "exec_axis", "exec_dir",
               "exact_match")


def encounter_streams(seed: int) -> list[np.random.SeedSequence]:
    """``[pilot, uplink, downlink]`` SeedSequences of one encounter (children of ``SeedSequence(seed)``).

    The delay streams are the *delay-process* seeds: a SIL shim replaying encounter ``seed`` uses
    ``DelayProcess(model, streams[STREAM_UP], epoch_s)`` for the uplink (same draws).
    """
    return [np.random.SeedSequence(int(seed), spawn_key=(k,)) for k in (STREAM_PILOT, STREAM_UP, STREAM_DOWN)]


def _gather_state(hist: np.ndarray, idx: np.ndarray) -> AircraftState:
    """State at history index ``idx`` (N,) from ``hist`` (K, N, ..., 6); nan where idx < 0."""
    n = idx.size
    rows = np.arange(n)
    a = hist[np.clip(idx, 0, None), rows]
    a = np.where((idx >= 0).reshape((n,) + (1,) * (a.ndim - 1)), a, np.nan)
    return AircraftState.from_array(a)


def _release_pointer(ptr: np.ndarray, release: np.ndarray, upto: int, t: float) -> np.ndarray:
    """Advance per-encounter counts of released packets: slots ``< upto`` with release ``<= t``.

    ``release`` (N, K) is non-decreasing along K (FIFO), so the count only grows.
    """
    rows = np.arange(ptr.size)
    while True:
        nxt = np.minimum(ptr, release.shape[1] - 1)
        can = (ptr < upto) & (release[rows, nxt] <= t + 1e-9)
        if not can.any():
            return ptr
        ptr = ptr + can


class _Accumulators:
    """Per-encounter result accumulators (N,)."""

    def __init__(self, n: int, own0: AircraftState):
        self.lowc = np.zeros(n, bool)
        self.nmac = np.zeros(n, bool)
        self.lowc_time = np.zeros(n)
        self.pi = np.zeros(n)  # PI (s), preset constants, integrated on the LoWC segments
        self.pi_paper = np.zeros(n)  # PI (s), the paper's Eq. constants (4000 ft / 450 ft / 35 s)
        self.min_range = np.full(n, np.inf)
        self.vsep_at_min = np.full(n, np.nan)
        self.dev_h = np.zeros(n)
        self.dev_v = np.zeros(n)
        self.counts = np.zeros((n, len(CODE_NAMES["decision"])), np.int64)
        self.n_active = np.zeros(n, np.int64)
        self.n_blend_exact = np.zeros(n, np.int64)
        self.n_blend_axis = np.zeros(n, np.int64)
        self.n_blend_intent = np.zeros(n, np.int64)
        self.by = np.zeros((n, len(CODE_NAMES["decided_by"])), np.int64)
        self.n_in_box = np.zeros(n, np.int64)
        self.n_recv_whole = np.zeros(n, np.int64)
        self.n_exec_whole = np.zeros(n, np.int64)
        self.p0 = own0.position()
        self.v0 = own0.velocity()
        self.dec_parts: list[tuple[np.ndarray, float, dict]] = []

    def deviation(self, own: AircraftState, t: float) -> None:
        """Max deviation (m) of the ownship from its unperturbed straight path p0 + v0 t."""
        d = own.position() - (self.p0 + self.v0 * t)
        self.dev_h = np.maximum(self.dev_h, np.hypot(d[:, 0], d[:, 1]))
        self.dev_v = np.maximum(self.dev_v, np.abs(d[:, 2]))

    def add(self, out: StepOutput, dt: float) -> None:
        dec = out.decisions
        self.lowc |= out.lowc
        self.nmac |= out.nmac
        self.lowc_time += out.lowc_time_s
        self.pi += out.pi_s
        self.pi_paper += out.pi_paper_s
        closer = out.seg_min_range_m < self.min_range
        self.min_range = np.where(closer, out.seg_min_range_m, self.min_range)
        self.vsep_at_min = np.where(closer, out.seg_vsep_m, self.vsep_at_min)
        self.deviation(out.own, out.t)
        active = np.asarray(dec["active"], bool)
        code = np.asarray(dec["decision"], np.int64)
        fresh = np.asarray(dec["pilot_cmd_fresh"], bool)
        self.n_recv_whole += fresh
        self.n_exec_whole += fresh & (~active | (code == D_PILOT))  # outside the active phase it is flown as sent
        ia = np.flatnonzero(active)
        if ia.size:
            np.add.at(self.counts, (ia, code[ia]), 1)
            self.n_active[ia] += 1
            blend = code == D_BLEND
            exact = blend & np.asarray(dec["exact_match"], bool)
            intent = blend & (np.asarray(dec["pilot_axis"]) != 0)
            axis_only = intent & ~exact & (np.asarray(dec["exec_axis"]) == np.asarray(dec["pilot_axis"]))
            self.n_blend_exact += exact & active
            self.n_blend_axis += axis_only & active
            self.n_blend_intent += intent & active
            np.add.at(self.by, (ia, np.asarray(dec["decided_by"], np.int64)[ia]), 1)
            self.n_in_box += active & np.asarray(dec["wait_in_box"], bool)
            self.dec_parts.append((ia, out.t, {k: np.asarray(dec[k])[ia] for k in _DEC_FIELDS}))


def _strings(codes: np.ndarray, names: Sequence[str]) -> pa.Array:
    return pa.DictionaryArray.from_arrays(pa.array(np.asarray(codes, np.int32)),
                                          pa.array(list(names), pa.string())).cast(pa.string())


def _decision_table(acc: _Accumulators, ids: np.ndarray, group: str) -> pa.Table:
    if not acc.dec_parts:
        return DECISION_SCHEMA.empty_table()
    rows = np.concatenate([p[0] for p in acc.dec_parts])
    t = np.concatenate([np.full(p[0].size, p[1]) for p in acc.dec_parts])
    order = np.lexsort((t, rows))  # encounter-major, then time
    rows, t = rows[order], t[order]
    col = {k: np.concatenate([p[2][k] for p in acc.dec_parts])[order] for k in _DEC_FIELDS}
    arrays = [pa.array(np.full(rows.size, group), pa.string()), pa.array(ids[rows], _I), pa.array(t),
              _strings(col["decision"], CODE_NAMES["decision"]), _strings(col["rule"], CODE_NAMES["rule"]),
              pa.array(col["wait_s"].astype(float)), pa.array(col["projl"].astype(bool)),
              _strings(col["decided_by"], CODE_NAMES["decided_by"]), pa.array(col["wait_p_lowc"].astype(float)),
              pa.array(col["wait_in_box"].astype(bool), mask=np.isnan(col["wait_p_lowc"].astype(float))),
              pa.array(col["wait_turn_dps"].astype(float)),
              pa.array(col["wait_map_turn_dps"].astype(float)),
              pa.array(col["sm_pilot"].astype(float)), pa.array(col["sm_exec"].astype(float)),
              _strings(col["pilot_axis"], CODE_NAMES["pilot_axis"]), _strings(col["pilot_dir"], CODE_NAMES["pilot_dir"]),
              _strings(col["exec_axis"], CODE_NAMES["exec_axis"]), _strings(col["exec_dir"], CODE_NAMES["exec_dir"]),
              pa.array(col["exact_match"].astype(bool))]
    return pa.Table.from_arrays(arrays, schema=DECISION_SCHEMA)


def _encounter_table(acc: _Accumulators, encounters, group: str, preset: str, duration: float) -> pa.Table:
    n = len(encounters)
    c = acc.counts
    received = c[:, D_PILOT] + c[:, D_BLEND] + c[:, D_DAA_OVERRIDE]
    cols = {
        "group": pa.array(np.full(n, group), pa.string()), "encounter_id": pa.array(encounters.encounter_id, _I),
        "seed": pa.array(encounters.seed, _I), "duration_s": pa.array(np.full(n, float(duration))),
        "lowc": pa.array(acc.lowc), "nmac": pa.array(acc.nmac), "lowc_duration_s": pa.array(acc.lowc_time),
        "pi": pa.array(acc.pi), "pi_paper": pa.array(acc.pi_paper), "min_range_m": pa.array(acc.min_range), "vsep_at_min_range_m": pa.array(acc.vsep_at_min),
        "dev_h_m": pa.array(acc.dev_h), "dev_v_m": pa.array(acc.dev_v), "n_active_steps": pa.array(acc.n_active, _I),
        "n_wait": pa.array(c[:, D_WAIT], _I), "n_no_wait": pa.array(c[:, D_NO_WAIT], _I),
        "n_pilot_received": pa.array(received, _I), "n_pilot_exec": pa.array(c[:, D_PILOT], _I),
        "n_blend": pa.array(c[:, D_BLEND], _I), "n_blend_exact": pa.array(acc.n_blend_exact, _I),
        "n_blend_axis": pa.array(acc.n_blend_axis, _I),
        "n_blend_intent": pa.array(acc.n_blend_intent, _I), "n_daa_override": pa.array(c[:, D_DAA_OVERRIDE], _I),
        "n_stale": pa.array(c[:, D_STALE], _I), "n_link_lost": pa.array(c[:, D_LINK_LOST], _I),
        "n_by_map": pa.array(acc.by[:, BY_MAP], _I), "n_by_projl": pa.array(acc.by[:, BY_PROJL], _I),
        "n_by_both": pa.array(acc.by[:, BY_BOTH], _I), "n_lookup_in_box": pa.array(acc.n_in_box, _I),
        "n_pilot_received_whole": pa.array(acc.n_recv_whole, _I), "n_pilot_exec_whole": pa.array(acc.n_exec_whole, _I),
        "intruder_turns": pa.array(np.asarray(encounters.intruder_turns, bool)),
        "preset": pa.array(np.full(n, preset), pa.string()),
    }
    return pa.Table.from_arrays(list(cols.values()), schema=ENCOUNTER_SCHEMA)


def _step_columns(out: StepOutput, delay_up: np.ndarray, delay_down: np.ndarray) -> dict:
    """Step-log columns (:mod:`daa_sil.steplog`) of one :class:`StepOutput`."""
    d, g, own, intr = out.decisions, out.geometry, out.own, out.intruders
    deg = np.degrees
    cols = {"step": np.full(own.shape[0], out.step, np.int32), "t": np.full(own.shape[0], out.t),
            "own_x": own.x, "own_y": own.y, "own_z": own.z, "own_gs": own.gs, "own_trk_deg": deg(own.trk),
            "own_vs": own.vs, "intr_x": intr.x, "intr_y": intr.y, "intr_z": intr.z, "intr_gs": intr.gs,
            "intr_trk_deg": deg(intr.trk), "intr_vs": intr.vs, "range_m": g["range_m"], "hmd_m": g["hmd_m"],
            "dh_m": g["dh_m"], "tau_mod_s": g["tau_mod_s"], "alert_level": out.telemetry.alert_level,
            "wcv": g["wcv"], "delay_up_s": delay_up, "delay_down_s": delay_down, "lowc": out.lowc, "nmac": out.nmac}
    for k in ("decision", "rule", "authority", "wait_s", "projl", "decided_by", "wait_p_lowc", "wait_in_box",
              "wait_map_turn_dps", "pilot_cmd_received", "pilot_cmd_age_s", "sm_pilot", "sm_exec", "pilot_axis",
              "pilot_dir", "exec_axis", "exec_dir"):
        cols[k] = d[k]
    cols["intr_turn_est_dps"] = deg(out.turn_est)
    for src, dst in (("cmd", "cmd"), ("pilot", "pilot"), ("daa", "daa")):
        cols[f"{dst}_trk_deg"] = deg(d[f"{src}_trk"])
        cols[f"{dst}_vs"] = d[f"{src}_vs"]
        cols[f"{dst}_gs"] = d[f"{src}_gs"]
    cols.update(out.telemetry.extra)
    return cols


def simulate(encounters, policy: AllocationPolicy, latency_up: DelayModel, latency_down: DelayModel,
             pilot_cfg: "PilotConfig | None" = None, daa_cfg: "DaaConfig | None" = None, wait_family=None, *,
             seeds: "np.ndarray | None" = None, preset: "str | None" = None, duration_s: "float | None" = None,
             dt: "float | None" = None, epoch_s: float = DEFAULT_EPOCH_S, group: str = "",
             record_steps: bool = False, wait_lookup=None,
             link_legs: "LinkLegs | None" = None) -> tuple[pa.Table, pa.Table, "pa.Table | None"]:
    """Simulate every encounter of ``encounters`` (an :class:`~daa_sil.models.encounters.EncounterSet`).

    ``policy`` the group's allocation policy; ``latency_up``/``latency_down`` each link's delay model
    (s), from their own streams; ``link_legs`` (a :class:`~daa_sil.models.latency.LinkLegs`, e.g. the
    round-trip rule's, :func:`~daa_sil.models.latency.link_legs`) replaces both; ``pilot_cfg`` (default :class:`PilotConfig`); ``daa_cfg`` (default: DO-365B with the
    thresholds of ``preset``, default ``"paper"``); ``wait_family`` a wait-map family (needed for
    ``wait_mode="map"``; or pass ``wait_lookup`` directly); ``seeds`` per-encounter seeds (default
    ``encounters.seed``); ``duration_s``/``dt`` (default from the set: 240 s / 1 s); ``epoch_s``
    delay-process epoch (s). Returns ``(encounter_table, decision_table, steplog or None)``.
    """
    n = len(encounters)
    if n == 0:
        raise UsageError("simulate needs at least one encounter")
    preset_name = get_thresholds(preset if preset is not None else
                                 (daa_cfg.th.name if daa_cfg is not None else "paper")).name
    cfg = daa_cfg if daa_cfg is not None else DaaConfig.for_preset(preset_name)
    pcfg = pilot_cfg if pilot_cfg is not None else PilotConfig()
    dt = float(dt if dt is not None else encounters.dt_s)
    duration = float(duration_s if duration_s is not None else encounters.duration_s)
    n_steps = int(round(duration / dt))
    if n_steps < 1:
        raise UsageError(f"duration {duration:g} s is shorter than one step of {dt:g} s")
    seeds = np.asarray(seeds if seeds is not None else encounters.seed, dtype=np.int64)
    if seeds.shape != (n,):
        raise UsageError(f"need {n} encounter seeds, got shape {seeds.shape}")
    if policy.wait_mode == "map" and wait_lookup is None:
        if wait_family is None:
            raise UsageError(f"policy {policy.name} uses the wait map; pass wait_family")
        wait_lookup = make_wait_lookup(wait_family, cfg=cfg)

    streams = [encounter_streams(s) for s in seeds]
    core = OnboardCore.from_encounters(encounters, policy, cfg, wait_lookup, thresholds=preset_name)
    # the flight plan the pilot returns to: the ownship's initial straight, level course
    pilot = PilotModel(n, [s[STREAM_PILOT] for s in streams], pcfg, plan=core.own, daa_cfg=cfg)
    legs = link_legs if link_legs is not None else LinkLegs(latency_up, latency_down)
    up, down = batched_link_delays(legs, [s[STREAM_UP] for s in streams], [s[STREAM_DOWN] for s in streams],
                                   epoch_s, duration + dt)
    m = core.m
    acc = _Accumulators(n, core.own)
    log = sl.StepLogBuilder(encounters.encounter_id, m) if record_steps else None
    rows = np.arange(n)

    # link state: downlink telemetry history and uplink packets, one slot per step
    hist_own = np.full((n_steps, n, 6), np.nan)
    hist_intr = np.full((n_steps, n, m, 6), np.nan)
    hist_alert = np.zeros((n_steps, n), np.int64)
    down_rel = np.full((n, n_steps), np.inf)
    down_ptr = np.zeros(n, np.int64)
    seen = np.full(n, -1, np.int64)  # telemetry index the pilot currently sees
    up_rel = np.full((n, n_steps), np.inf)
    up_ptr = np.zeros(n, np.int64)
    newest_sent = np.full((n, n_steps), -1, np.int64)  # newest command slot sent at or before each slot
    up_cmd = np.full((n_steps, n, 3), np.nan)
    last_cmd_slot = np.full(n, -1, np.int64)  # newest command slot delivered to the vehicle
    last_down, last_up = np.full(n, -np.inf), np.full(n, -np.inf)
    display = PilotDisplay(n, cfg, pcfg.alert_level_min)

    for k in range(n_steps):
        t = k * dt
        # ---- 1. GCS / pilot ------------------------------------------------------------------
        down_ptr = _release_pointer(down_ptr, down_rel, k, t)
        obs = down_ptr - 1
        new = obs != seen
        seen = obs
        obs_own = _gather_state(hist_own, obs)
        obs_intr = _gather_state(hist_intr, obs)
        i = np.flatnonzero(new & (obs >= 0))
        display.refresh(i, obs_own[i], obs_intr[i], hist_alert[obs[i], i])
        pout = pilot.step(t, obs_own, display.guidance(), obs_intr)
        # GCS packet of step k (heartbeat + command if streaming), FIFO-released on the vehicle side
        d_up = up.delay_at(t)
        rel_up = fifo_release(np.full((n, 1), t), d_up[:, None], prev_release=last_up)[:, 0]
        last_up = rel_up
        up_rel[:, k] = rel_up
        newest_sent[:, k] = np.where(pout.send, k, newest_sent[:, k - 1] if k else -1)
        up_cmd[k] = np.stack([pout.cmd.trk, pout.cmd.vs, pout.cmd.gs], axis=-1)
        # ---- 2. vehicle ----------------------------------------------------------------------
        up_ptr = _release_pointer(up_ptr, up_rel, k + 1, t)
        link_alive = np.where(up_ptr > 0, up_rel[rows, np.maximum(up_ptr - 1, 0)], np.nan)
        # newest command slot among the released ones
        released_cmd = np.where(up_ptr > 0, newest_sent[rows, np.maximum(up_ptr - 1, 0)], -1)
        received = released_cmd > last_cmd_slot
        last_cmd_slot = np.maximum(last_cmd_slot, released_cmd)
        slot = np.maximum(released_cmd, 0)
        c = up_cmd[slot, rows]
        pin = PilotInput(received=received,
                         cmd=Command(np.where(received, c[:, 0], np.nan), np.where(received, c[:, 1], np.nan),
                                     np.where(received, c[:, 2], np.nan)),
                         t_sent=np.where(received, slot * dt, np.nan),
                         t_recv=np.where(received, up_rel[rows, slot], np.nan), link_alive_t=link_alive)
        out = core.step(t, pin)
        acc.add(out, dt)
        # telemetry for t_k enters the downlink
        d_down = down.delay_at(t)
        rel_down = fifo_release(np.full((n, 1), t), d_down[:, None], prev_release=last_down)[:, 0]
        last_down = rel_down
        down_rel[:, k] = rel_down
        hist_own[k] = out.own.as_array()
        hist_intr[k] = out.intruders.as_array()
        hist_alert[k] = out.telemetry.alert_level.max(axis=1) if m else 0
        if log is not None:
            log.append(_step_columns(out, d_up, d_down))
    acc.deviation(core.own, n_steps * dt)
    enc = _encounter_table(acc, encounters, group, preset_name, n_steps * dt)
    dec = _decision_table(acc, np.asarray(encounters.encounter_id, np.int64), group)
    return enc, dec, (log.finish() if log is not None else None)


__all__ = ["simulate", "encounter_streams", "ENCOUNTER_SCHEMA", "DECISION_SCHEMA", "STREAM_PILOT", "STREAM_UP",
           "STREAM_DOWN"]
