"""The vehicle's MAVLink identity: an ArduPlane-compatible fixed wing, and its flight modes.

Why ArduPlane: ground stations decode ``custom_mode`` by the HEARTBEAT's autopilot field. With
``MAV_AUTOPILOT_GENERIC`` MAVProxy falls back to ArduPlane's table anyway (our old codes 0/1/2 read
as MANUAL / CIRCLE / STABILIZE) and MAVSDK decodes modes only for PX4 and ArduPilot. Presenting as
ArduPilot (``MAV_AUTOPILOT_ARDUPILOTMEGA``, ``MAV_TYPE_FIXED_WING``) and mapping each authority to
the ArduPlane mode that does the same thing makes every stock client show a true name:

======================  ==============  =====================================================
authority (agent)       ArduPlane mode  why this mode
======================  ==============  =====================================================
pilot                   GUIDED (15)     the aircraft flies setpoints sent from the ground
daa (DAA, blend,        AVOID_ADSB (14) ArduPilot's mode while its ADS-B avoidance flies
override, link lost)
waiting (agent waits)   CRUISE (7)      holds the last course, climb rate and speed: what the
                                        agent does while it waits for the delayed pilot
======================  ==============  =====================================================

(LOITER would read "Hold" in MAVSDK, but an ArduPlane in LOITER circles; ours flies straight on.)

Mode requests (``MAV_CMD_DO_SET_MODE``, the ``SET_MODE`` message): the agent decides authority
every step (the paper's Algorithm 1), and a ground station cannot override it; but a received pilot
command is always judged by SM(u), so a mode request must not stand in its way:

* ``GUIDED`` (the pilot's own mode) is ``ACCEPTED`` whatever the authority: it says "my commands are
  coming" (MAVSDK's ``goto_location`` asks for it before its DO_REPOSITION, MAVProxy's ``mode
  GUIDED`` before ``guided``). The pilot's commands then go to the agent, which flies them if safe
  (or blends them); the heartbeat keeps showing who flies (AVOID_ADSB / CRUISE while the agent does);
* ``AVOID_ADSB`` and ``CRUISE`` are ``DENIED``: only the agent enters them;
* any other mode, or a request without ``MAV_MODE_FLAG_CUSTOM_MODE_ENABLED``: ``DENIED``.

The agent itself is switched on and off with the ``DAA_ENABLE`` parameter (as ArduPilot's ADS-B
avoidance with ``AVD_ENABLE``), never by a mode. Every request is logged like a parameter write.

``base_mode`` follows ArduPlane: CUSTOM_MODE_ENABLED | STABILIZE | SAFETY_ARMED, plus GUIDED in
GUIDED and AVOID_ADSB. The aircraft is always airborne and armed: ARM is accepted (it already is),
DISARM fails.
"""

from __future__ import annotations

from daa_sil.link.codec import mavlink as M
from daa_sil.link.plane import AVOID_ADSB, CRUISE, GUIDED, PLANE_MODES, mode_name  # noqa: F401 (names of this interface)

AUTOPILOT = M.MAV_AUTOPILOT_ARDUPILOTMEGA
VEHICLE_TYPE = M.MAV_TYPE_FIXED_WING

#: authority -> ArduPlane mode number
AUTHORITY_MODE = {"pilot": GUIDED, "daa": AVOID_ADSB, "waiting": CRUISE}
#: capabilities actually served (AUTOPILOT_VERSION): MAVLink 2, COMMAND_INT (DO_REPOSITION, modes),
#: SET_POSITION_TARGET_GLOBAL_INT velocity setpoints, and the C-cast parameter encoding (integer
#: parameters travel as their float value, as ArduPilot does). No missions, no FTP.
CAPABILITIES = (M.MAV_PROTOCOL_CAPABILITY_MAVLINK2 | M.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
                | M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT
                | M.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST)


def mode_of(authority: str, agent_enabled: bool = True) -> int:
    """ArduPlane mode number shown for ``authority`` (GUIDED whenever the agent is off)."""
    if not agent_enabled:
        return GUIDED
    return AUTHORITY_MODE.get(authority, GUIDED)


def base_mode(mode: int) -> int:
    """HEARTBEAT ``base_mode`` for ArduPlane mode ``mode`` (airborne, armed)."""
    b = M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | M.MAV_MODE_FLAG_STABILIZE_ENABLED | M.MAV_MODE_FLAG_SAFETY_ARMED
    if mode in (GUIDED, AVOID_ADSB):
        b |= M.MAV_MODE_FLAG_GUIDED_ENABLED
    return b


def mode_request(base: int, custom: int, current: int) -> "tuple[int, str]":
    """Decide a mode request while the vehicle shows mode ``current``: ``(MAV_RESULT, one-line reason)``."""
    if not int(base) & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
        return M.MAV_RESULT_DENIED, "mode: CUSTOM_MODE_ENABLED flag missing"
    custom = int(custom)
    if custom == GUIDED:
        if int(current) == GUIDED:
            return M.MAV_RESULT_ACCEPTED, "mode GUIDED: the pilot has authority"
        return M.MAV_RESULT_ACCEPTED, f"GUIDED: agent judges commands ({mode_name(current)} now)"
    if custom in (AVOID_ADSB, CRUISE):
        return M.MAV_RESULT_DENIED, f"mode {mode_name(custom)}: set by the DAA agent only"
    return M.MAV_RESULT_DENIED, f"mode {mode_name(custom)} not available; use GUIDED"
