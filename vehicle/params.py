"""The vehicle's parameters: the allocation agent's real settings, for the MAVLink parameter protocol.

Sans-IO: :class:`ParamTable` reads the current :class:`daa_sil.agent.step.AllocationPolicy` and turns
a PARAM_SET into a new policy (``dataclasses.replace``); the node swaps it in at the next step
boundary and answers with PARAM_VALUE.

=============  ======  =====================================  ===========  ==========
name           type    meaning (AllocationPolicy field)       range        writable
=============  ======  =====================================  ===========  ==========
DAA_ENABLE     INT8    onboard agent on (1) / off (0)          0, 1         yes
               ``enabled``
DAA_WT         REAL32  wait threshold W_T, s                    [0, 120]     yes
               ``wait_threshold_s``
DAA_PROJL_S    REAL32  ProjL look-ahead, s                      [0, 120]     yes
               ``projl_horizon_s``
DAA_STALE_S    REAL32  stale-command limit, s                   [1, 120]     yes
               ``stale_command_s``
DAA_LINK_TO    REAL32  link-lost timeout, s                     [1, 120]     yes
               ``link_timeout_s``
DAA_WAIT_MODE  INT8    wait function: 0 none, 1 constant,       --           read-only
                       2 MDP map, 3 always (``wait_mode``)
DAA_WAIT_CONST REAL32  constant wait, s (``constant_wait_s``)   --           read-only
DAA_PRESET     INT8    threshold preset: 0 do365, 1 paper       --           read-only
=============  ======  =====================================  ===========  ==========

The parameters of the per-group settings (DAA_WT ... DAA_WAIT_CONST) are made from their
:class:`~daa_sil.config.settings.Setting` (``mavlink``, ``writable``, range, help): a setting
registered with a parameter name has one here, with no edit to this module. Ranges are those of
every other input; DAA_STALE_S and
DAA_LINK_TO start at :data:`MIN_TIMEOUT_S` (one sim step, 1 s): the GCS sends at most once per step,
so a link timeout shorter than a step declares the link lost between any two packets, and a stale
limit shorter than a step makes every command that crossed the link stale; a value like 1.4e-45 s
(the smallest float32) is no setting anyone means. ``-0.0`` is stored and reported as ``0.0``.
Integer parameters travel C-cast (the
float value of the integer, ``MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST``), as ArduPilot's do.
Per the parameter protocol a rejected PARAM_SET (read-only, out of range, not a number, not an
integer for an integer parameter) is answered with a PARAM_VALUE holding the **current** value;
an unknown name gets no PARAM_VALUE. The reason goes out as a STATUSTEXT either way.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, replace
from typing import Callable

from daa_sil.config.settings import STALE_COMMAND, Setting, group_settings
from daa_sil.link.codec import mavlink as M

REAL32, INT8 = M.MAV_PARAM_TYPE_REAL32, M.MAV_PARAM_TYPE_INT8
#: smallest DAA_STALE_S / DAA_LINK_TO a PARAM_SET may give (s): one sim step (see the module docstring)
MIN_TIMEOUT_S = STALE_COMMAND.lo


@dataclass(frozen=True)
class ParamSpec:
    """One parameter: wire name (<= 16 chars), MAV_PARAM_TYPE, getter, and (if writable) how to set it."""

    name: str
    ptype: int
    doc: str
    get: Callable  #: policy -> value (float)
    field: "str | None" = None  #: AllocationPolicy field written by PARAM_SET (None = read-only)
    lo: float = -math.inf
    hi: float = math.inf
    integer: bool = False

    @property
    def writable(self) -> bool:
        return self.field is not None

    def range_text(self) -> str:
        if self.integer:
            return f"{int(self.lo)}..{int(self.hi)}"
        return f"[{self.lo:g}, {self.hi:g}]"


@dataclass(frozen=True)
class SetResult:
    """Outcome of a PARAM_SET: ``status`` accepted / unchanged / read_only / out_of_range / not_integer /
    unknown; ``policy`` the new policy when accepted (else None); ``value`` what PARAM_VALUE reports."""

    status: str
    spec: "ParamSpec | None"
    value: float
    old: float
    policy: object = None
    reason: str = ""

    @property
    def ok(self) -> bool:
        return self.status in ("accepted", "unchanged")


def setting_param(s: Setting) -> ParamSpec:
    """The REAL32 parameter of a per-group setting (:attr:`Setting.mavlink`): its policy field, range
    and help; read-only unless :attr:`Setting.writable`."""
    unit = f" ({s.unit})" if s.unit else ""
    return ParamSpec(s.mavlink, REAL32, f"{s.help}{unit}" + ("" if s.writable else ", read-only"),
                     lambda p, name=s.name: float(getattr(p, name)), s.name if s.writable else None,
                     *(s.range if s.writable else (-math.inf, math.inf)))


def float32(x: float) -> float:
    """The value as it travels in a float32 MAVLink field."""
    return struct.unpack("<f", struct.pack("<f", x))[0] if math.isfinite(x) else x


class ParamTable:
    """The parameter list over a policy (``preset``: the scenario's threshold preset, read-only)."""

    def __init__(self, preset: str):
        from daa_sil.config.policy import WAIT_MODES  # lazy: start-up time
        from daa_sil.geometry.thresholds import PRESETS  # lazy: start-up time

        presets = tuple(PRESETS)
        code = presets.index(preset) if preset in presets else -1
        groups = [s for s in group_settings() if s.mavlink]  # every per-group setting with a parameter
        self.specs: tuple[ParamSpec, ...] = (
            ParamSpec("DAA_ENABLE", INT8, "onboard allocation agent on (1) / off (0)",
                      lambda p: float(bool(p.enabled)), "enabled", 0, 1, integer=True),
            *(setting_param(s) for s in groups if s.writable),
            ParamSpec("DAA_WAIT_MODE", INT8, f"wait function: {', '.join(f'{i} {n}' for i, n in enumerate(WAIT_MODES))}"
                      " (read-only)", lambda p: float(WAIT_MODES.index(p.wait_mode))),
            *(setting_param(s) for s in groups if not s.writable),
            ParamSpec("DAA_PRESET", INT8, f"threshold preset: {', '.join(f'{i} {n}' for i, n in enumerate(presets))}"
                      " (read-only)", lambda p, c=code: float(c)),
        )
        self._by_name = {s.name: i for i, s in enumerate(self.specs)}

    def __len__(self) -> int:
        return len(self.specs)

    def find(self, name: "str | bytes | None" = None, index: int = -1) -> "tuple[int, ParamSpec] | None":
        """``(index, spec)`` by ``index`` (>= 0) or else by exact ``name``; None if there is none."""
        if index is not None and int(index) >= 0:
            i = int(index)
            return (i, self.specs[i]) if i < len(self.specs) else None
        if isinstance(name, bytes):
            name = name.split(b"\0", 1)[0].decode("ascii", "replace")
        i = self._by_name.get(str(name or "").split("\0", 1)[0])
        return None if i is None else (i, self.specs[i])

    def value(self, spec: ParamSpec, policy) -> float:
        return float32(spec.get(policy)) + 0.0  # never -0.0

    def set(self, name, value: float, policy) -> SetResult:
        """Check a PARAM_SET of ``name`` to ``value`` against ``policy`` (never raises on content)."""
        found = self.find(name)
        if found is None:
            shown = name.decode("ascii", "replace") if isinstance(name, bytes) else str(name)
            shown = shown.split("\0", 1)[0]
            return SetResult("unknown", None, math.nan, math.nan, reason=f"unknown parameter {shown!r}")
        _, spec = found
        old = self.value(spec, policy)
        v = float(value) + 0.0  # -0.0 -> 0.0: a sign on zero is not a setting
        if not spec.writable:
            return SetResult("read_only", spec, old, old, reason=f"{spec.name} is read-only")
        if not math.isfinite(v) or v > spec.hi or v < spec.lo:
            return SetResult("out_of_range", spec, old, old,
                             reason=f"{spec.name} {value!r} out of range {spec.range_text()}; kept {old:g}")
        if spec.integer and v != round(v):
            return SetResult("not_integer", spec, old, old, reason=f"{spec.name} must be an integer, got {value!r}")
        new = float32(v)
        if new == old:
            return SetResult("unchanged", spec, old, old, policy, reason=f"{spec.name} already {old:g}")
        target = bool(round(new)) if spec.field == "enabled" else new
        return SetResult("accepted", spec, new, old, replace(policy, **{spec.field: target}),
                         reason=f"{spec.name} {old:g} -> {new:g}")
