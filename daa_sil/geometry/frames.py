"""Frames and angle conventions; every conversion between them lives here.

World frame: **ENU** metres (x east, y north, z up). Tracks/headings are **compass** angles:
radians clockwise from north inside the code (degrees only at the edges), so a velocity is
``(gs sin(trk), gs cos(trk), vs)``.

The MDP uses the **paper's relative frame** (Tabassum & Bai Eq. 1-8): ownship at the origin with
heading theta_o = 0 along +X; X is along the ownship track (``dx > 0``: intruder ahead), Y is to the
ownship's **left** (right-handed X-Y-Z with Z up), and headings are measured counter-clockwise from
+X (so +90 deg points left). The paper state is

    ``(dx, dy, dh, vi, vh, theta)`` = (intruder position ahead, intruder position left,
    intruder altitude minus ownship altitude, intruder ground speed, intruder vertical speed
    minus ownship vertical speed, intruder heading CCW from the ownship track in [0, 2pi)).

So ``dx > 0, theta = pi`` is head-on, ``dx < 0, theta = 0`` is overtaking, and a positive paper turn
rate (theta increasing) is a **left** turn, i.e. a negative compass turn rate.

Geodetic conversion (for MAVLink) uses a local tangent plane at a reference point with the WGS-84
meridian/prime-vertical radii; it is exact in both directions by construction and accurate to a
few metres over the 10 km of an encounter.
"""

from __future__ import annotations

import numpy as np

TWO_PI = 2.0 * np.pi

#: indices of the paper state vector
DX, DY, DH, VI, VH, THETA = range(6)
PAPER_STATE_NAMES = ("dx", "dy", "dh", "vi", "vh", "theta")


def wrap_pi(a):
    """Wrap angle(s) to [-pi, pi)."""
    a = np.asarray(a, dtype=float)
    return (a + np.pi) % TWO_PI - np.pi


def wrap_2pi(a):
    """Wrap angle(s) to [0, 2pi)."""
    a = np.asarray(a, dtype=float)
    return a % TWO_PI


def track_from_velocity(vx, vy):
    """Compass track (rad, [0, 2pi)) of an ENU horizontal velocity."""
    return wrap_2pi(np.arctan2(np.asarray(vx, dtype=float), np.asarray(vy, dtype=float)))


def velocity_from_track(gs, trk, vs=0.0) -> np.ndarray:
    """ENU velocity ``(..., 3)`` from ground speed (m/s), compass track (rad) and vertical speed (m/s)."""
    gs, trk, vs = np.broadcast_arrays(np.asarray(gs, float), np.asarray(trk, float), np.asarray(vs, float))
    return np.stack([gs * np.sin(trk), gs * np.cos(trk), vs], axis=-1)


def to_paper_state(own_pos, own_vel, intr_pos, intr_vel) -> np.ndarray:
    """Paper relative state ``(..., 6)`` = (dx, dy, dh, vi, vh, theta) from ENU positions/velocities.

    ``own_*`` broadcast against ``intr_*`` (e.g. own ``(N, 3)`` with intruders ``(N, M, 3)`` after
    ``own[:, None]``). dx/dy/dh in m, vi/vh in m/s, theta in rad [0, 2pi).
    """
    own_pos, own_vel = np.asarray(own_pos, float), np.asarray(own_vel, float)
    intr_pos, intr_vel = np.asarray(intr_pos, float), np.asarray(intr_vel, float)
    psi_o = track_from_velocity(own_vel[..., 0], own_vel[..., 1])
    fx, fy = np.sin(psi_o), np.cos(psi_o)  # forward unit vector (ENU)
    lx, ly = -fy, fx  # left unit vector: forward rotated +90 deg CCW
    d = intr_pos - own_pos
    dx = d[..., 0] * fx + d[..., 1] * fy
    dy = d[..., 0] * lx + d[..., 1] * ly
    dh = d[..., 2]
    vi = np.hypot(intr_vel[..., 0], intr_vel[..., 1])
    vh = intr_vel[..., 2] - own_vel[..., 2]
    psi_i = track_from_velocity(intr_vel[..., 0], intr_vel[..., 1])
    theta = wrap_2pi(-(psi_i - psi_o))
    return np.stack(np.broadcast_arrays(dx, dy, dh, vi, vh, theta), axis=-1)


def from_paper_state(paper, own_speed: float = 55.0, own_track: float = 0.0, own_vs: float = 0.0
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Inverse of :func:`to_paper_state` for an ownship at the ENU origin.

    Returns ``(own_pos, own_vel, intr_pos, intr_vel)``; ``own_track`` is a compass angle (rad).
    """
    p = np.asarray(paper, dtype=float)
    dx, dy, dh, vi, vh, theta = (p[..., k] for k in range(6))
    fx, fy = np.sin(own_track), np.cos(own_track)
    lx, ly = -fy, fx
    intr_pos = np.stack([dx * fx + dy * lx, dx * fy + dy * ly, dh], axis=-1)
    psi_i = wrap_2pi(own_track - theta)
    intr_vel = velocity_from_track(vi, psi_i, vh + own_vs)
    own_pos = np.zeros_like(intr_pos)
    own_vel = np.broadcast_to(velocity_from_track(own_speed, own_track, own_vs), intr_vel.shape).copy()
    return own_pos, own_vel, intr_pos, intr_vel


# --- geodetic <-> local ENU ---------------------------------------------------------------------
_WGS84_A = 6378137.0
_WGS84_E2 = 6.69437999014e-3


def _radii(lat0_deg: float) -> tuple[float, float]:
    lat = np.radians(lat0_deg)
    w = np.sqrt(1.0 - _WGS84_E2 * np.sin(lat) ** 2)
    r_n = _WGS84_A / w  # prime vertical
    r_m = _WGS84_A * (1.0 - _WGS84_E2) / w ** 3  # meridian
    return r_m, r_n * np.cos(lat)


def enu_to_geodetic(x, y, z, lat0_deg: float, lon0_deg: float, alt0_m: float = 0.0):
    """Local ENU (m) to (lat deg, lon deg, alt m MSL) around the reference point."""
    r_m, r_p = _radii(lat0_deg)
    lat = lat0_deg + np.degrees(np.asarray(y, float) / r_m)
    lon = lon0_deg + np.degrees(np.asarray(x, float) / r_p)
    return lat, lon, alt0_m + np.asarray(z, float)


def geodetic_to_enu(lat_deg, lon_deg, alt_m, lat0_deg: float, lon0_deg: float, alt0_m: float = 0.0):
    """(lat deg, lon deg, alt m MSL) to local ENU (m) around the reference point."""
    r_m, r_p = _radii(lat0_deg)
    y = np.radians(np.asarray(lat_deg, float) - lat0_deg) * r_m
    x = np.radians(np.asarray(lon_deg, float) - lon0_deg) * r_p
    return x, y, np.asarray(alt_m, float) - alt0_m
