"""Batched fast-time simulation of N encounters (paper §IV), following the step order exactly.

At step ``k`` (``t_k = k dt``, ``dt = 1 s``, ``T = 240 s``; ``docs/architecture.md``):

1. **GCS / pilot** -- the pilot observes the newest telemetry whose downlink release time is
   ``<= t_k`` (per-encounter telemetry history + FIFO release rule of
   :func:`daa_sil.link.delayline.fifo_release`), and :meth:`daa_sil.models.ground.GroundCore.step` (the same
   step-1 code the SIL GCS runs) refreshes the pilot's display from that view where it changed (DAA
   bands only where the observed alert reaches ``PilotConfig.alert_level_min``) and the pilot model
   decides. The GCS sends a packet every step (a heartbeat,
   plus the streamed command when the pilot has one) stamped ``t_k``; packets are released on the
   vehicle side at ``max(t_k + d_up(t_k), previous release)``. What crosses the link is what the
   MAVLink link carries (:mod:`daa_sil.link.setpoint`): the command's float32 setpoints, and the
   ownship's float32 position and vertical speed in the telemetry, so the SIL flies the same numbers.
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
(:mod:`daa_sil.steplog`). :func:`simulate_parts` runs several parts side by side in one batch --
e.g. the groups of a campaign chunk, each with its own policy and delay models -- and returns each
part's tables exactly as :func:`simulate` of that part alone would (every random stream is per
encounter, every step is element-wise per encounter, and the DAA gives each encounter's rows what a
call of their own gives, so it is called once per step on all the rows that need it).

Memory: what a link carries is kept in a :class:`~daa_sil.study.simulation.slot_ring.SlotRing` only until
the other end has read it (about the longest delay in steps), so a batch of N encounters holds
O(N) link state whatever the duration.

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

from dataclasses import dataclass
from typing import Sequence

import numpy as np
import pyarrow as pa

from daa_sil import steplog as sl
from daa_sil.agent.memory import PilotInput
from daa_sil.agent.wait_function import make_wait_lookup
from daa_sil.agent.allocation import PolicyRows
from daa_sil.config.policy import AllocationPolicy
from daa_sil.daa.config import DaaConfig
from daa_sil.errors import UsageError
from daa_sil.geometry.kinematics import AircraftState, Command
from daa_sil.models.link_rule import LinkLegs
from daa_sil.geometry.thresholds import get_thresholds
# the encounter's random streams (defined with the models: the SIL's GCS and shim use them too)
from daa_sil.models.streams import STREAM_DOWN, STREAM_PILOT, STREAM_UP, encounter_streams
from daa_sil.link.delayline import fifo_release
from daa_sil.link.setpoint import observed_own, wire_command
from daa_sil.models.delay_process import BatchedDelay
from daa_sil.models.encounters import concat_encounters
from daa_sil.models.latency import DEFAULT_EPOCH_S, DelayModel
from daa_sil.models.pilot_config import PilotConfig
from daa_sil.models.ground import GroundCore
from daa_sil.onboard import OnboardCore, step_columns
from daa_sil.study.simulation.fasttime_results import (DECISION_SCHEMA, ENCOUNTER_SCHEMA, Accumulators, decision_table,
                                            encounter_table)
from daa_sil.study.simulation.slot_ring import SlotRing




def _release_pointer(ptr: np.ndarray, release, upto: int, t: float) -> np.ndarray:
    """Advance per-encounter counts of released packets: slots ``< upto`` with release ``<= t``.

    ``release`` is ``(N, K)`` (release time of each slot) or a function ``(slots, rows) -> release
    times`` of those rows' slots; it is non-decreasing along the slots (FIFO), so the count only
    grows. Only the encounters that may still advance are looked at.
    """
    if not callable(release):
        table = release
        release = lambda s, r: table[r, np.minimum(s, table.shape[1] - 1)]  # noqa: E731
    ptr = ptr.copy()
    cand = np.flatnonzero(ptr < upto)
    while cand.size:
        cand = cand[release(ptr[cand], cand) <= t + 1e-9]
        ptr[cand] += 1
        cand = cand[ptr[cand] < upto]
    return ptr


@dataclass
class SimPart:
    """One part of a fast-time batch (:func:`simulate_parts`): encounters flown under one policy
    and one pair of link delay models (s), labelled ``group`` in its result tables."""

    encounters: object  #: an :class:`~daa_sil.models.encounters.EncounterSet`
    policy: AllocationPolicy
    latency_up: DelayModel
    latency_down: DelayModel
    seeds: "np.ndarray | None" = None  #: per-encounter seeds (default ``encounters.seed``)
    group: str = ""
    #: the two links' delays under a latency rule (replaces ``latency_up``/``latency_down``; e.g. the
    #: round-trip rule's, :func:`daa_sil.models.link_rule.link_legs`)
    link_legs: "LinkLegs | None" = None


class _LinkDelays:
    """One link direction of a batch: each part's delay model and the per-encounter delay streams
    (:class:`~daa_sil.models.delay_process.BatchedDelay` per part); ``delay_at(t)`` -> (N,) s."""

    def __init__(self, models: Sequence[DelayModel], streams: Sequence[list], epoch_s: float, duration_s: float,
                 made: "list | None" = None):
        # parts that read the same streams (one list object) under equal models have equal tables, draw
        # for draw: drawn once. The groups of a chunk share a latency model two at a time; under the
        # round-trip rule both links apply one model to the uplink stream (``made`` shared by the two
        # directions)
        made = [] if made is None else made
        self.parts = []
        for m, ss in zip(models, streams):
            table = next((b for mm, s2, b in made if s2 is ss and mm == m), None)
            if table is None:
                table = BatchedDelay(m, ss, epoch_s, duration_s)
                made.append((m, ss, table))
            self.parts.append(table)

    def delay_at(self, t: float) -> np.ndarray:
        if len(self.parts) == 1:
            return self.parts[0].delay_at(t)
        return np.concatenate([p.delay_at(t) for p in self.parts])


def _streams_per_part(seeds: Sequence[np.ndarray]) -> list[list]:
    """Each part's per-encounter streams (:func:`encounter_streams`), made once per distinct seed array:
    the groups of a chunk fly the same encounters, so their parts share one list (a SeedSequence is
    only read, never spawned from, so sharing it changes no draw)."""
    made: dict = {}
    out = []
    for s in seeds:
        key = s.tobytes()
        if key not in made:
            made[key] = [encounter_streams(x) for x in s]
        out.append(made[key])
    return out


def _stream_column(streams: Sequence[list], which: Sequence[int], made: dict) -> list[list]:
    """Stream ``which[i]`` of every encounter of part ``i``; parts that share their streams and read the
    same stream get one list object, also across calls with the same ``made`` (so :class:`_LinkDelays`
    draws their tables once)."""
    out = []
    for st, k in zip(streams, which):
        key = (id(st), k)
        if key not in made:
            made[key] = [x[k] for x in st]
        out.append(made[key])
    return out


def simulate(encounters, policy: AllocationPolicy, latency_up: DelayModel, latency_down: DelayModel,
             pilot_cfg: "PilotConfig | None" = None, daa_cfg: "DaaConfig | None" = None, wait_family=None, *,
             seeds: "np.ndarray | None" = None, preset: "str | None" = None, duration_s: "float | None" = None,
             dt: "float | None" = None, epoch_s: float = DEFAULT_EPOCH_S, group: str = "",
             record_steps: bool = False, wait_lookup=None,
             link_legs: "LinkLegs | None" = None) -> tuple[pa.Table, pa.Table, "pa.Table | None"]:
    """Simulate every encounter of ``encounters`` (an :class:`~daa_sil.models.encounters.EncounterSet`).

    ``policy`` the group's allocation policy; ``latency_up``/``latency_down`` each link's delay model
    (s), from their own streams; ``link_legs`` (a :class:`~daa_sil.models.link_rule.LinkLegs`, e.g. the
    round-trip rule's, :func:`~daa_sil.models.link_rule.link_legs`) replaces both; ``pilot_cfg`` (default :class:`PilotConfig`); ``daa_cfg`` (default: DO-365B with the
    thresholds of ``preset``, default ``"paper"``); ``wait_family`` a wait-map family (needed for
    ``wait_mode="map"``; or pass ``wait_lookup`` directly); ``seeds`` per-encounter seeds (default
    ``encounters.seed``); ``duration_s``/``dt`` (default from the set: 240 s / 1 s); ``epoch_s``
    delay-process epoch (s). Returns ``(encounter_table, decision_table, steplog or None)``.
    """
    part = SimPart(encounters, policy, latency_up, latency_down, seeds, group, link_legs)
    (enc, dec), log = _run([part], pilot_cfg, daa_cfg, wait_family, preset=preset, duration_s=duration_s, dt=dt,
                           epoch_s=epoch_s, record_steps=record_steps, wait_lookup=wait_lookup)
    return enc, dec, log


def simulate_parts(parts: Sequence[SimPart], pilot_cfg: "PilotConfig | None" = None,
                   daa_cfg: "DaaConfig | None" = None, wait_family=None, *, preset: "str | None" = None,
                   duration_s: "float | None" = None, dt: "float | None" = None, epoch_s: float = DEFAULT_EPOCH_S,
                   wait_lookup=None) -> list[tuple[pa.Table, pa.Table]]:
    """Simulate several parts side by side in one batch; returns ``[(encounter_table,
    decision_table), ...]``, one pair per part, each equal to :func:`simulate` of that part alone.
    The parts share the pilot and DAA configurations, duration, step and intruder count."""
    if not parts:
        raise UsageError("simulate_parts needs at least one part")
    tables, _ = _run(list(parts), pilot_cfg, daa_cfg, wait_family, preset=preset, duration_s=duration_s, dt=dt,
                     epoch_s=epoch_s, record_steps=False, wait_lookup=wait_lookup)
    return tables if len(parts) > 1 else [tables]


def _run(parts: list, pilot_cfg, daa_cfg, wait_family, *, preset, duration_s, dt, epoch_s, record_steps, wait_lookup):
    """The batched step loop of :func:`simulate` / :func:`simulate_parts` (see the module docstring)."""
    sizes = [len(p.encounters) for p in parts]
    if min(sizes) == 0:
        raise UsageError("simulate needs at least one encounter")
    enc0 = parts[0].encounters
    if any(p.encounters.m != enc0.m for p in parts):
        raise UsageError("the parts of a batch must have the same number of intruders")
    preset_name = get_thresholds(preset if preset is not None else
                                 (daa_cfg.th.name if daa_cfg is not None else "paper")).name
    cfg = daa_cfg if daa_cfg is not None else DaaConfig.for_preset(preset_name)
    pcfg = pilot_cfg if pilot_cfg is not None else PilotConfig()
    dt = float(dt if dt is not None else enc0.dt_s)
    duration = float(duration_s if duration_s is not None else enc0.duration_s)
    n_steps = int(round(duration / dt))
    if n_steps < 1:
        raise UsageError(f"duration {duration:g} s is shorter than one step of {dt:g} s")
    seeds = []
    for p, size in zip(parts, sizes):
        s = np.asarray(p.seeds if p.seeds is not None else p.encounters.seed, dtype=np.int64)
        if s.shape != (size,):
            raise UsageError(f"need {size} encounter seeds, got shape {s.shape}")
        seeds.append(s)
    if any(p.policy.wait_mode == "map" for p in parts) and wait_lookup is None:
        if wait_family is None:
            name = next(p.policy.name for p in parts if p.policy.wait_mode == "map")
            raise UsageError(f"policy {name} uses the wait map; pass wait_family")
        wait_lookup = make_wait_lookup(wait_family, cfg=cfg)

    encounters = enc0 if len(parts) == 1 else concat_encounters([p.encounters for p in parts])
    n = sum(sizes)
    bounds = np.concatenate([[0], np.cumsum(sizes)])
    policy = parts[0].policy if len(parts) == 1 else PolicyRows.stacked([p.policy for p in parts], sizes)
    streams = _streams_per_part(seeds)
    core = OnboardCore.from_encounters(encounters, policy, cfg, wait_lookup, thresholds=preset_name,
                                       step_log=record_steps)
    # the flight plan the pilot returns to: the ownship's initial straight, level course
    ground = GroundCore(n, [x[STREAM_PILOT] for st in streams for x in st], pcfg, cfg, plan=core.own)
    # each part's link legs: one-way (each link its own stream) or a shared round trip (both links
    # read the uplink stream's draws: models/link_rule.py)
    legs = [p.link_legs if p.link_legs is not None else LinkLegs(p.latency_up, p.latency_down) for p in parts]
    columns: dict = {}
    tables: list = []
    up = _LinkDelays([lg.up for lg in legs], _stream_column(streams, [STREAM_UP] * len(legs), columns), epoch_s,
                     duration + dt, tables)
    down = _LinkDelays([lg.down for lg in legs],
                       _stream_column(streams, [STREAM_UP if lg.shared else STREAM_DOWN for lg in legs], columns),
                       epoch_s, duration + dt, tables)
    m = core.m
    acc = Accumulators(n, core.own)
    log = sl.StepLogBuilder(encounters.encounter_id, m) if record_steps else None

    # link state, one slot per step, kept until read: telemetry down, GCS packets up
    downlink = SlotRing(n, {"own": ((6,), float, np.nan), "intr": ((m, 6), float, np.nan), "alert": ((), np.int64, 0),
                            "release": ((), float, np.inf)})
    uplink = SlotRing(n, {"release": ((), float, np.inf), "newest_sent": ((), np.int64, -1),
                          "cmd": ((3,), float, np.nan), "n_sent": ((), np.int64, 0)})
    down_ptr = np.zeros(n, np.int64)
    seen = np.full(n, -1, np.int64)  # telemetry index the pilot currently sees
    up_ptr = np.zeros(n, np.int64)
    last_cmd_slot = np.full(n, -1, np.int64)  # newest command slot delivered to the vehicle
    last_n_sent = np.zeros(n, np.int64)  # commands sent up to it (the vehicle has been released them all)
    last_down, last_up = np.full(n, -np.inf), np.full(n, -np.inf)
    down_release = lambda s, r: downlink.gather("release", s, r)  # noqa: E731
    up_release = lambda s, r: uplink.gather("release", s, r)  # noqa: E731

    for k in range(n_steps):
        t = k * dt
        # ---- 1. GCS / pilot ------------------------------------------------------------------
        down_ptr = _release_pointer(down_ptr, down_release, k, t)
        obs = down_ptr - 1
        new = obs != seen
        seen = obs
        obs_own = AircraftState.from_array(downlink.gather("own", obs))
        obs_intr = AircraftState.from_array(downlink.gather("intr", obs))
        fresh = np.flatnonzero(new & (obs >= 0))
        # the display bands the states it shows itself (each row's bands are what it gets alone)
        pout = ground.step(t, obs_own, obs_intr, fresh, downlink.gather("alert", obs[fresh], fresh))
        downlink.release(max(int(down_ptr.min()) - 1, 0))
        # GCS packet of step k (heartbeat + command if streaming), FIFO-released on the vehicle side
        d_up = up.delay_at(t)
        rel_up = fifo_release(np.full((n, 1), t), d_up[:, None], prev_release=last_up)[:, 0]
        last_up = rel_up
        prev_newest = uplink.gather("newest_sent", np.full(n, k - 1))
        prev_sent = uplink.gather("n_sent", np.full(n, k - 1))
        slot_up = uplink.open(k)
        slot_up["release"][:] = rel_up
        slot_up["newest_sent"][:] = np.where(pout.send, k, prev_newest)
        slot_up["n_sent"][:] = prev_sent + pout.send
        wire = wire_command(pout.cmd, np.flatnonzero(pout.send))  # (as PILOT_MANEUVER carries them: float32)
        slot_up["cmd"][:] = np.stack([wire.trk, wire.vs, wire.gs], axis=-1)
        # ---- 2. vehicle ----------------------------------------------------------------------
        up_ptr = _release_pointer(up_ptr, up_release, k + 1, t)
        newest = np.maximum(up_ptr - 1, 0)
        link_alive = np.where(up_ptr > 0, uplink.gather("release", newest), np.nan)
        # newest command slot among the released ones
        released_cmd = np.where(up_ptr > 0, uplink.gather("newest_sent", newest), -1)
        received = released_cmd > last_cmd_slot
        last_cmd_slot = np.maximum(last_cmd_slot, released_cmd)
        # commands released this step besides the newest (a FIFO burst): superseded within the step
        n_sent = np.where(up_ptr > 0, uplink.gather("n_sent", newest), 0)
        superseded = np.where(received, n_sent - last_n_sent - 1, 0)
        last_n_sent = np.where(received, n_sent, last_n_sent)
        slot = np.where(received, released_cmd, -1)  # only a received command is read (its slot is held)
        c = uplink.gather("cmd", slot)
        pin = PilotInput(received=received,
                         cmd=Command(np.where(received, c[:, 0], np.nan), np.where(received, c[:, 1], np.nan),
                                     np.where(received, c[:, 2], np.nan)),
                         t_sent=np.where(received, np.maximum(slot, 0) * dt, np.nan),
                         t_recv=np.where(received, uplink.gather("release", slot), np.nan), link_alive_t=link_alive)
        uplink.release(max(int(up_ptr.min()) - 1, 0))
        out = core.step(t, pin)
        acc.add(out, dt, superseded)
        # telemetry for t_k enters the downlink
        d_down = down.delay_at(t)
        rel_down = fifo_release(np.full((n, 1), t), d_down[:, None], prev_release=last_down)[:, 0]
        last_down = rel_down
        slot_down = downlink.open(k)
        slot_down["release"][:] = rel_down
        slot_down["own"][:] = observed_own(out.own)  # (what LOCAL_POSITION_NED carries of the ownship)
        slot_down["intr"][:] = out.intruders.as_array()
        slot_down["alert"][:] = out.telemetry.alert_level.max(axis=1) if m else 0
        if log is not None:
            log.append(step_columns(out, d_up, d_down))
    acc.deviation(core.own, n_steps * dt)
    decisions = acc.decisions()
    tables = [(encounter_table(acc, lo, hi, p.encounters, p.group, preset_name, n_steps * dt),
               decision_table(decisions, lo, hi, np.asarray(p.encounters.encounter_id, np.int64), p.group))
              for p, lo, hi in zip(parts, bounds[:-1], bounds[1:])]
    return (tables[0] if len(parts) == 1 else tables), (log.finish() if log is not None else None)


__all__ = ["simulate", "simulate_parts", "SimPart", "encounter_streams", "ENCOUNTER_SCHEMA", "DECISION_SCHEMA",
           "STREAM_PILOT", "STREAM_UP", "STREAM_DOWN"]
