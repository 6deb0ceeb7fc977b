"""Pilot command gate: absolute, idempotent setpoints under multi-second delay.

Each pilot command carries its send time (sim s) and a sequence number. The gate applies each
command at most once and never an older one after a newer one: a command is accepted only if
its ``(t_sent, seq)`` is strictly newer than the last accepted one *from the same source*
(sources: the MAVLink ``(sysid, compid)``). Duplicates (same seq re-delivered by the link or the
shim's ``dup``), replays and reordered stale commands are counted and dropped.
Commands stamped in the future (beyond ``max_future_s``) are forged or from an unsynchronised
clock: counted and dropped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from daa_sil.config.settings import VEHICLE_SYSID
from daa_sil.link.codec import mavlink as M


@dataclass(frozen=True)
class PilotCommand:
    """One accepted pilot command. ``nan`` fields mean keep current. Angles deg, speeds m/s."""

    t_sent: float  #: sim time the pilot sent it, s
    seq: int  #: command sequence number (>= 1)
    track_deg: float
    vs_mps: float
    gs_mps: float
    source: tuple = (255, 190)
    kind: str = "PILOT_MANEUVER"


@dataclass
class GateCounters:
    accepted: int = 0
    duplicate: int = 0
    older: int = 0
    future: int = 0
    invalid: int = 0


@dataclass
class CommandGate:
    """Accept each pilot command at most once, in order of ``(t_sent, seq)`` per source."""

    max_future_s: float = 2.0
    counters: GateCounters = field(default_factory=GateCounters)
    _last: dict = field(default_factory=dict)

    def offer(self, cmd: PilotCommand, t_now: float) -> bool:
        """True if ``cmd`` is new and valid at vehicle sim time ``t_now`` (s); else counted and dropped."""
        c = self.counters
        vals = (cmd.track_deg, cmd.vs_mps, cmd.gs_mps)
        if (not math.isfinite(cmd.t_sent) or cmd.t_sent < 0 or cmd.seq < 0
                or all(math.isnan(v) for v in vals) or any(math.isinf(v) for v in vals)
                or (math.isfinite(cmd.track_deg) and not 0.0 <= cmd.track_deg <= 360.0)
                or (math.isfinite(cmd.gs_mps) and not 0.0 < cmd.gs_mps <= 400.0)
                or (math.isfinite(cmd.vs_mps) and abs(cmd.vs_mps) > 60.0)):
            c.invalid += 1
            return False
        if cmd.t_sent > t_now + self.max_future_s:
            c.future += 1
            return False
        key = (cmd.t_sent, cmd.seq)
        last = self._last.get(cmd.source)
        if last is not None:
            if key == last:
                c.duplicate += 1
                return False
            if key < last:
                c.older += 1
                return False
        self._last[cmd.source] = key
        c.accepted += 1
        return True

    def last_accepted(self, source: tuple) -> "tuple[float, int] | None":
        """``(t_sent, seq)`` of the newest command accepted from ``source`` ``(sysid, compid)``; None if none."""
        return self._last.get(tuple(source))


def reposition_command(msg, own_xyz: tuple, origin, t_sent: float, seq: int) -> "PilotCommand | str":
    """A ``MAV_CMD_DO_REPOSITION`` (COMMAND_INT: x/y degE7; COMMAND_LONG: param5/6 deg) as a pilot command.

    The vehicle flies absolute setpoints, so "go to this point" becomes "fly the initial bearing from
    the current position ``own_xyz`` (ENU m) to the point"; ground speed = ``param1`` if > 0 (else
    keep); the vertical speed is kept (the altitude ``z`` / ``param7`` is not flown: there is no
    altitude-hold setpoint). Returns the command, or a one-line reason it is invalid.
    """
    from daa_sil.geometry.frames import geodetic_to_enu  # lazy: start-up time

    if msg.get_type() == "COMMAND_INT":
        lat, lon = msg.x / 1e7, msg.y / 1e7
    else:
        lat, lon = float(msg.param5), float(msg.param6)
    if not (math.isfinite(lat) and math.isfinite(lon) and -90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
        return f"DO_REPOSITION: bad position {lat!r}, {lon!r}"
    x, y, _ = geodetic_to_enu(lat, lon, origin.alt_m, origin.lat_deg, origin.lon_deg, origin.alt_m)
    de, dn = float(x) - own_xyz[0], float(y) - own_xyz[1]
    if math.hypot(de, dn) < 1.0:
        return "DO_REPOSITION: the point is where the aircraft is"
    gs = float(msg.param1)
    gs = gs if math.isfinite(gs) and gs > 0 else math.nan
    trk = math.degrees(math.atan2(de, dn)) % 360.0
    return PilotCommand(t_sent, int(seq), trk, math.nan, gs, (msg.get_srcSystem(), msg.get_srcComponent()),
                        "DO_REPOSITION")


#: SET_POSITION_TARGET_GLOBAL_INT type_mask bits that must be clear for a velocity setpoint
_VEL_IGNORE = (M.POSITION_TARGET_TYPEMASK_VX_IGNORE | M.POSITION_TARGET_TYPEMASK_VY_IGNORE
               | M.POSITION_TARGET_TYPEMASK_VZ_IGNORE)


def setpoint_command(msg, vehicle_sysid: int = VEHICLE_SYSID.default) -> "PilotCommand | None":
    """A PILOT_MANEUVER or a stock SET_POSITION_TARGET_GLOBAL_INT velocity setpoint (NED m/s) as a pilot
    command; None if it is not for this vehicle or not a velocity setpoint. Values are checked by the
    :class:`CommandGate` (NaN = keep, infinities and out-of-range values invalid)."""
    src = (msg.get_srcSystem(), msg.get_srcComponent())
    if msg.target_system not in (0, vehicle_sysid):
        return None
    if msg.get_type() == "PILOT_MANEUVER":
        return PilotCommand(msg.time_boot_ms / 1000.0, int(msg.cmd_seq), float(msg.track_deg), float(msg.vs),
                            float(msg.gs), src, "PILOT_MANEUVER")
    if msg.type_mask & _VEL_IGNORE:
        return None
    vn, ve, vd = float(msg.vx), float(msg.vy), float(msg.vz)
    if not all(math.isfinite(v) for v in (vn, ve, vd)):
        return None
    gs = math.hypot(vn, ve)
    trk = math.degrees(math.atan2(ve, vn)) % 360.0 if gs > 0.5 else math.nan
    return PilotCommand(msg.time_boot_ms / 1000.0, 0, trk, -vd, gs if gs > 0.5 else math.nan, src,
                        "SET_POSITION_TARGET_GLOBAL_INT")
