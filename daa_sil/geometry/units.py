"""Unit conversions. Everything inside daa-sil is SI (m, s, m/s, rad); these are for the edges."""

from __future__ import annotations

import numpy as np

FT = 0.3048  #: metres per foot
NMI = 1852.0  #: metres per nautical mile
KT = 1852.0 / 3600.0  #: m/s per knot (0.514444...)
FPM = FT / 60.0  #: m/s per foot per minute (0.00508)
G0 = 9.80665  #: standard gravity, m/s^2
DEG = np.pi / 180.0  #: radians per degree


def ft_to_m(x):
    """Feet to metres."""
    return np.asarray(x, dtype=float) * FT


def m_to_ft(x):
    """Metres to feet."""
    return np.asarray(x, dtype=float) / FT


def kt_to_mps(x):
    """Knots to metres per second."""
    return np.asarray(x, dtype=float) * KT


def mps_to_kt(x):
    """Metres per second to knots."""
    return np.asarray(x, dtype=float) / KT


def fpm_to_mps(x):
    """Feet per minute to metres per second."""
    return np.asarray(x, dtype=float) * FPM


def mps_to_fpm(x):
    """Metres per second to feet per minute."""
    return np.asarray(x, dtype=float) / FPM


def deg_to_rad(x):
    """Degrees to radians."""
    return np.asarray(x, dtype=float) * DEG


def rad_to_deg(x):
    """Radians to degrees."""
    return np.asarray(x, dtype=float) / DEG
