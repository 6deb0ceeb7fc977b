"""Load, validate and save scenario YAML (schema: :mod:`daa_sil.sil.scenario.schema`).

Validation walks the composed YAML node tree, so every error names ``file:line: field: message``
and what is allowed. A hand-written walker rather than a schema library: see docs/sil.md,
"Scenario files".
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Callable

import yaml

from daa_sil.config.settings import DELAY_EPOCH, DURATION, SCENARIO_GROUP, SCENARIO_LINK, STANDARD_PRESET
from daa_sil.config.yaml_input import compose_yaml, read_yaml_text

from daa_sil.errors import FileFormatError, UsageError

from .schema import (MAX_INTRUDERS, PILOT_RESPONSES, DECISIONS, FAULT_PROCESSES, FAULT_SIGNALS, AllocationSpec, IntruderGeometry,
                     Expectation, InitialState, IntruderSpec, LinkSpec, Maneuver, Origin, Outage, PilotSpec, ProcessFault,
                     Scenario, ScriptedCommand)
from daa_sil.config.overrides import Overrides, notice, settings_of


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
        spec.cpa = IntruderGeometry(
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
    from daa_sil.models import delay_spec  # lazy: start-up time

    try:
        if isinstance(node, yaml.ScalarNode):
            spec = v.string(node, path)
            delay_spec.parse_delay_spec(spec)
            return spec
        if isinstance(node, yaml.MappingNode):
            d = {k: v.scalar(val, f"{path}.{k}") for k, val in
                 v.mapping(node, path, {"type"}, {"seconds", "mean_s", "sd_s", "lo_s", "hi_s", "file"}).items()}
            delay_spec.delay_model_from_dict(d, where=path)
            return d
    except UsageError as exc:
        v.fail(node, path, str(exc))
    v.fail(node, path, "must be a delay spec string (e.g. const:4) or a mapping with 'type'")


def _link(v: _V, node, path, dur) -> LinkSpec:
    m = v.mapping(node, path, set(), {"up", "down", "round_trip", "epoch_s", "loss", "outages", "dup", "reorder"})
    if "round_trip" in m and ("up" in m or "down" in m):
        v.fail(m["round_trip"], f"{path}.round_trip", "give either round_trip or up/down, not both")
    ls = LinkSpec(up=_delay(v, m["up"], f"{path}.up") if "up" in m else (None if "round_trip" in m else SCENARIO_LINK.default),
                  down=_delay(v, m["down"], f"{path}.down") if "down" in m else None,
                  round_trip=_delay(v, m["round_trip"], f"{path}.round_trip") if "round_trip" in m else None,
                  epoch_s=v.opt(m, "epoch_s", path, v.number, DELAY_EPOCH.default, lo=DELAY_EPOCH.lo, hi=DELAY_EPOCH.hi),
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
    from daa_sil.config.groups import group_spec, group_table  # lazy: start-up time
    from daa_sil.config.policy import WAIT_MODES  # lazy: start-up time

    m = v.mapping(node, path, set(), {"group", "wait", "blending", "projl", *Overrides.keys_read()})
    group = v.opt(m, "group", path, v.string, SCENARIO_GROUP.default, choices=tuple(group_table()))
    g = group_spec(group).policy()
    settings = Overrides()
    for s in settings_of():  # every per-group setting, by its name or an old key (with a notice)
        keys = [k for k in s.keys if k in m]
        if len(keys) > 1:
            v.fail(m[keys[1]], f"{path}.{keys[1]}", f"is {path}.{s.name}, given twice")
        elif keys:
            if keys[0] != s.name:
                notice(f"{v.source}: {path}.{keys[0]} is now called {path}.{s.name} (read as such)")
            value = v.opt(m, keys[0], path, v.number, None, lo=s.lo, hi=s.hi)
            if value is not None:
                settings = settings.with_(s, value)
    return AllocationSpec(
        group=group,
        wait=v.opt(m, "wait", path, v.string, g.wait_mode, choices=WAIT_MODES),
        blending=v.opt(m, "blending", path, v.boolean, g.blending),
        projl=v.opt(m, "projl", path, v.boolean, g.projl),
        settings=settings)


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
    dur = v.opt(m, "duration_s", "", v.number, DURATION.default, lo=DURATION.lo, hi=DURATION.hi)
    sc = Scenario(
        name=v.opt(m, "name", "", v.string, maxlen=64),
        description=v.opt(m, "description", "", v.string, ""),
        seed=v.opt(m, "seed", "", v.integer, 1, lo=0, hi=2 ** 63 - 1),
        duration_s=dur,
        thresholds=v.opt(m, "thresholds", "", v.string, STANDARD_PRESET.default, choices=("do365", "paper", "daidalus")),
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
    root = compose_yaml(text, source, "scenario")  # bounded size, depth and aliases; one-line errors
    if root is None:
        raise FileFormatError(f"{source}: empty scenario file")
    return _scenario(_V(source), root)


def load_scenario(path: "str | os.PathLike") -> Scenario:
    """Load and validate a scenario file (FileFormatError naming file/line/field on any problem)."""
    p = Path(path)
    try:
        text = read_yaml_text(p, "scenario")
    except FileNotFoundError:
        raise FileFormatError(f"{p}: scenario file not found") from None
    return parse_scenario(text, str(p))


def scenario_from_dict(d: dict, source: str = "<dict>") -> Scenario:
    """Validate a plain dict (round-trips through YAML so the same checks apply)."""
    return parse_scenario(yaml.safe_dump(d, sort_keys=False), source)


def dump_scenario(sc: Scenario) -> str:
    """YAML text of ``sc``."""
    return yaml.safe_dump(sc.to_dict(), sort_keys=False)


def save_scenario(sc: Scenario, path: "str | os.PathLike", overwrite: bool = False) -> Path:
    """Write ``sc`` as YAML atomically."""
    from daa_sil.files import atomic_write_text  # lazy: start-up time

    return atomic_write_text(path, dump_scenario(sc), overwrite=overwrite)
