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
    duration_s: float (0, 3600]     [240]   sim length; steps are dt = 1 s
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
      cpa:                          geometry at the closest point of approach (models.md §5)
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
      wait_constant_s: [0, 120]       [from group, else 5]
      blending: bool                  [from group]
      projl: bool                     [from group]  ProjL veto
      wait_threshold_s: [0, 120]      [from group]  W_T
      link_timeout_s: (0, 120]        [agent default]
      stale_command_s: (0, 120]       [agent default]
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
"""

from __future__ import annotations

import math
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable

import yaml

from daa_sil.errors import FileFormatError, UsageError

DECISIONS = ("none", "wait", "no_wait", "pilot", "blend", "daa_override", "daa", "stale", "link_lost")
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
class CpaGeometry:
    """Intruder placement by its closest point of approach to the unmaneuvered ownship."""

    angle_deg: float
    hmd_m: float
    t_cpa_s: float
    gs_mps: float
    vmd_m: float = 0.0
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
    cpa: "CpaGeometry | None" = None
    maneuvers: list = field(default_factory=list)


@dataclass
class Outage:
    """Link down (both directions) for datagrams sent in ``[start_s, end_s)`` (sim s)."""

    start_s: float
    end_s: float


@dataclass
class LinkSpec:
    """Delay specs are kept as given (str or dict); :func:`delay_model` builds the model."""

    up: Any = "const:4"
    down: Any = None
    epoch_s: float = 10.0
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
    group: str = "ID-1"
    wait: str = "map"
    wait_constant_s: float = 5.0
    blending: bool = True
    wait_threshold_s: float = 4.0
    projl: bool = True
    link_timeout_s: "float | None" = None
    stale_command_s: "float | None" = None


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
    duration_s: float = 240.0
    thresholds: str = "do365"
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
        if d["link"]["down"] is None:
            d["link"].pop("down")
        d["pilot"]["commands"] = [{k: v for k, v in c.items() if not (isinstance(v, float) and math.isnan(v))}
                                  for c in d["pilot"]["commands"]]
        if d["pilot"]["mode"] == "model":
            d["pilot"].pop("commands")
        d["pilot"]["model"] = {"response": d["pilot"].pop("response")}
        for sect in ("allocation", "expect"):
            d[sect] = {k: v for k, v in d[sect].items() if v is not None and v != []}
        if d["faults"]:
            d["faults"] = [{("kill" if k == "process" else k): v for k, v in f.items() if v is not None}
                           for f in d["faults"]]
        else:
            d.pop("faults")
        return d


# --------------------------------------------------------------------------------------------
# node-level validation

class _V:
    """Validator over a composed YAML node tree; errors carry ``file:line: field: message``."""

    def __init__(self, source: str):
        self.source = source
        self._cons = yaml.constructor.SafeConstructor()

    def fail(self, node: "yaml.Node | None", path: str, msg: str) -> "NoReturn":  # noqa: F821
        line = f":{node.start_mark.line + 1}" if node is not None and node.start_mark is not None else ""
        raise FileFormatError(f"{self.source}{line}: {path or '<top>'}: {msg}")

    def scalar(self, node, path):
        if not isinstance(node, yaml.ScalarNode):
            kind = "a mapping" if isinstance(node, yaml.MappingNode) else "a list"
            self.fail(node, path, f"expected a value, got {kind}")
        try:
            return self._cons.construct_object(node, deep=True)
        except yaml.YAMLError as exc:
            self.fail(node, path, f"bad value: {getattr(exc, 'problem', exc)}")

    def number(self, node, path, lo=None, hi=None, lo_open=False, hi_open=False) -> float:
        v = self.scalar(node, path)
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            self.fail(node, path, f"must be a number, got {v!r}")
        v = float(v)
        if not math.isfinite(v):
            self.fail(node, path, f"must be finite, got {v!r}")
        bad = (lo is not None and (v < lo or (lo_open and v == lo))) or \
              (hi is not None and (v > hi or (hi_open and v == hi)))
        if bad:
            lb = "(" if lo_open else "["
            rb = ")" if hi_open else "]"
            self.fail(node, path, f"must be within {lb}{'-inf' if lo is None else f'{lo:g}'}, "
                                  f"{'inf' if hi is None else f'{hi:g}'}{rb}, got {v:g}")
        return v

    def integer(self, node, path, lo=None, hi=None) -> int:
        v = self.scalar(node, path)
        if isinstance(v, bool) or not isinstance(v, int):
            self.fail(node, path, f"must be an integer, got {v!r}")
        if (lo is not None and v < lo) or (hi is not None and v > hi):
            self.fail(node, path, f"must be within [{lo}, {hi}], got {v}")
        return v

    def boolean(self, node, path) -> bool:
        v = self.scalar(node, path)
        if not isinstance(v, bool):
            self.fail(node, path, f"must be true or false, got {v!r}")
        return v

    def string(self, node, path, choices=None, maxlen=None) -> str:
        v = self.scalar(node, path)
        if not isinstance(v, str):
            self.fail(node, path, f"must be a string, got {v!r}")
        if choices is not None and v not in choices:
            self.fail(node, path, f"must be one of {', '.join(choices)}, got {v!r}")
        if maxlen is not None and len(v) > maxlen:
            self.fail(node, path, f"must be at most {maxlen} characters, got {len(v)}")
        return v

    def seq(self, node, path, min_len=0, max_len=None) -> list:
        if not isinstance(node, yaml.SequenceNode):
            self.fail(node, path, "must be a list")
        n = len(node.value)
        if n < min_len or (max_len is not None and n > max_len):
            self.fail(node, path, f"must have {min_len}..{max_len if max_len is not None else 'any'} items, got {n}")
        return node.value

    def mapping(self, node, path, required: "set[str]", optional: "set[str]") -> dict:
        """Return ``{key: value_node}``; unknown, duplicate or missing keys fail."""
        if not isinstance(node, yaml.MappingNode):
            self.fail(node, path, "must be a mapping (key: value)")
        out: dict = {}
        allowed = required | optional
        for knode, vnode in node.value:
            key = self.scalar(knode, path)
            sub = f"{path}.{key}" if path else str(key)
            if not isinstance(key, str) or key not in allowed:
                self.fail(knode, sub, f"unknown key; allowed: {', '.join(sorted(allowed))}")
            if key in out:
                self.fail(knode, sub, "duplicate key")
            out[key] = vnode
        missing = sorted(required - set(out))
        if missing:
            self.fail(node, f"{path}.{missing[0]}" if path else missing[0], "missing required field")
        return out

    def opt(self, m: dict, key: str, path: str, conv: Callable, default=None, **kw):
        if key not in m:
            return default
        return conv(m[key], f"{path}.{key}" if path else key, **kw)


def _state(v: _V, node, path, dur) -> InitialState:
    m = v.mapping(node, path, {"alt_m", "gs_mps", "track_deg"}, {"x_m", "y_m", "vs_mps"})
    return InitialState(
        x_m=v.opt(m, "x_m", path, v.number, 0.0, lo=-100_000, hi=100_000),
        y_m=v.opt(m, "y_m", path, v.number, 0.0, lo=-100_000, hi=100_000),
        alt_m=v.opt(m, "alt_m", path, v.number, lo=0, hi=20_000),
        gs_mps=v.opt(m, "gs_mps", path, v.number, lo=5, hi=350),
        track_deg=v.opt(m, "track_deg", path, v.number, lo=0, hi=360, hi_open=True),
        vs_mps=v.opt(m, "vs_mps", path, v.number, 0.0, lo=-50, hi=50))


def _intruder(v: _V, node, path, idx: int, dur: float) -> IntruderSpec:
    m = v.mapping(node, path, set(), {"id", "callsign", "initial", "cpa", "maneuvers"})
    if ("initial" in m) == ("cpa" in m):
        v.fail(node, path, "give exactly one of 'initial' (state at t = 0) or 'cpa' (closest-approach geometry)")
    spec = IntruderSpec(id=v.opt(m, "id", path, v.integer, 1000 + idx, lo=1, hi=0xFFFFFF),
                        callsign=v.opt(m, "callsign", path, v.string, f"INTR{idx + 1}", maxlen=8))
    if "initial" in m:
        p = f"{path}.initial"
        v.mapping(m["initial"], p, {"x_m", "y_m", "alt_m", "gs_mps", "track_deg"}, {"vs_mps"})
        spec.initial = _state(v, m["initial"], p, dur)
    else:
        p = f"{path}.cpa"
        mm = v.mapping(m["cpa"], p, {"angle_deg", "hmd_m", "t_cpa_s", "gs_mps"}, {"vmd_m", "vs_mps"})
        spec.cpa = CpaGeometry(
            angle_deg=v.opt(mm, "angle_deg", p, v.number, lo=0, hi=360, hi_open=True),
            hmd_m=v.opt(mm, "hmd_m", p, v.number, lo=-5000, hi=5000),
            t_cpa_s=v.opt(mm, "t_cpa_s", p, v.number, lo=0, hi=dur, lo_open=True),
            gs_mps=v.opt(mm, "gs_mps", p, v.number, lo=5, hi=350),
            vmd_m=v.opt(mm, "vmd_m", p, v.number, 0.0, lo=-1000, hi=1000),
            vs_mps=v.opt(mm, "vs_mps", p, v.number, 0.0, lo=-50, hi=50))
    if "maneuvers" in m:
        prev_end = 0.0
        for j, mn in enumerate(v.seq(m["maneuvers"], f"{path}.maneuvers", max_len=64)):
            p = f"{path}.maneuvers[{j}]"
            mm = v.mapping(mn, p, {"start_s", "end_s"}, {"turn_rate_dps", "accel_mps2", "vertical_accel_mps2"})
            start = v.opt(mm, "start_s", p, v.number, lo=prev_end, hi=dur, hi_open=True)
            end = v.opt(mm, "end_s", p, v.number, lo=start, hi=dur, lo_open=True)
            spec.maneuvers.append(Maneuver(
                start, end,
                turn_rate_dps=v.opt(mm, "turn_rate_dps", p, v.number, 0.0, lo=-10, hi=10),
                accel_mps2=v.opt(mm, "accel_mps2", p, v.number, 0.0, lo=-5, hi=5),
                vertical_accel_mps2=v.opt(mm, "vertical_accel_mps2", p, v.number, 0.0, lo=-10, hi=10)))
            prev_end = end
    return spec


def _delay(v: _V, node, path):
    """A latency spec string or dict, checked by building the model (daa_sil.models.latency)."""
    from daa_sil.models import latency

    try:
        if isinstance(node, yaml.ScalarNode):
            spec = v.string(node, path)
            latency.parse_delay_spec(spec)
            return spec
        if isinstance(node, yaml.MappingNode):
            d = {k: v.scalar(val, f"{path}.{k}") for k, val in
                 v.mapping(node, path, {"type"}, {"seconds", "mean_s", "sd_s", "lo_s", "hi_s", "file"}).items()}
            latency.delay_model_from_dict(d, where=path)
            return d
    except UsageError as exc:
        v.fail(node, path, str(exc))
    v.fail(node, path, "must be a delay spec string (e.g. const:4) or a mapping with 'type'")


def _link(v: _V, node, path, dur) -> LinkSpec:
    m = v.mapping(node, path, set(), {"up", "down", "epoch_s", "loss", "outages", "dup", "reorder"})
    ls = LinkSpec(up=_delay(v, m["up"], f"{path}.up") if "up" in m else "const:4",
                  down=_delay(v, m["down"], f"{path}.down") if "down" in m else None,
                  epoch_s=v.opt(m, "epoch_s", path, v.number, 10.0, lo=0, hi=600),
                  loss=v.opt(m, "loss", path, v.number, 0.0, lo=0, hi=1, hi_open=True),
                  dup=v.opt(m, "dup", path, v.number, 0.0, lo=0, hi=1, hi_open=True),
                  reorder=v.opt(m, "reorder", path, v.number, 0.0, lo=0, hi=1, hi_open=True))
    if "outages" in m:
        for j, on in enumerate(v.seq(m["outages"], f"{path}.outages", max_len=64)):
            p = f"{path}.outages[{j}]"
            mm = v.mapping(on, p, {"start_s", "end_s"}, set())
            start = v.opt(mm, "start_s", p, v.number, lo=0, hi=dur)
            ls.outages.append(Outage(start, v.opt(mm, "end_s", p, v.number, lo=start, lo_open=True)))
    return ls


def _pilot(v: _V, node, path, dur) -> PilotSpec:
    m = v.mapping(node, path, set(), {"mode", "model", "commands"})
    ps = PilotSpec(mode=v.opt(m, "mode", path, v.string, "model", choices=("model", "scripted")))
    if "model" in m:
        mm = v.mapping(m["model"], f"{path}.model", set(), {"response"})
        ps.response = v.opt(mm, "response", f"{path}.model", v.string, "deterministic", choices=PILOT_RESPONSES)
    if ps.mode == "model" and "commands" in m:
        v.fail(m["commands"], f"{path}.commands", "only allowed with mode: scripted")
    if ps.mode == "scripted":
        if "commands" not in m:
            v.fail(node, f"{path}.commands", "missing required field (mode: scripted)")
        items = v.seq(m["commands"], f"{path}.commands", min_len=1, max_len=1000)
        raw = []
        prev = -1.0
        for j, cn in enumerate(items):
            p = f"{path}.commands[{j}]"
            mm = v.mapping(cn, p, {"t_s"}, {"until_s", "track_deg", "vs_mps", "gs_mps"})
            t = v.opt(mm, "t_s", p, v.number, lo=0, hi=dur)
            if t <= prev:
                v.fail(mm["t_s"], f"{p}.t_s", f"must be later than the previous command's t_s ({prev:g})")
            prev = t
            if not {"track_deg", "vs_mps", "gs_mps"} & set(mm):
                v.fail(cn, p, "needs at least one of track_deg, vs_mps, gs_mps")
            until = v.opt(mm, "until_s", p, v.number, None, lo=t, hi=dur, lo_open=True)
            raw.append((ScriptedCommand(
                t, until if until is not None else math.nan,
                track_deg=v.opt(mm, "track_deg", p, v.number, math.nan, lo=0, hi=360, hi_open=True),
                vs_mps=v.opt(mm, "vs_mps", p, v.number, math.nan, lo=-50, hi=50),
                gs_mps=v.opt(mm, "gs_mps", p, v.number, math.nan, lo=5, hi=350)), mm.get("until_s")))
        for j, (c, unode) in enumerate(raw):
            nxt = raw[j + 1][0].t_s if j + 1 < len(raw) else dur
            if math.isnan(c.until_s):
                c.until_s = nxt
            elif c.until_s > nxt:
                v.fail(unode, f"{path}.commands[{j}].until_s", f"must not pass the next command's t_s ({nxt:g})")
            ps.commands.append(c)
    return ps


def _allocation(v: _V, node, path) -> AllocationSpec:
    from daa_sil.agent import WAIT_MODES
    from daa_sil.config.groups import group_spec, group_table

    m = v.mapping(node, path, set(), {"group", "wait", "wait_constant_s", "blending", "wait_threshold_s", "projl",
                                      "link_timeout_s", "stale_command_s"})
    group = v.opt(m, "group", path, v.string, "ID-1", choices=tuple(group_table()))
    g = group_spec(group).policy()
    return AllocationSpec(
        group=group,
        wait=v.opt(m, "wait", path, v.string, g.wait_mode, choices=WAIT_MODES),
        wait_constant_s=v.opt(m, "wait_constant_s", path, v.number, g.constant_wait_s, lo=0, hi=120),
        blending=v.opt(m, "blending", path, v.boolean, g.blending),
        wait_threshold_s=v.opt(m, "wait_threshold_s", path, v.number, g.wait_threshold_s, lo=0, hi=120),
        projl=v.opt(m, "projl", path, v.boolean, g.projl),
        link_timeout_s=v.opt(m, "link_timeout_s", path, v.number, None, lo=0, hi=120, lo_open=True),
        stale_command_s=v.opt(m, "stale_command_s", path, v.number, None, lo=0, hi=120, lo_open=True))


def _expect(v: _V, node, path, dur) -> Expectation:
    m = v.mapping(node, path, set(), {"lowc", "nmac", "decisions_include", "decisions_exclude",
                                      "min_range_at_least_m", "link_lost_by_s"})

    def names(n, p):
        return [v.string(x, f"{p}[{i}]", choices=DECISIONS) for i, x in enumerate(v.seq(n, p))]

    return Expectation(
        lowc=v.opt(m, "lowc", path, v.boolean), nmac=v.opt(m, "nmac", path, v.boolean),
        decisions_include=v.opt(m, "decisions_include", path, names, []),
        decisions_exclude=v.opt(m, "decisions_exclude", path, names, []),
        min_range_at_least_m=v.opt(m, "min_range_at_least_m", path, v.number, None, lo=0, hi=1e6),
        link_lost_by_s=v.opt(m, "link_lost_by_s", path, v.number, None, lo=0, hi=dur))


def _faults(v: _V, node, path, dur) -> list:
    out = []
    for j, fn in enumerate(v.seq(node, path, max_len=16)):
        p = f"{path}[{j}]"
        m = v.mapping(fn, p, {"kill", "at_s"}, {"restart_s", "signal"})
        at = v.opt(m, "at_s", p, v.number, lo=0, hi=dur, lo_open=True, hi_open=True)
        out.append(ProcessFault(
            process=v.opt(m, "kill", p, v.string, choices=FAULT_PROCESSES), at_s=at,
            restart_s=v.opt(m, "restart_s", p, v.number, None, lo=at, hi=dur, lo_open=True, hi_open=True),
            signal=v.opt(m, "signal", p, v.string, "KILL", choices=FAULT_SIGNALS)))
    for a, b in zip(out, out[1:]):
        end = a.restart_s if a.restart_s is not None else math.inf
        if a.process == b.process and b.at_s <= end:
            v.fail(node, path, f"faults of the same process must not overlap: {a.describe()} / {b.describe()}")
    return out


TOP_REQUIRED = {"name", "ownship", "intruders"}
TOP_OPTIONAL = {"description", "seed", "duration_s", "thresholds", "origin", "link", "pilot", "allocation", "expect",
                "faults"}


def _scenario(v: _V, root) -> Scenario:
    m = v.mapping(root, "", TOP_REQUIRED, TOP_OPTIONAL)
    dur = v.opt(m, "duration_s", "", v.number, 240.0, lo=1, hi=3600)
    sc = Scenario(
        name=v.opt(m, "name", "", v.string, maxlen=64),
        description=v.opt(m, "description", "", v.string, ""),
        seed=v.opt(m, "seed", "", v.integer, 1, lo=0, hi=2 ** 63 - 1),
        duration_s=dur,
        thresholds=v.opt(m, "thresholds", "", v.string, "do365", choices=("do365", "paper", "daidalus")),
        ownship=_state(v, m["ownship"], "ownship", dur),
        intruders=[_intruder(v, n, f"intruders[{i}]", i, dur)
                   for i, n in enumerate(v.seq(m["intruders"], "intruders", 1, MAX_INTRUDERS))],
        source=v.source)
    ids = [i.id for i in sc.intruders]
    if len(set(ids)) != len(ids):
        v.fail(m["intruders"], "intruders", f"intruder ids must be unique, got {ids}")
    if "origin" in m:
        om = v.mapping(m["origin"], "origin", set(), {"lat_deg", "lon_deg", "alt_m"})
        sc.origin = Origin(lat_deg=v.opt(om, "lat_deg", "origin", v.number, 37.4, lo=-80, hi=80),
                           lon_deg=v.opt(om, "lon_deg", "origin", v.number, -122.05, lo=-180, hi=180),
                           alt_m=v.opt(om, "alt_m", "origin", v.number, 0.0, lo=-500, hi=9000))
    if "link" in m:
        sc.link = _link(v, m["link"], "link", dur)
    if "pilot" in m:
        sc.pilot = _pilot(v, m["pilot"], "pilot", dur)
    if "allocation" in m:
        sc.allocation = _allocation(v, m["allocation"], "allocation")
    if "expect" in m:
        sc.expect = _expect(v, m["expect"], "expect", dur)
    if "faults" in m:
        sc.faults = _faults(v, m["faults"], "faults", dur)
    return sc


# --------------------------------------------------------------------------------------------
# public API

def parse_scenario(text: str, source: str = "<string>") -> Scenario:
    """Validate YAML ``text``; errors name ``source``, the line and the field."""
    try:
        root = yaml.compose(text, Loader=yaml.SafeLoader)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        line = f":{mark.line + 1}" if mark is not None else ""
        raise FileFormatError(f"{source}{line}: not valid YAML: {getattr(exc, 'problem', None) or exc}") from None
    if root is None:
        raise FileFormatError(f"{source}: empty scenario file")
    return _scenario(_V(source), root)


def load_scenario(path: "str | os.PathLike") -> Scenario:
    """Load and validate a scenario file (FileFormatError naming file/line/field on any problem)."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise FileFormatError(f"{p}: scenario file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise FileFormatError(f"{p}: cannot read scenario: {getattr(exc, 'strerror', None) or exc}") from None
    return parse_scenario(text, str(p))


def scenario_from_dict(d: dict, source: str = "<dict>") -> Scenario:
    """Validate a plain dict (round-trips through YAML so the same checks apply)."""
    return parse_scenario(yaml.safe_dump(d, sort_keys=False), source)


def dump_scenario(sc: Scenario) -> str:
    """YAML text of ``sc``."""
    return yaml.safe_dump(sc.to_dict(), sort_keys=False)


def save_scenario(sc: Scenario, path: "str | os.PathLike", overwrite: bool = False) -> Path:
    """Write ``sc`` as YAML atomically."""
    from daa_sil.files import atomic_write_text

    return atomic_write_text(path, dump_scenario(sc), overwrite=overwrite)


def delay_spec_string(spec) -> str:
    """A scenario delay spec (str or dict) as the ``--delay`` string of ``daa-sil shim``."""
    from daa_sil.models import latency

    return spec if isinstance(spec, str) else latency.delay_model_from_dict(spec).spec()


def delay_models(sc: Scenario):
    """``(up, down)`` :class:`daa_sil.models.latency.DelayModel` objects of the scenario's link."""
    from daa_sil.models import latency

    def build(spec):
        return latency.parse_delay_spec(spec) if isinstance(spec, str) else latency.delay_model_from_dict(spec)

    up = build(sc.link.up)
    return up, (build(sc.link.down) if sc.link.down is not None else up)


def ownship_state(sc: Scenario):
    """The ownship at t = 0 as an ``(1,)`` :class:`daa_sil.geometry.kinematics.AircraftState`."""
    import numpy as np

    from daa_sil.geometry.kinematics import AircraftState

    o = sc.ownship
    return AircraftState(np.array([o.x_m]), np.array([o.y_m]), np.array([o.alt_m]), np.array([o.gs_mps]),
                         np.array([math.radians(o.track_deg)]), np.array([o.vs_mps]))


def encounter_set(sc: Scenario, encounter_id: int = 0):
    """The scenario as a one-encounter :class:`daa_sil.models.encounters.EncounterSet` (N = 1, M intruders).

    ``cpa`` intruders are placed by :func:`daa_sil.models.encounters.encounter_from_geometry` against the
    scenario's (unmaneuvered) ownship; ``initial`` intruders start as given. Scripts become the
    set's segments. This is the one conversion the SIL vehicle and fast-time parity runs share.
    """
    import numpy as np

    from daa_sil.models import encounters as enc
    from daa_sil.geometry.kinematics import AircraftState

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
                c = spec.cpa
                one = enc.encounter_from_geometry(
                    [enc.IntruderGeometry(c.angle_deg, c.hmd_m, c.t_cpa_s, c.gs_mps, c.vmd_m, c.vs_mps, mv)],
                    own=own, duration_s=sc.duration_s, dt_s=1.0, encounter_id=encounter_id, seed=sc.seed)
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
                            duration_s=float(sc.duration_s), dt_s=1.0, config={"source": f"scenario:{sc.name}"})


def check_expectation(exp: Expectation, result: dict) -> list[str]:
    """Violations of ``exp`` by a run ``result`` (keys ``lowc``, ``nmac``, ``min_range_m``,
    ``decision_counts``, ``first_link_lost_s``); empty list = all expectations hold."""
    bad: list[str] = []
    if exp.lowc is not None and bool(result["lowc"]) != exp.lowc:
        bad.append(f"expected lowc={str(exp.lowc).lower()}, got {str(bool(result['lowc'])).lower()}")
    if exp.nmac is not None and bool(result["nmac"]) != exp.nmac:
        bad.append(f"expected nmac={str(exp.nmac).lower()}, got {str(bool(result['nmac'])).lower()}")
    counts = result.get("decision_counts", {})
    for d in exp.decisions_include:
        if counts.get(d, 0) <= 0:
            bad.append(f"expected decision '{d}' to appear, it did not")
    for d in exp.decisions_exclude:
        if counts.get(d, 0) > 0:
            bad.append(f"expected no '{d}' decision, got {counts[d]}")
    if exp.min_range_at_least_m is not None:
        mr = result.get("min_range_m")
        if mr is None or not mr >= exp.min_range_at_least_m:
            bad.append(f"expected min range >= {exp.min_range_at_least_m:g} m, got {mr}")
    if exp.link_lost_by_s is not None:
        t = result.get("first_link_lost_s")
        if t is None or t > exp.link_lost_by_s:
            bad.append(f"expected link_lost by t = {exp.link_lost_by_s:g} s, got {t}")
    return bad


__all__ = ["Scenario", "InitialState", "CpaGeometry", "Maneuver", "IntruderSpec", "LinkSpec", "Outage",
           "PilotSpec", "ScriptedCommand", "AllocationSpec", "Expectation", "Origin", "DECISIONS",
           "ProcessFault", "FAULT_PROCESSES",
           "parse_scenario", "load_scenario", "scenario_from_dict", "dump_scenario", "save_scenario",
           "delay_models", "delay_spec_string", "check_expectation", "encounter_set", "ownship_state"]
