"""A pilot command as it crosses the link: the setpoints the vehicle receives for those the GCS sent.

The GCS sends a command as ``PILOT_MANEUVER`` (``daa_sil.link.messages.pilot_maneuver``, the GCS node):
the track in degrees clockwise from north, wrapped to [0, 360) (``math.degrees(trk) % 360.0``), the
vertical and ground speeds in m/s, each a MAVLink ``float`` field, so a 32-bit float on the wire
(rounded to nearest, ties to even). The vehicle reads them back as doubles and turns the track into
radians (``math.radians``). A nan field (keep) stays nan. :func:`wire_command` is that round trip for a
batch, with the same operations (``np.degrees`` / ``np.radians`` multiply by the same constants as
``math.degrees`` / ``math.radians``, and ``np.mod`` is Python's ``%`` for floats), so fast-time flies
exactly the command a SIL vehicle flies (``tests/test_sil_parity.py``).
"""

from __future__ import annotations

import numpy as np

from daa_sil.geometry.kinematics import AircraftState, Command


def wire_command(cmd: Command, rows: "np.ndarray | None" = None) -> Command:
    """The command (rad, m/s, arrays (N,)) the vehicle receives for ``cmd`` sent as ``PILOT_MANEUVER``; with
    ``rows`` (indices), only those rows' (the others nan: nothing was sent)."""
    trk, vs, gs = (np.asarray(a, float) for a in (cmd.trk, cmd.vs, cmd.gs))
    if rows is not None:
        out = Command(np.full(trk.shape, np.nan), np.full(trk.shape, np.nan), np.full(trk.shape, np.nan))
        if rows.size:
            sent = wire_command(Command(trk[rows], vs[rows], gs[rows]))
            out.trk[rows], out.vs[rows], out.gs[rows] = sent.trk, sent.vs, sent.gs
        return out
    with np.errstate(invalid="ignore", over="ignore"):
        deg = np.mod(np.degrees(trk), 360.0)  # (nan and +-inf give nan)
        wire_trk = np.radians(deg.astype(np.float32).astype(float))
        return Command(wire_trk, vs.astype(np.float32).astype(float), gs.astype(np.float32).astype(float))


def observed_own(own: AircraftState) -> np.ndarray:
    """``(N, 6)`` ownship states (x, y, z, gs, trk, vs) as the GCS reads them from ``LOCAL_POSITION_NED``: the
    position and the vertical speed are float fields (32 bits: north, east, down, ..., down speed), so they
    arrive rounded to float32; ground speed and track are kept as the vehicle's doubles (the GCS derives
    them from the float32 north / east speeds with ``math.hypot`` / ``math.atan2``, whose last bits numpy's
    vectorised functions do not reproduce)."""
    a = own.as_array()
    for col in (0, 1, 2, 5):
        a[..., col] = a[..., col].astype(np.float32).astype(float)
    return a


__all__ = ["wire_command", "observed_own"]
