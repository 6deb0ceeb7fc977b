"""A scenario file's intruders as traffic for a vehicle already flying (sans-IO; ``daa-sil inject``).

A standalone ``daa-vehicle`` flies on past its scenario and takes new intruders as ADSB_VEHICLE messages
sent to it on a writable link (:mod:`vehicle.traffic`). :func:`traffic_reports` turns the ``intruders:``
of any scenario file into such reports, placed around the ownship **where it is now** the way the
scenario places them around its start:

* a ``cpa:`` intruder is placed against the ownship's current position and velocity (its CPA comes
  ``t_cpa_s`` seconds from now, at the given angle, miss distances and speed);
* an ``initial:`` intruder keeps its offset from the scenario's ownship start, shifted to the ownship now
  (not rotated).

Positions go out as latitude / longitude around the ownship's own reported position, so the vehicle's
scenario origin need not be known. An injected intruder flies straight on (scripted manoeuvres of the
file are not carried over).
"""

from __future__ import annotations

import math
from dataclasses import replace

from daa_sil.link.codec import mavlink as M

#: ADSB_VEHICLE flags of an injected report (as the vehicle's own: coords, altitude, heading, velocity,
#: callsign, simulated, vertical velocity)
FLAGS = (M.ADSB_FLAGS_VALID_COORDS | M.ADSB_FLAGS_VALID_ALTITUDE | M.ADSB_FLAGS_VALID_HEADING
         | M.ADSB_FLAGS_VALID_VELOCITY | M.ADSB_FLAGS_VALID_CALLSIGN | M.ADSB_FLAGS_SIMULATED
         | M.ADSB_FLAGS_VERTICAL_VELOCITY_VALID)


def own_from_telemetry(gpi) -> dict:
    """The ownship now from a GLOBAL_POSITION_INT: lat / lon (deg), alt (m MSL), ground speed (m/s), compass
    track (deg) and vertical speed (m/s, up)."""
    vn, ve, vd = gpi.vx / 100.0, gpi.vy / 100.0, gpi.vz / 100.0
    return {"lat": gpi.lat / 1e7, "lon": gpi.lon / 1e7, "alt": gpi.alt / 1000.0, "gs": math.hypot(vn, ve),
            "trk": math.degrees(math.atan2(ve, vn)) % 360.0, "vs": -vd}


def traffic_reports(sc, own: dict) -> list:
    """ADSB_VEHICLE messages for the intruders of scenario ``sc`` around the ownship ``own``
    (:func:`own_from_telemetry`), in the file's order."""
    from daa_sil.geometry.frames import enu_to_geodetic  # lazy: start-up time
    from daa_sil.sil.scenario import encounter_set  # lazy: start-up time

    start = sc.ownship
    now = replace(start, x_m=0.0, y_m=0.0, alt_m=0.0, gs_mps=own["gs"], track_deg=own["trk"], vs_mps=own["vs"])
    shifted = [i if i.cpa is not None else replace(i, initial=replace(
        i.initial, x_m=i.initial.x_m - start.x_m, y_m=i.initial.y_m - start.y_m, alt_m=i.initial.alt_m - start.alt_m))
        for i in sc.intruders]
    es = encounter_set(replace(sc, ownship=now, intruders=tuple(shifted)))
    it = es.intr
    out = []
    for j, spec in enumerate(sc.intruders):
        x, y, z = float(it.x[0, j]), float(it.y[0, j]), float(it.z[0, j])  # ENU m from the ownship now
        lat, lon, alt = enu_to_geodetic(x, y, own["alt"] + z, own["lat"], own["lon"], 0.0)
        gs, trk, vs = float(it.gs[0, j]), math.degrees(float(it.trk[0, j])) % 360.0, float(it.vs[0, j])
        out.append(M.MAVLink_adsb_vehicle_message(
            int(spec.id), int(round(float(lat) * 1e7)), int(round(float(lon) * 1e7)), M.ADSB_ALTITUDE_TYPE_GEOMETRIC,
            int(round(float(alt) * 1000.0)), int(round(trk * 100.0)) % 36000, min(65535, int(round(gs * 100.0))),
            max(-32768, min(32767, int(round(vs * 100.0)))), spec.callsign.encode("ascii", "replace")[:9],
            M.ADSB_EMITTER_TYPE_UAV, 0, FLAGS, 0))
    return out
