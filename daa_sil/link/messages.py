"""Builders and readers for the daa-sil messages, so nodes never hand-pack fields.

Times: every ``t_s`` argument is shared sim time in seconds; on the wire it is ms (``time_ms`` /
``time_boot_ms``, uint32). Tracks are degrees clockwise from north on the wire; builders that take
agent records convert from the agent's compass radians.

Enum codes on the wire equal the agent's integer codes (``daa_sil.agent.step`` / ``daa_sil.daa.config``
name tables); :data:`CODES` maps names to codes for each field kind.

Pilot commands: :func:`pilot_maneuver` builds the custom PILOT_MANEUVER (send time + command
sequence number + absolute track / vertical speed / ground speed, NaN = keep). A stock GCS
(MAVProxy, QGC) can instead send SET_POSITION_TARGET_GLOBAL_INT or _LOCAL_NED with velocity
enabled (e.g. ``type_mask`` 0x09C7 / 0x0DC7); :func:`pilot_command_from` maps it as
``track = atan2(vy, vx)`` (NED: vx north, vy east), ``gs = hypot(vx, vy)``, ``vs = -vz``, send time
= ``time_boot_ms`` (must be sim time), ``cmd_seq`` = the MAVLink header sequence (0-255, wraps).
"""

from __future__ import annotations

import math
from typing import NamedTuple, Sequence

import numpy as np

from ..errors import UsageError
from .codec import mavlink as d

BAND_SLOTS = 16
_UINT32 = 2**32 - 1


def _enum_names(enum: str, prefix: str) -> tuple[str, ...]:
    entries = d.enums[enum]
    top = max(k for k in entries if entries[k].name.startswith(prefix) and not entries[k].name.endswith("ENUM_END"))
    return tuple(entries[i].name[len(prefix):].lower() for i in range(top + 1))


#: wire code tables: field kind -> names in code order (index = code)
NAMES = {
    "decision": _enum_names("DAA_SIL_DECISION", "DAA_SIL_DECISION_"),
    "authority": _enum_names("DAA_SIL_AUTHORITY", "DAA_SIL_AUTHORITY_"),
    "rule": tuple("-" if n == "none" else n for n in _enum_names("DAA_SIL_RULE", "DAA_SIL_RULE_")),
    "axis": _enum_names("DAA_SIL_AXIS", "DAA_SIL_AXIS_"),
    "dir": _enum_names("DAA_SIL_DIRECTION", "DAA_SIL_DIRECTION_"),
    "region": _enum_names("DAA_SIL_BAND_REGION", "DAA_SIL_BAND_REGION_"),
    "dimension": _enum_names("DAA_SIL_BAND_DIMENSION", "DAA_SIL_BAND_DIMENSION_"),
}
#: field kind -> {name: code}
CODES = {kind: {n: i for i, n in enumerate(names)} for kind, names in NAMES.items()}


def wire_int(x, lo: int, hi: int) -> "int | None":
    """A number from the wire that must be an integer within ``[lo, hi]`` (e.g. a message id carried in
    a COMMAND_LONG float parameter): the int, or None for NaN, +-inf, fractions and values outside the
    range (``int(nan)`` would raise, ``int(1e30)`` or ``int(2.7)`` would pass an absurd value on). Never raises."""
    try:
        v = float(x)
    except (TypeError, ValueError, OverflowError):
        return None
    if not (lo <= v <= hi) or v != math.floor(v):
        return None
    return int(v)


def ms(t_s: float) -> int:
    """Sim seconds -> uint32 milliseconds (rounded); one-line UsageError if out of range."""
    if not (isinstance(t_s, (int, float, np.floating, np.integer)) and math.isfinite(t_s)):
        raise UsageError(f"sim time must be a finite number of seconds, got {t_s!r}")
    v = int(round(float(t_s) * 1000.0))
    if not 0 <= v <= _UINT32:
        raise UsageError(f"sim time {t_s!r} s is outside the uint32 millisecond range [0, {_UINT32 / 1000:.0f}] s")
    return v


def sim_tick(k: int, t_s: float):
    """SIM_TICK for step ``k`` at sim time ``t_s`` (s)."""
    return d.MAVLink_sim_tick_message(int(k), ms(t_s))


def sim_tick_ack(k: int, t_s: float, sent: int = 0):
    """SIM_TICK_ACK for step ``k`` (echoing ``t_s``); ``sent`` = messages the GCS sent this step."""
    return d.MAVLink_sim_tick_ack_message(int(k), ms(t_s), min(int(sent), 0xFFFF))


def pilot_maneuver(t_sent_s: float, cmd_seq: int, track_deg: float = math.nan, vs: float = math.nan,
                   gs: float = math.nan, target_system: int = 1, target_component: int = 1):
    """PILOT_MANEUVER: track deg (clockwise from north), vs m/s (up +), gs m/s; NaN = keep."""
    if not 1 <= int(cmd_seq) <= _UINT32:
        raise UsageError(f"cmd_seq must be within [1, {_UINT32}], got {cmd_seq!r}")
    trk = float(track_deg) % 360.0 if math.isfinite(track_deg) else math.nan
    return d.MAVLink_pilot_maneuver_message(ms(t_sent_s), int(cmd_seq), target_system, target_component,
                                            trk, float(vs), float(gs))


class PilotCommand(NamedTuple):
    """A pilot command as the vehicle sees it. Times s, track deg, speeds m/s (NaN = keep)."""

    t_sent_s: float
    cmd_seq: int
    track_deg: float
    vs: float
    gs: float
    source: str  # message type it came from


_VEL_IGNORE = 0b111000  # type_mask bits 3-5: ignore vx, vy, vz


def pilot_command_from(msg) -> "PilotCommand | None":
    """Read a pilot command from PILOT_MANEUVER or SET_POSITION_TARGET_{GLOBAL_INT,LOCAL_NED}.

    Returns None for other messages or a SET_POSITION_TARGET without velocity.
    """
    t = msg.get_type()
    if t == "PILOT_MANEUVER":
        return PilotCommand(msg.time_boot_ms / 1000.0, msg.cmd_seq, msg.track_deg, msg.vs, msg.gs, t)
    if t in ("SET_POSITION_TARGET_GLOBAL_INT", "SET_POSITION_TARGET_LOCAL_NED"):
        if msg.type_mask & _VEL_IGNORE:
            return None
        vn, ve, vd = msg.vx, msg.vy, msg.vz
        return PilotCommand(msg.time_boot_ms / 1000.0, msg.get_seq(), math.degrees(math.atan2(ve, vn)) % 360.0,
                            -vd, math.hypot(vn, ve), t)
    return None


def daa_bands(t_s: float, dimension: "str | int", lower: Sequence[float], upper: Sequence[float],
              regions: Sequence["str | int"]) -> list:
    """DAA_BANDS message(s) for one dimension: 16 intervals per message, ``part``/``parts`` numbered.

    ``dimension``: ``track`` (deg), ``ground_speed`` (m/s), ``vertical_speed`` (m/s), ``altitude`` (m)
    or its code; ``regions``: names (``none far mid near recovery``) or codes. An empty list gives
    one message with ``count = 0`` (no bands).
    """
    dim = CODES["dimension"][dimension] if isinstance(dimension, str) else int(dimension)
    lo, hi = list(map(float, lower)), list(map(float, upper))
    try:
        reg = [CODES["region"][r] if isinstance(r, str) else int(r) for r in regions]
    except KeyError as exc:
        raise UsageError(f"unknown band region {exc.args[0]!r}; allowed: {', '.join(NAMES['region'])}") from None
    if not len(lo) == len(hi) == len(reg):
        raise UsageError(f"bands need equal numbers of lower, upper and regions, got {len(lo)}, {len(hi)}, {len(reg)}")
    parts = max(1, -(-len(lo) // BAND_SLOTS))
    if parts > 255:
        raise UsageError(f"too many band intervals ({len(lo)}); at most {255 * BAND_SLOTS}")
    out = []
    for p in range(parts):
        sl = slice(p * BAND_SLOTS, (p + 1) * BAND_SLOTS)
        n = len(lo[sl])
        pad = BAND_SLOTS - n
        out.append(d.MAVLink_daa_bands_message(ms(t_s), dim, n, p, parts, lo[sl] + [0.0] * pad,
                                               hi[sl] + [0.0] * pad, reg[sl] + [0] * pad))
    return out


def bands_from(msgs: Sequence) -> "dict[int, tuple[list[float], list[float], list[int]]]":
    """Reassemble DAA_BANDS messages of one time step: ``{dimension: (lower, upper, region codes)}``.

    Parts are ordered by ``part``; a dimension with missing parts is left out (incomplete).
    """
    by_dim: dict[int, dict[int, object]] = {}
    total: dict[int, int] = {}
    for m in msgs:
        if m.get_type() != "DAA_BANDS":
            continue
        by_dim.setdefault(m.dimension, {})[m.part] = m
        total[m.dimension] = m.parts
    out = {}
    for dim, parts in by_dim.items():
        if len(parts) != total[dim] or set(parts) != set(range(total[dim])):
            continue
        lo, hi, rg = [], [], []
        for p in range(total[dim]):
            m = parts[p]
            n = min(int(m.count), BAND_SLOTS)
            lo += list(m.lower[:n])
            hi += list(m.upper[:n])
            rg += list(m.region[:n])
        out[dim] = (lo, hi, rg)
    return out


def allocation_decision(t_s: float, record: dict, i: int = 0, pilot_cmd_seq: int = 0):
    """ALLOCATION_DECISION from row ``i`` of an agent decision record (``daa_sil.agent.step.DECISION_FIELDS``).

    Integer code fields are sent as is (same codes); ``cmd_trk`` is compass radians in the record
    and degrees on the wire; missing fields are sent as NaN / 0.
    """
    def f(name, default=math.nan):
        v = record.get(name)
        if v is None:
            return default
        v = np.asarray(v)
        return v.item() if v.ndim == 0 else v[i].item()

    def code(name):
        v = f(name, 0)
        return 0 if (isinstance(v, float) and not math.isfinite(v)) else int(v)

    trk = f("cmd_trk")
    return d.MAVLink_allocation_decision_message(
        ms(t_s), code("authority"), code("decision"), code("rule"), float(f("wait_s")), int(bool(f("projl", 0))),
        float(f("sm_pilot")), float(f("sm_exec")), code("pilot_axis"), code("pilot_dir"), code("exec_axis"),
        code("exec_dir"), math.degrees(trk) % 360.0 if math.isfinite(trk) else math.nan, float(f("cmd_vs")),
        float(f("cmd_gs")), int(pilot_cmd_seq), float(f("pilot_cmd_age_s")))
