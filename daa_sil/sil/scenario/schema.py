"""Scenario files: one scripted encounter for the SIL (and for fast-time parity runs).

A scenario is a YAML mapping. Units are SI except angles, which are degrees (compass tracks,
clockwise from north). Positions are ENU metres from the scenario origin (x east, y north) with
``alt_m`` the altitude above the origin. Every key is checked: an unknown key, a wrong type, a
missing field or an out-of-range value raises :class:`daa_sil.errors.FileFormatError` naming the
file, the line and the field, e.g. ``scenarios/x.yaml:12: intruders[0].cpa.hmd_m: must be within
[-5000, 5000], got 9000``.

Schema (``*`` = required; defaults in brackets)::

    name*: str                      short identifier (used in result files)
    description: str                [""]
    seed: int >= 0                  [1]     root of every random stream (pilot, link up/down)
    duration_s: float [1, 3600]     [240]   sim length; steps are dt = 1 s
    thresholds: do365 | paper | daidalus   [do365] well-clear / NMAC / DAA preset
    origin:                                 geodetic reference of the ENU frame (MAVLink output)
      lat_deg: [-80, 80]            [37.4]
      lon_deg: [-180, 180]          [-122.05]
      alt_m:   [-500, 9000]         [0]     MSL altitude of ENU z = 0
    ownship*:
      x_m, y_m: float               [0]
      alt_m*: float [0, 20000]
      gs_mps*: float [5, 350]
      track_deg*: float [0, 360)
      vs_mps: float [-50, 50]       [0]
    intruders*: list of 1..8, each
      id: int [1, 16777215]         [1000 + index]  ICAO address in ADSB_VEHICLE
      callsign: str, <= 8 chars     ["INTR<index+1>"]
      initial:                      exactly one of initial / cpa
        x_m*, y_m*, alt_m*, gs_mps*, track_deg*, vs_mps [0]
      cpa:                          geometry at the closest point of approach (docs/models.md, "Encounters")
        angle_deg*: [0, 360)        encounter angle, intruder track minus ownship track (180 = head-on)
        hmd_m*: [-5000, 5000]       signed horizontal miss distance (+ = passes on the right)
        vmd_m: [-1000, 1000]  [0]   intruder minus ownship altitude at CPA
        t_cpa_s*: (0, duration_s]   time of CPA (unmaneuvered ownship)
        gs_mps*: [5, 350]
        vs_mps: [-50, 50]     [0]
      maneuvers: list               intruder script, non-overlapping, in time order
        - start_s*: [0, duration_s)
          end_s*: (start_s, duration_s]
          turn_rate_dps: [-10, 10]  [0] compass sense, + = right
          accel_mps2: [-5, 5]       [0] along-track
          vertical_accel_mps2: [-10, 10] [0]
    link:                                   delay shim per direction
      up: delay spec                [const:4] uplink (GCS -> vehicle): "const:4", "gauss:5,3",
      down: delay spec              [= up]    "uniform:1,8" or {type: constant, seconds: 4} ...
      round_trip: delay spec        [-]       instead of up/down: the round trip, split evenly (each
                                              link half of one draw per epoch, the uplink's stream;
                                              the paper reading's rule, docs/models.md "Link delay")
      epoch_s: float [0, 600]       [10]      piecewise-constant delay epoch (0 = per packet)
      loss: [0, 1)                  [0]       Bernoulli loss probability (each direction)
      dup: [0, 1)                   [0]       duplication probability (SIL shim only; fast-time ignores it)
      reorder: [0, 1)               [0]       queue-jump reordering probability (SIL shim only)
      outages: list                             link down windows, both directions: a datagram
        - start_s*, end_s*                      sent in [start_s, end_s) is lost
    pilot:
      mode: model | scripted        [model]
      model:                                    options of daa_sil.models.pilot.PilotModel
        response: deterministic | fixed | guendel | no_atc | nasa_rayleigh5  [deterministic]
      commands: list (scripted mode; required there, forbidden in model mode)
        - t_s*: [0, duration_s]      first send time; the command is streamed once per step
          until_s: (t_s, duration_s] [next command's t_s, else duration_s]
          track_deg, vs_mps, gs_mps  at least one; omitted = keep current
    allocation:
      group: a group of daa_sil/data/groups.yaml (B-1 ... ID-2, ID-2-projl, ID-2-map) [ID-1]
                                      its wait function, W_T, ProjL and blending are the defaults below
      wait: none | constant | map | always  [from group]
      blending: bool                  [from group]
      projl: bool                     [from group]  ProjL veto
      every per-group setting (docs/configuration.md), each [from group]:
      wait_threshold_s: [0, 120]      W_T (old key wt)
      projl_horizon_s: [0, 120]       ProjL look-ahead N (old key projl_lookahead)
      constant_wait_s: [0, 120]       the constant wait (old key wait_constant_s)
      link_timeout_s: [1, 120]        link-lost timeout
      stale_command_s: [1, 120]       stale-command limit
    expect:                                   checked by ``daa-sil run`` (exit 1 if violated)
      lowc: bool                      LoWC must (true) / must not (false) occur
      nmac: bool
      decisions_include: [decision names]  each must appear at least once
      decisions_exclude: [decision names]  none may appear
      min_range_at_least_m: float     minimum horizontal range must be >= this
      link_lost_by_s: float           a link_lost decision must appear at or before this sim time
    faults: list                              process faults, carried out by ``daa-sil run --clock
      - kill*: gcs                            realtime`` (lockstep refuses them: there the GCS is part of
        at_s*: (0, duration_s)                the clock). ``kill`` names the process (only the GCS: the
        restart_s: (at_s, duration_s)         vehicle and the shim are the run); ``at_s`` / ``restart_s``
        signal: KILL | TERM | INT  [KILL]     are vehicle sim times; a restart binds the same port and
                                              writes its own command log. Omit restart_s = stays dead.
                                              ``result.json`` ``faults`` says when each was carried out;
                                              a fault that could not be carried out fails the run.

Decision names: none, wait, no_wait, pilot, blend, daa_override, daa, stale, link_lost.

The defaults and ranges shown for ``duration_s``, ``thresholds``, ``link.up``, ``link.epoch_s`` and the
allocation keys are those of :mod:`daa_sil.config.settings`, which the loader and the dataclasses read.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any

from daa_sil.config.overrides import Overrides
from daa_sil.config.settings import DELAY_EPOCH, DURATION, SCENARIO_GROUP, SCENARIO_LINK, STANDARD_PRESET
from daa_sil.agent.decision import DECISION_NAMES
from daa_sil.models.encounter_geometry import IntruderGeometry

#: the decision names ``expect.decisions_include`` / ``decisions_exclude`` accept: the agent's (one definition)
DECISIONS = DECISION_NAMES
PILOT_RESPONSES = ("deterministic", "fixed", "guendel", "no_atc", "nasa_rayleigh5")
MAX_INTRUDERS = 8


# --------------------------------------------------------------------------------------------
# dataclasses (the validated scenario)

@dataclass
class Origin:
    lat_deg: float = 37.4
    lon_deg: float = -122.05
    alt_m: float = 0.0


@dataclass
class InitialState:
    """ENU position (m), ground speed (m/s), compass track (deg), vertical speed (m/s, up)."""

    x_m: float
    y_m: float
    alt_m: float
    gs_mps: float
    track_deg: float
    vs_mps: float = 0.0


@dataclass
class Maneuver:
    """Intruder script segment: rates held over ``[start_s, end_s)``."""

    start_s: float
    end_s: float
    turn_rate_dps: float = 0.0
    accel_mps2: float = 0.0
    vertical_accel_mps2: float = 0.0


@dataclass
class IntruderSpec:
    id: int
    callsign: str
    initial: "InitialState | None" = None
    #: placement by closest approach to the unmaneuvered ownship (its script is ``maneuvers``, not ``cpa.maneuvers``)
    cpa: "IntruderGeometry | None" = None
    maneuvers: list = field(default_factory=list)


@dataclass
class Outage:
    """Link down (both directions) for datagrams sent in ``[start_s, end_s)`` (sim s)."""

    start_s: float
    end_s: float


@dataclass
class LinkSpec:
    """Delay specs are kept as given (str or dict); :func:`delay_model` builds the model."""

    up: Any = SCENARIO_LINK.default
    down: Any = None
    round_trip: Any = None  #: instead of up/down: the round trip, split evenly between the links
    epoch_s: float = DELAY_EPOCH.field()
    loss: float = 0.0
    outages: list = field(default_factory=list)
    dup: float = 0.0
    reorder: float = 0.0

    def outage_windows(self) -> list[tuple[float, float]]:
        """``(start_s, end_s)`` link-down windows (sim s)."""
        return [(o.start_s, o.end_s) for o in self.outages]


@dataclass
class ScriptedCommand:
    """A scripted pilot command (nan = keep current), streamed once per step over ``[t_s, until_s)``."""

    t_s: float
    until_s: float
    track_deg: float = math.nan
    vs_mps: float = math.nan
    gs_mps: float = math.nan


@dataclass
class PilotSpec:
    mode: str = "model"
    response: str = "deterministic"
    commands: list = field(default_factory=list)


@dataclass
class AllocationSpec:
    """The scenario's group, its wait function, blending and ProjL veto (the group's unless given),
    and ``settings``: the per-group settings the scenario gives (W_T, N, ...; unset = the group's)."""

    group: str = SCENARIO_GROUP.default
    wait: str = "map"
    blending: bool = True
    projl: bool = True
    settings: Overrides = field(default_factory=Overrides)


@dataclass
class Expectation:
    lowc: "bool | None" = None
    nmac: "bool | None" = None
    decisions_include: list = field(default_factory=list)
    decisions_exclude: list = field(default_factory=list)
    min_range_at_least_m: "float | None" = None
    link_lost_by_s: "float | None" = None


FAULT_PROCESSES = ("gcs",)
FAULT_SIGNALS = ("KILL", "TERM", "INT")


@dataclass
class ProcessFault:
    """Kill ``process`` with SIG``signal`` at vehicle sim time ``at_s``; restart it at ``restart_s`` (None = never)."""

    process: str
    at_s: float
    restart_s: "float | None" = None
    signal: str = "KILL"

    def describe(self) -> str:
        """``"SIGKILL gcs at 20 s, restart at 40 s"``."""
        return (f"SIG{self.signal} {self.process} at {self.at_s:g} s"
                + (f", restart at {self.restart_s:g} s" if self.restart_s is not None else ", no restart"))


@dataclass
class Scenario:
    name: str
    ownship: InitialState
    intruders: list
    description: str = ""
    seed: int = 1
    duration_s: float = DURATION.field()
    thresholds: str = STANDARD_PRESET.default
    origin: Origin = field(default_factory=Origin)
    link: LinkSpec = field(default_factory=LinkSpec)
    pilot: PilotSpec = field(default_factory=PilotSpec)
    allocation: AllocationSpec = field(default_factory=AllocationSpec)
    expect: Expectation = field(default_factory=Expectation)
    faults: list = field(default_factory=list)
    source: str = field(default="<memory>", compare=False)

    @property
    def n_steps(self) -> int:
        """Number of 1 s steps (``t_k = k``, k = 0 .. n_steps-1)."""
        return int(math.floor(self.duration_s + 1e-9))

    def to_dict(self) -> dict:
        """Plain YAML-ready dict (the inverse of :func:`scenario_from_dict`)."""
        d = asdict(self)
        d.pop("source", None)
        for intr in d["intruders"]:
            for k in ("initial", "cpa"):
                if intr[k] is None:
                    intr.pop(k)
            if "cpa" in intr:  # a scenario's CPA is at the CPA, its script under the intruder's own key
                intr["cpa"].pop("maneuvers")
                intr["cpa"].pop("angle_at")
        for k in ("up", "down", "round_trip"):  # absent (a round trip replaces up / down)
            if d["link"][k] is None:
                d["link"].pop(k)
        d["pilot"]["commands"] = [{k: v for k, v in c.items() if not (isinstance(v, float) and math.isnan(v))}
                                  for c in d["pilot"]["commands"]]
        if d["pilot"]["mode"] == "model":
            d["pilot"].pop("commands")
        d["pilot"]["model"] = {"response": d["pilot"].pop("response")}
        d["allocation"].pop("settings")
        d["allocation"].update(self.allocation.settings.given())  # the per-group settings the scenario gives
        for sect in ("allocation", "expect"):
            d[sect] = {k: v for k, v in d[sect].items() if v is not None and v != []}
        if d["faults"]:
            d["faults"] = [{("kill" if k == "process" else k): v for k, v in f.items() if v is not None}
                           for f in d["faults"]]
        else:
            d.pop("faults")
        return d
