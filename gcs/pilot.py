"""The GCS's pilot and what it sends, typed (no sockets, no clock).

* :class:`ModelPilot`: :class:`daa_sil.models.ground.GroundCore` (N = 1; step 1, the same code fast-time
  runs: the pilot's display and :class:`daa_sil.models.pilot.PilotModel`) on the observed ownship
  and intruders (:func:`observed`), streaming per the allocation semantics;
* :class:`ScriptedPilot`: the scenario's ``pilot.commands`` (each sent once per step over
  ``[t_s, until_s)``).

Each step a pilot gives at most one :class:`PilotOrder`; the GCS sends it as a PILOT_MANEUVER and
logs it as a :class:`CommandSent`. A setting the GCS sends (``--set``) is a :class:`SettingSent`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from daa_sil.geometry.kinematics import AircraftState

from .view import View
from daa_sil.daa import kernels


class ScheduledSetting(NamedTuple):
    """A setting the GCS sends at sim time ``t`` (s): ``PARAM_SET name value``, or with ``name`` ``MODE`` a
    DO_SET_MODE to mode number ``value`` (``daa-gcs --set T:NAME=VALUE``)."""

    t: float
    name: str
    value: float


@dataclass(frozen=True)
class PilotOrder:
    """What the pilot commands at a step: track (deg, compass), vertical speed and ground speed (m/s; NaN =
    keep); ``kind`` ``hold`` / ``maneuverN`` (model) or ``scripted``; ``axis`` / ``direction`` of the
    model's maneuver (None for a script)."""

    track_deg: float
    vs_mps: float
    gs_mps: float
    kind: str
    axis: "str | None" = None
    direction: "str | None" = None


@dataclass(frozen=True)
class CommandSent:
    """A PILOT_MANEUVER the GCS sent: at sim time ``t`` (s) with sequence number ``seq`` (wall ``wall_s``,
    UNIX s)."""

    t: float
    seq: int
    wall_s: float
    order: PilotOrder

    def as_dict(self) -> dict:
        """The command log's line (``gcs_commands.jsonl``)."""
        o = self.order
        d = {"t": self.t, "seq": self.seq, "wall_s": self.wall_s, "track_deg": o.track_deg, "vs_mps": o.vs_mps,
             "gs_mps": o.gs_mps, "kind": o.kind}
        if o.axis is not None:
            d["axis"], d["dir"] = o.axis, o.direction
        return d


@dataclass(frozen=True)
class SettingSent:
    """A PARAM_SET (``kind`` ``param``) or DO_SET_MODE (``mode``, ``name`` MODE) the GCS sent at ``t`` (s)."""

    t: float
    kind: str
    name: str
    value: float
    wall_s: float

    def as_dict(self) -> dict:
        return {"t": self.t, "kind": self.kind, "name": self.name, "value": self.value, "wall_s": self.wall_s}


def observed(view: View, order: "list[int]") -> "tuple[AircraftState, AircraftState] | None":
    """Observed ownship (1,) and intruders (1, M) of ``view``, intruders in scenario ``order`` (ICAO ids;
    those not in it sorted), or None before telemetry."""
    if view.own is None or not view.intruders:
        return None
    ids = [i for i in order if i in view.intruders] or sorted(view.intruders)
    own = AircraftState(*(np.array([val]) for val in view.own[1:]))
    arr = np.array([view.intruders[i] for i in ids])
    intr = AircraftState(*(arr[None, :, k] for k in range(6)))
    return own, intr


class ScriptedPilot:
    """The scenario's scripted commands (``pilot.commands``: each sent once per step over ``[t_s, until_s)``)."""

    def __init__(self, commands=()):
        self.commands = list(commands)

    def orders(self, t: float, view: View, order: "list[int]") -> "list[PilotOrder]":
        out = [PilotOrder(c.track_deg, c.vs_mps, c.gs_mps, "scripted") for c in self.commands
               if c.t_s - 1e-9 <= t < c.until_s - 1e-9]
        return out[-1:]


class ModelPilot:
    """The pilot model of one encounter: a :class:`daa_sil.models.ground.GroundCore` of N = 1 (``ground``)."""

    def __init__(self, ground):
        self.ground = ground
        self._seen = math.nan  # vehicle time of the telemetry the display last showed

    def orders(self, t: float, view: View, order: "list[int]") -> "list[PilotOrder]":
        """Step the pilot at ``t`` (s) on ``view``; the display is refreshed only when newer telemetry is seen
        (as in fast-time), with the alert level the vehicle sent with that telemetry (DAA_ALERT)."""
        obs = observed(view, order)
        none = np.zeros(0, np.int64)
        if obs is None:  # nothing seen yet: the pilot steps on an unknown (nan) state, as in fast-time
            nan = np.full(1, np.nan)
            self.ground.step(t, AircraftState(nan, nan, nan, nan, nan, nan), None, none, none)
            return []
        own, intr = obs
        t_seen = view.own[0]
        fresh, alert = none, none
        if t_seen != self._seen:
            self._seen = t_seen
            level = view.alert[1] if view.alert[0] == t_seen else self.ground.display.alert[0]
            fresh, alert = np.array([0]), np.array([int(level)])
        po = self.ground.step(t, own, intr, fresh, alert)
        if not bool(po.send[0]):
            return []
        kind = "hold" if int(po.maneuver[0]) == 0 else f"maneuver{int(po.maneuver[0])}"
        trk = float(po.cmd.trk[0])
        return [PilotOrder(math.degrees(trk) % 360.0 if math.isfinite(trk) else math.nan, float(po.cmd.vs[0]),
                           float(po.cmd.gs[0]), kind, str(po.axis_names()[0]), str(po.direction_names()[0]))]


def make_pilot(sc, mode: str, daa_cfg, config=None):
    """The pilot of ``mode`` (``model`` / ``scripted``) for scenario ``sc`` (None: no scenario): the model
    with the scenario's seed, response and plan (the ownship's initial course, which the pilot returns
    to after the conflict), and ``config``'s pilot changes."""
    if mode != "model":
        return ScriptedPilot(sc.pilot.commands if sc is not None else ())
    from daa_sil.config.readings import reading_for  # lazy: start-up time
    from daa_sil.models.ground import GroundCore  # lazy: start-up time
    from daa_sil.models.pilot_config import PilotConfig  # lazy: start-up time
    from daa_sil.models.streams import STREAM_PILOT, encounter_streams  # lazy: start-up time
    from daa_sil.sil.scenario import ownship_state  # lazy: start-up time

    seed = encounter_streams(sc.seed if sc is not None else 0)[STREAM_PILOT]
    response = sc.pilot.response if sc else "guendel"
    # the configuration's pilot under its reading; without one, the study's default reading's pilot
    pcfg = (config.pilot_config(mode=response) if config is not None
            else reading_for().pilot_config(PilotConfig(mode=response)))
    ground = GroundCore(1, [seed], pcfg, daa_cfg, plan=ownship_state(sc) if sc is not None else None)

    kernels.get()  # load the compiled DAA before READY, not at the first conflict in realtime
    return ModelPilot(ground)
