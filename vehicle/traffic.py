"""Traffic injected while the vehicle flies: an ADSB_VEHICLE sent *to* the vehicle is a new intruder (sans-IO).

A ground station (or ``daa-sil inject``, which places a scenario file's intruders around the ownship
where it is now) sends a stock ``ADSB_VEHICLE`` to the vehicle on a writable link (the pilot's, or an
output marked ``,rw``): the vehicle adds an intruder at the reported position (geometric altitude,
MSL), course over ground, ground speed and vertical speed, named by its ICAO address and callsign. It
flies straight and level in speed from then on (no scripted manoeuvres), is streamed back as
ADSB_VEHICLE like the scenario's own intruders and is seen by the DAA and the agent from the next step.

:func:`intruder_from_adsb` checks a report and returns the intruder or a one-line reason it is refused:
the coordinates, altitude, heading and velocity flags must be set, the values physical
(:data:`daa_sil.geometry.kinematics.STATE_BOUNDS`, latitudes and longitudes in range, at most
:data:`MAX_RANGE_M` from the ownship), and the ICAO address new. At most :data:`MAX_INTRUDERS`
intruders fly at once (the scenario's count too).
"""

from __future__ import annotations

import math
from typing import NamedTuple

from daa_sil.link.codec import mavlink as M

#: flags an injected report must carry
REQUIRED_FLAGS = (M.ADSB_FLAGS_VALID_COORDS | M.ADSB_FLAGS_VALID_ALTITUDE | M.ADSB_FLAGS_VALID_HEADING
                  | M.ADSB_FLAGS_VALID_VELOCITY)
#: intruders flown at once, the scenario's included (each costs the DAA a column)
MAX_INTRUDERS = 16
#: farthest an injected intruder may start from the ownship (horizontal, m)
MAX_RANGE_M = 100_000.0
#: fastest injected intruder (ground speed, m/s) and steepest vertical speed (m/s)
MAX_GS_MPS, MAX_VS_MPS = 400.0, 60.0


class Intruder(NamedTuple):
    """An injected intruder: ICAO address, callsign, ENU position (m), ground speed (m/s), compass track
    (rad), vertical speed (m/s, up)."""

    icao: int
    callsign: str
    x: float
    y: float
    z: float
    gs: float
    trk: float
    vs: float


def callsign_of(msg) -> str:
    """The report's callsign (printable ASCII, NULs stripped)."""
    raw = msg.callsign
    text = raw.decode("ascii", "replace") if isinstance(raw, (bytes, bytearray)) else str(raw)
    return "".join(c for c in text.split("\0", 1)[0] if 32 <= ord(c) < 127).strip()


def intruder_from_adsb(msg, origin, own_xyz: "tuple[float, float, float]", known_icao,
                       flying: int) -> "Intruder | str":
    """An ADSB_VEHICLE as an intruder (``origin``: the scenario's lat_deg / lon_deg / alt_m; ``own_xyz`` the
    ownship's ENU position, m; ``known_icao`` the addresses flying; ``flying`` how many intruders fly), or
    the reason it is refused (one line, at most 50 characters, for a STATUSTEXT)."""
    from daa_sil.geometry.frames import geodetic_to_enu  # lazy: start-up time
    from daa_sil.geometry.kinematics import state_in_bounds  # lazy: start-up time

    icao = int(msg.ICAO_address)
    if int(msg.flags) & REQUIRED_FLAGS != REQUIRED_FLAGS:
        return f"traffic {icao}: coords/alt/heading/velocity flags"
    if icao in set(known_icao):
        return f"traffic {icao}: already flying"
    if flying >= MAX_INTRUDERS:
        return f"traffic {icao}: {MAX_INTRUDERS} intruders fly already"
    lat, lon, alt = msg.lat / 1e7, msg.lon / 1e7, msg.altitude / 1000.0
    if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0) or int(msg.heading) > 35999:
        return f"traffic {icao}: position or heading out of range"
    x, y, z = (float(v) for v in geodetic_to_enu(lat, lon, alt, origin.lat_deg, origin.lon_deg, origin.alt_m))
    gs, trk, vs = int(msg.hor_velocity) / 100.0, math.radians(int(msg.heading) / 100.0), int(msg.ver_velocity) / 100.0
    vx, vy = gs * math.sin(trk), gs * math.cos(trk)
    if not state_in_bounds(x, y, z, vx, vy, vs) or gs > MAX_GS_MPS or abs(vs) > MAX_VS_MPS:
        return f"traffic {icao}: not a physical state"
    if math.hypot(x - own_xyz[0], y - own_xyz[1]) > MAX_RANGE_M:
        return f"traffic {icao}: over {MAX_RANGE_M / 1000:.0f} km from the ownship"
    return Intruder(icao, callsign_of(msg) or f"T{icao}", x, y, z, gs, trk, vs)
