"""Pure encoding of one vehicle step into MAVLink messages (no sockets, no clock).

Conventions (``reference/mavlink_spec.md`` §2.3, §6):

* every ``time_boot_ms`` is **sim time** (ms since scenario start); SYSTEM_TIME publishes the
  scenario epoch (``time_unix_usec`` = epoch + sim time);
* HEARTBEAT from compid 1, ``MAV_TYPE_FIXED_WING`` / ``MAV_AUTOPILOT_GENERIC``;
  ``base_mode`` = CUSTOM_MODE_ENABLED | GUIDED | SAFETY_ARMED (+ AUTO while onboard DAA flies);
  ``custom_mode`` = authority (0 pilot, 1 DAA, 2 hold = DAA_SIL_AUTHORITY);
* intruders as ADSB_VEHICLE with the **vehicle's** sysid, flags = coords | altitude | heading |
  velocity | callsign | simulated | vertical velocity (223), ``tslc`` 0, ``heading`` = course
  over ground, ``ver_velocity`` positive up;
* GLOBAL_POSITION_INT velocities are NED cm/s, ``hdg`` = track (cdeg).

Scaled integers are produced by one helper each (:func:`deg_e7`, :func:`cm_s_i16`, ...), clamped to
their field ranges so an extreme value can never raise in ``pack``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from daa_sil.frames import enu_to_geodetic
from daa_sil.link.codec import mavlink as M
from daa_sil.units import G0

#: scenario epoch published in SYSTEM_TIME (UNIX s): 2024-01-01T00:00:00Z
SCENARIO_EPOCH_UNIX = 1_704_067_200
ADSB_FLAGS = (M.ADSB_FLAGS_VALID_COORDS | M.ADSB_FLAGS_VALID_ALTITUDE | M.ADSB_FLAGS_VALID_HEADING
              | M.ADSB_FLAGS_VALID_VELOCITY | M.ADSB_FLAGS_VALID_CALLSIGN | M.ADSB_FLAGS_SIMULATED
              | M.ADSB_FLAGS_VERTICAL_VELOCITY_VALID)
AUTHORITY_CODE = {"pilot": M.DAA_SIL_AUTHORITY_PILOT, "daa": M.DAA_SIL_AUTHORITY_DAA, "hold": M.DAA_SIL_AUTHORITY_HOLD}
DECISION_CODE = {"none": 0, "wait": 1, "no_wait": 2, "pilot": 3, "blend": 4, "daa_override": 5, "daa": 6,
                 "stale": 7, "link_lost": 8}
RULE_CODE = {"-": 0, "axis_dir": 1, "axis": 2, "any": 3, "best_effort": 4}
AXIS_CODE = {"none": 0, "horizontal": 1, "vertical": 2, "speed": 3}
DIR_CODE = {"none": 0, "left": 1, "right": 2, "up": 3, "down": 4, "faster": 5, "slower": 6}
REGION_CODE = {"none": 0, "far": 1, "mid": 2, "near": 3, "recovery": 4}
BANDS_PER_MSG = 16


def _clamp_int(v: float, lo: int, hi: int, default: int = 0) -> int:
    if not math.isfinite(v):
        return default
    return int(max(lo, min(hi, round(v))))


def deg_e7(deg: float) -> int:
    """Degrees -> int32 degE7."""
    return _clamp_int(deg * 1e7, -2**31, 2**31 - 1)


def cm_s_i16(mps: float) -> int:
    """m/s -> int16 cm/s (clamped to +-327.67 m/s)."""
    return _clamp_int(mps * 100.0, -32768, 32767)


def cdeg_u16(deg: float) -> int:
    """Compass degrees -> uint16 centidegrees in [0, 35999]."""
    if not math.isfinite(deg):
        return 65535
    return int(round((deg % 360.0) * 100.0)) % 36000


def time_ms(t: float) -> int:
    """Sim seconds -> uint32 ms."""
    return _clamp_int(t * 1000.0, 0, 2**32 - 1)


def _f(x) -> float:
    """Float for a MAVLink float field (None -> NaN)."""
    return float("nan") if x is None else float(x)


@dataclass
class Kin:
    """One aircraft's kinematic state: ENU m, compass track rad, m/s; ``turn_rate`` rad/s (+ right)."""

    x: float
    y: float
    z: float
    gs: float
    trk: float
    vs: float
    turn_rate: float = 0.0


def heartbeat(authority: str) -> "M.MAVLink_message":
    """Vehicle HEARTBEAT: authority in ``custom_mode``; AUTO flag while onboard DAA flies."""
    base = M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | M.MAV_MODE_FLAG_GUIDED_ENABLED | M.MAV_MODE_FLAG_SAFETY_ARMED
    if authority == "daa":
        base |= M.MAV_MODE_FLAG_AUTO_ENABLED
    return M.MAVLink_heartbeat_message(M.MAV_TYPE_FIXED_WING, M.MAV_AUTOPILOT_GENERIC, base,
                                       AUTHORITY_CODE.get(authority, 0), M.MAV_STATE_ACTIVE, 3)


def system_time(t: float) -> "M.MAVLink_message":
    return M.MAVLink_system_time_message(int((SCENARIO_EPOCH_UNIX + t) * 1e6), time_ms(t))


def global_position(t: float, own: Kin, origin) -> "M.MAVLink_message":
    """GLOBAL_POSITION_INT of the ownship (``origin`` has lat_deg, lon_deg, alt_m)."""
    lat, lon, alt = enu_to_geodetic(own.x, own.y, own.z, origin.lat_deg, origin.lon_deg, origin.alt_m)
    vn, ve = own.gs * math.cos(own.trk), own.gs * math.sin(own.trk)
    return M.MAVLink_global_position_int_message(
        time_ms(t), deg_e7(float(lat)), deg_e7(float(lon)), _clamp_int(float(alt) * 1000.0, -2**31, 2**31 - 1),
        _clamp_int(own.z * 1000.0, -2**31, 2**31 - 1), cm_s_i16(vn), cm_s_i16(ve), cm_s_i16(-own.vs),
        cdeg_u16(math.degrees(own.trk)))


def attitude(t: float, own: Kin) -> "M.MAVLink_message":
    """ATTITUDE: coordinated-turn bank from the turn rate, flight-path pitch, yaw = track."""
    roll = math.atan2(own.gs * own.turn_rate, G0) if math.isfinite(own.turn_rate) else 0.0
    pitch = math.atan2(own.vs, max(own.gs, 1e-3))
    yaw = (own.trk + math.pi) % (2 * math.pi) - math.pi
    return M.MAVLink_attitude_message(time_ms(t), roll, pitch, yaw, 0.0, 0.0,
                                      own.turn_rate if math.isfinite(own.turn_rate) else 0.0)


def adsb_vehicle(icao: int, callsign: str, intr: Kin, origin) -> "M.MAVLink_message":
    """ADSB_VEHICLE for one intruder (geometric altitude, COG heading, vertical speed up)."""
    lat, lon, alt = enu_to_geodetic(intr.x, intr.y, intr.z, origin.lat_deg, origin.lon_deg, origin.alt_m)
    return M.MAVLink_adsb_vehicle_message(
        int(icao) & 0xFFFFFFFF, deg_e7(float(lat)), deg_e7(float(lon)), M.ADSB_ALTITUDE_TYPE_GEOMETRIC,
        _clamp_int(float(alt) * 1000.0, -2**31, 2**31 - 1), cdeg_u16(math.degrees(intr.trk)),
        _clamp_int(intr.gs * 100.0, 0, 65535), cm_s_i16(intr.vs), callsign.encode("ascii", "replace")[:9],
        M.ADSB_EMITTER_TYPE_UAV, 0, ADSB_FLAGS, 0)


def statustext(text: str, severity: int = M.MAV_SEVERITY_WARNING) -> "M.MAVLink_message":
    return M.MAVLink_statustext_message(severity, text.encode("ascii", "replace")[:50])


def track_bands(t: float, lo_deg, hi_deg, regions) -> "list[M.MAVLink_message]":
    """DAA_BANDS (track) messages, 16 intervals per message (at least one message)."""
    n = len(lo_deg)
    parts = max(1, math.ceil(n / BANDS_PER_MSG))
    out = []
    for p in range(parts):
        sl = slice(p * BANDS_PER_MSG, (p + 1) * BANDS_PER_MSG)
        lo = [float(v) for v in lo_deg[sl]]
        hi = [float(v) for v in hi_deg[sl]]
        rg = [REGION_CODE.get(str(r), M.DAA_SIL_BAND_REGION_UNKNOWN) for r in regions[sl]]
        cnt = len(lo)
        pad = BANDS_PER_MSG - cnt
        out.append(M.MAVLink_daa_bands_message(time_ms(t), M.DAA_SIL_BAND_DIMENSION_TRACK, cnt, p, parts,
                                               lo + [0.0] * pad, hi + [0.0] * pad, rg + [0] * pad))
    return out


def allocation_decision(t: float, rec: dict, pilot_cmd_seq: int, pilot_cmd_age: float) -> "M.MAVLink_message":
    """ALLOCATION_DECISION from one step-log record (string fields as in the step log)."""
    return M.MAVLink_allocation_decision_message(
        time_ms(t), AUTHORITY_CODE.get(rec.get("authority", "pilot"), 0), DECISION_CODE.get(rec.get("decision", "none"), 0),
        RULE_CODE.get(rec.get("rule", "-"), 0), _f(rec.get("wait_s")), int(bool(rec.get("projl", False))),
        _f(rec.get("sm_pilot")), _f(rec.get("sm_exec")), AXIS_CODE.get(rec.get("pilot_axis", "none"), 0),
        DIR_CODE.get(rec.get("pilot_dir", "none"), 0), AXIS_CODE.get(rec.get("exec_axis", "none"), 0),
        DIR_CODE.get(rec.get("exec_dir", "none"), 0), _f(rec.get("cmd_trk_deg")), _f(rec.get("cmd_vs")),
        _f(rec.get("cmd_gs")), int(pilot_cmd_seq) & 0xFFFFFFFF, _f(pilot_cmd_age))


def command_ack(command: int, result: int, seq: int, target_system: int, target_component: int) -> "M.MAVLink_message":
    """COMMAND_ACK; for PILOT_MANEUVER ``command`` is its message id and ``result_param2`` its cmd_seq."""
    return M.MAVLink_command_ack_message(int(command) & 0xFFFF, result, 100, int(seq) & 0x7FFFFFFF,
                                         target_system, target_component)


def local_position(t: float, own: Kin) -> "M.MAVLink_message":
    """LOCAL_POSITION_NED (float, from the scenario origin): the lossless ownship state the GCS uses."""
    vn, ve = own.gs * math.cos(own.trk), own.gs * math.sin(own.trk)
    return M.MAVLink_local_position_ned_message(time_ms(t), own.y, own.x, -own.z, vn, ve, -own.vs)


def alert_level(t: float, level: int) -> "M.MAVLink_message":
    """NAMED_VALUE_INT ``DAA_ALERT``: the highest DAIDALUS alert level over intruders (0-3) at ``t``."""
    return M.MAVLink_named_value_int_message(time_ms(t), b"DAA_ALERT", int(level))
