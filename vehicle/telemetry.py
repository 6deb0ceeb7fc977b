"""Pure encoding of one vehicle step into MAVLink messages (no sockets, no clock).

Conventions (``docs/sil.md`` "Identity, telemetry and rates"):

* every ``time_boot_ms`` is **sim time** (ms since scenario start); SYSTEM_TIME publishes the
  scenario epoch (``time_unix_usec`` = epoch + sim time); ``time_usec`` fields are sim time in us;
* HEARTBEAT from compid 1 as an ArduPlane (:mod:`vehicle.identity`): ``custom_mode`` = the ArduPlane
  mode of the authority (GUIDED pilot / AVOID_ADSB DAA / CRUISE waiting), ``base_mode`` as ArduPlane;
* intruders as ADSB_VEHICLE with the **vehicle's** sysid, flags = coords | altitude | heading |
  velocity | callsign | simulated | vertical velocity (223), ``tslc`` 0, ``heading`` = course
  over ground, ``ver_velocity`` positive up;
* GLOBAL_POSITION_INT velocities are NED cm/s, ``hdg`` = track (cdeg); no wind is modelled, so
  heading = track and airspeed = ground speed (VFR_HUD);
* ATTITUDE: coordinated-turn bank ``tan(phi) = V * omega / g`` from the turn rate flown over the
  step, pitch = flight-path angle, yaw = track; body rates of that steady turn;
* the SIL simulates a perfect sensor suite (GPS, AHRS, gyro, accel, mag present, enabled, healthy
  in SYS_STATUS) and no battery (voltage UINT16_MAX, current -1, remaining -1: "unknown").

Scaled integers are produced by one helper each (:func:`deg_e7`, :func:`cm_s_i16`, ...), clamped to
their field ranges so an extreme value can never raise in ``pack``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from daa_sil.geometry.frames import enu_to_geodetic
from daa_sil.link.codec import mavlink as M
from daa_sil.link.plane import system_time, time_ms
from daa_sil.geometry.units import G0

from . import identity as ident
from daa_sil import __version__

ADSB_FLAGS = (M.ADSB_FLAGS_VALID_COORDS | M.ADSB_FLAGS_VALID_ALTITUDE | M.ADSB_FLAGS_VALID_HEADING
              | M.ADSB_FLAGS_VALID_VELOCITY | M.ADSB_FLAGS_VALID_CALLSIGN | M.ADSB_FLAGS_SIMULATED
              | M.ADSB_FLAGS_VERTICAL_VELOCITY_VALID)
AUTHORITY_CODE = {"pilot": M.DAA_SIL_AUTHORITY_PILOT, "daa": M.DAA_SIL_AUTHORITY_DAA,
                  "waiting": M.DAA_SIL_AUTHORITY_WAITING}
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


def heartbeat(authority: str, agent_enabled: bool = True, state: int = M.MAV_STATE_ACTIVE) -> "M.MAVLink_message":
    """Vehicle HEARTBEAT as an ArduPlane: the authority's mode in ``custom_mode`` (:mod:`vehicle.identity`);
    ``state`` the MAV_STATE (BOOT while the vehicle prepares, STANDBY while it waits for a GCS)."""
    mode = ident.mode_of(authority, agent_enabled)
    return M.MAVLink_heartbeat_message(ident.VEHICLE_TYPE, ident.AUTOPILOT, ident.base_mode(mode), mode, state, 3)


def _geo(k: Kin, origin, geo):
    """``(lat deg, lon deg, alt m MSL)`` of ``k``: ``geo`` if already converted, else from ``origin``."""
    if geo is not None:
        return geo
    return enu_to_geodetic(k.x, k.y, k.z, origin.lat_deg, origin.lon_deg, origin.alt_m)


def global_position(t: float, own: Kin, origin, geo=None) -> "M.MAVLink_message":
    """GLOBAL_POSITION_INT of the ownship (``origin`` has lat_deg, lon_deg, alt_m)."""
    lat, lon, alt = _geo(own, origin, geo)
    vn, ve = own.gs * math.cos(own.trk), own.gs * math.sin(own.trk)
    return M.MAVLink_global_position_int_message(
        time_ms(t), deg_e7(float(lat)), deg_e7(float(lon)), _clamp_int(float(alt) * 1000.0, -2**31, 2**31 - 1),
        _clamp_int(own.z * 1000.0, -2**31, 2**31 - 1), cm_s_i16(vn), cm_s_i16(ve), cm_s_i16(-own.vs),
        cdeg_u16(math.degrees(own.trk)))


def bank_angle(gs: float, turn_rate: float) -> float:
    """Coordinated-turn bank (rad, + right): ``tan(phi) = V * omega / g`` (V m/s, omega rad/s)."""
    return math.atan(gs * turn_rate / G0) if math.isfinite(turn_rate) and math.isfinite(gs) else 0.0


def attitude(t: float, own: Kin) -> "M.MAVLink_message":
    """ATTITUDE: coordinated-turn bank from ``own.turn_rate``, flight-path pitch, yaw = track.

    Body rates of a steady coordinated turn at earth yaw rate omega and bank phi: p = 0,
    q = omega sin(phi), r = omega cos(phi).
    """
    w = own.turn_rate if math.isfinite(own.turn_rate) else 0.0
    roll = bank_angle(own.gs, w)
    pitch = math.atan2(own.vs, max(own.gs, 1e-3))
    yaw = (own.trk + math.pi) % (2 * math.pi) - math.pi
    return M.MAVLink_attitude_message(time_ms(t), roll, pitch, yaw, 0.0, w * math.sin(roll), w * math.cos(roll))


def adsb_vehicle(icao: int, callsign: str, intr: Kin, origin, geo=None) -> "M.MAVLink_message":
    """ADSB_VEHICLE for one intruder (geometric altitude, COG heading, vertical speed up)."""
    lat, lon, alt = _geo(intr, origin, geo)
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


# --- standard status / position messages (ArduPilot SITL's set) ----------------------------------------
SENSORS = (M.MAV_SYS_STATUS_SENSOR_3D_GYRO | M.MAV_SYS_STATUS_SENSOR_3D_ACCEL | M.MAV_SYS_STATUS_SENSOR_3D_MAG
           | M.MAV_SYS_STATUS_SENSOR_GPS | M.MAV_SYS_STATUS_AHRS | M.MAV_SYS_STATUS_PREARM_CHECK)


def time_us(t: float) -> int:
    """Sim seconds -> uint64 us."""
    return _clamp_int(t * 1e6, 0, 2**63 - 1)


def _alt_mm(alt_m: float) -> int:
    return _clamp_int(alt_m * 1000.0, -2**31, 2**31 - 1)


def sys_status(agent_enabled: bool) -> "M.MAVLink_message":
    """SYS_STATUS: simulated sensors all healthy; OBSTACLE_AVOIDANCE present, enabled = the DAA agent; no battery."""
    avoid = M.MAV_SYS_STATUS_OBSTACLE_AVOIDANCE
    present = SENSORS | avoid
    enabled = SENSORS | (avoid if agent_enabled else 0)
    # no geofence; its health bit set = "not breached", as ArduPilot reports it (MAVProxy says "fence
    # breach" when a GCS sees the bit clear)
    health = present | M.MAV_SYS_STATUS_GEOFENCE
    return M.MAVLink_sys_status_message(present, enabled, health, 0, 65535, -1, -1, 0, 0, 0, 0, 0, 0)


def gps_raw_int(t: float, own: Kin, origin, geo=None) -> "M.MAVLink_message":
    """GPS_RAW_INT: a 3D fix at the true position (MSL altitude); DOPs and satellites unknown."""
    lat, lon, alt = _geo(own, origin, geo)
    return M.MAVLink_gps_raw_int_message(time_us(t), M.GPS_FIX_TYPE_3D_FIX, deg_e7(float(lat)), deg_e7(float(lon)),
                                         _alt_mm(float(alt)), 65535, 65535, _clamp_int(own.gs * 100.0, 0, 65534),
                                         cdeg_u16(math.degrees(own.trk)), 255)


def vfr_hud(own: Kin, origin, geo=None) -> "M.MAVLink_message":
    """VFR_HUD: airspeed = ground speed (no wind), heading = track (deg), MSL altitude (m), climb (m/s).

    Throttle is not modelled and is sent as 0.
    """
    _, _, alt = _geo(own, origin, geo)
    hdg = int(round(math.degrees(own.trk) % 360.0)) % 360 if math.isfinite(own.trk) else 0
    return M.MAVLink_vfr_hud_message(own.gs, own.gs, hdg, 0, float(alt), own.vs)


def home_position(t: float, home: Kin, origin) -> "M.MAVLink_message":
    """HOME_POSITION: where the ownship started (``home``), local NED from the scenario origin."""
    lat, lon, alt = enu_to_geodetic(home.x, home.y, home.z, origin.lat_deg, origin.lon_deg, origin.alt_m)
    return M.MAVLink_home_position_message(deg_e7(float(lat)), deg_e7(float(lon)), _alt_mm(float(alt)), home.y,
                                           home.x, -home.z, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0, time_us(t))


def extended_sys_state() -> "M.MAVLink_message":
    """EXTENDED_SYS_STATE: a fixed wing (no VTOL state), in the air."""
    return M.MAVLink_extended_sys_state_message(M.MAV_VTOL_STATE_UNDEFINED, M.MAV_LANDED_STATE_IN_AIR)


#: POSITION_TARGET type_mask of a velocity-only target (position, acceleration, yaw, yaw rate ignored)
VELOCITY_TARGET_MASK = (M.POSITION_TARGET_TYPEMASK_X_IGNORE | M.POSITION_TARGET_TYPEMASK_Y_IGNORE
                        | M.POSITION_TARGET_TYPEMASK_Z_IGNORE | M.POSITION_TARGET_TYPEMASK_AX_IGNORE
                        | M.POSITION_TARGET_TYPEMASK_AY_IGNORE | M.POSITION_TARGET_TYPEMASK_AZ_IGNORE
                        | M.POSITION_TARGET_TYPEMASK_YAW_IGNORE | M.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE)


def position_target(t: float, trk_deg: float, gs: float, vs: float, own: Kin) -> "M.MAVLink_message":
    """POSITION_TARGET_GLOBAL_INT: the velocity the vehicle is flying toward (the executed command,
    NED m/s; a NaN field = "keep" is reported as the current value). This is the setpoint feedback
    ArduPilot gives instead of a COMMAND_ACK for SET_POSITION_TARGET_*."""
    trk = math.radians(trk_deg) if math.isfinite(trk_deg) else own.trk
    g = gs if math.isfinite(gs) else own.gs
    v = vs if math.isfinite(vs) else own.vs
    return M.MAVLink_position_target_global_int_message(time_ms(t), M.MAV_FRAME_GLOBAL_INT, VELOCITY_TARGET_MASK,
                                                        0, 0, 0.0, g * math.cos(trk), g * math.sin(trk), -v,
                                                        0.0, 0.0, 0.0, 0.0, 0.0)


def software_version(version: str) -> int:
    """``"0.1.0"`` -> ArduPilot-style ``flight_sw_version`` (major << 24 | minor << 16 | patch << 8 | DEV)."""
    parts = [int(p) if p.isdigit() else 0 for p in (version.split(".") + ["0", "0", "0"])[:3]]
    return (parts[0] & 0xFF) << 24 | (parts[1] & 0xFF) << 16 | (parts[2] & 0xFF) << 8 | M.FIRMWARE_VERSION_TYPE_DEV


def autopilot_version() -> "M.MAVLink_message":
    """AUTOPILOT_VERSION with the capabilities actually served (:data:`vehicle.identity.CAPABILITIES`)."""

    return M.MAVLink_autopilot_version_message(ident.CAPABILITIES, software_version(__version__), 0, 0, 0,
                                               [0] * 8, [0] * 8, [0] * 8, 0, 0, 0)


def message_interval(msg_id: int, interval_us: int) -> "M.MAVLink_message":
    return M.MAVLink_message_interval_message(int(msg_id) & 0xFFFF, int(interval_us))


def param_value(name: str, value: float, ptype: int, count: int, index: int) -> "M.MAVLink_message":
    return M.MAVLink_param_value_message(name.encode("ascii"), float(value), ptype, count, index)


# --- one step's telemetry ------------------------------------------------------------------------------
def kin_of(state, i: int = 0, turn_rate: float = 0.0) -> Kin:
    """:class:`Kin` of row ``i`` of a batched ownship :class:`~daa_sil.geometry.kinematics.AircraftState`."""
    return Kin(float(state.x[i]), float(state.y[i]), float(state.z[i]), float(state.gs[i]), float(state.trk[i]),
               float(state.vs[i]), turn_rate)


def step_messages(vc, t: float, out, home: Kin, agent_enabled: bool = True) -> "dict[int, list]":
    """Every message the vehicle can stream for step ``t``, ``{msg_id: [messages]}`` (several ADSB_VEHICLE,
    DAA_BANDS), from a :class:`vehicle.core.VehicleCore` just stepped to ``out``.

    The turn rate for ATTITUDE is the one flown over the step: the track change from the state at
    ``t`` (``out.own``) to the core's state at ``t + dt``, over ``dt``.
    """
    row = vc.last_row
    origin = vc.sc.origin
    own0, own1 = out.own, vc.core.own
    dtrk = (float(own1.trk[0]) - float(own0.trk[0]) + math.pi) % (2 * math.pi) - math.pi
    ko = kin_of(own0, 0, dtrk / vc.dt)
    it = out.intruders
    m = it.shape[1]
    # one geodetic conversion for the ownship and every intruder
    lat, lon, alt = enu_to_geodetic(*(np.concatenate((a[:1], b[0])) for a, b in ((own0.x, it.x), (own0.y, it.y),
                                                                                   (own0.z, it.z))),
                                    origin.lat_deg, origin.lon_deg, origin.alt_m)
    lat, lon, alt = lat.tolist(), lon.tolist(), alt.tolist()
    g0 = (lat[0], lon[0], alt[0])
    adsb = [adsb_vehicle(vc.icao[j], vc.callsigns[j],
                         Kin(float(it.x[0, j]), float(it.y[0, j]), float(it.z[0, j]), float(it.gs[0, j]),
                             float(it.trk[0, j]), float(it.vs[0, j])), origin, (lat[j + 1], lon[j + 1], alt[j + 1]))
            for j in range(m)]
    seq = vc.last_cmd.seq if vc.last_cmd is not None else 0
    level = int(np.max(out.telemetry.alert_level[0])) if it.shape[1] else 0
    return {
        M.MAVLINK_MSG_ID_HEARTBEAT: [heartbeat(vc.last_authority, agent_enabled)],
        M.MAVLINK_MSG_ID_SYSTEM_TIME: [system_time(t)],
        M.MAVLINK_MSG_ID_SYS_STATUS: [sys_status(agent_enabled)],
        M.MAVLINK_MSG_ID_GPS_RAW_INT: [gps_raw_int(t, ko, origin, g0)],
        M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: [global_position(t, ko, origin, g0)],
        M.MAVLINK_MSG_ID_LOCAL_POSITION_NED: [local_position(t, ko)],
        M.MAVLINK_MSG_ID_ATTITUDE: [attitude(t, ko)],
        M.MAVLINK_MSG_ID_VFR_HUD: [vfr_hud(ko, origin, g0)],
        M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: [extended_sys_state()],
        M.MAVLINK_MSG_ID_POSITION_TARGET_GLOBAL_INT: [position_target(t, row["cmd_trk_deg"], row["cmd_gs"],
                                                                      row["cmd_vs"], ko)],
        M.MAVLINK_MSG_ID_HOME_POSITION: [home_position(t, home, origin)],
        M.MAVLINK_MSG_ID_ADSB_VEHICLE: adsb,
        M.MAVLINK_MSG_ID_NAMED_VALUE_INT: [alert_level(t, level)],
        M.MAVLINK_MSG_ID_DAA_BANDS: track_bands(t, row["bands_trk_lo_deg"], row["bands_trk_hi_deg"],
                                                row["bands_trk_region"]),
        M.MAVLINK_MSG_ID_ALLOCATION_DECISION: [allocation_decision(t, row, seq, row["pilot_cmd_age_s"])],
    }
