"""The MAVLink vocabulary both ends of the SIL share: ArduPlane's flight-mode numbers and names (the
vehicle presents itself as an ArduPlane, :mod:`vehicle.identity` says why) and the scenario's clock
on the wire (``time_boot_ms`` stamps, SYSTEM_TIME). The vehicle publishes with them, the GCS reads
and sends with them; neither imports the other."""

from __future__ import annotations

import math

from daa_sil.link.codec import mavlink as M

#: ArduPlane mode numbers (ArduPlane's ``Mode::Number``) -> names, as MAVProxy / pymavlink spell them
PLANE_MODES = {0: "MANUAL", 1: "CIRCLE", 2: "STABILIZE", 3: "TRAINING", 4: "ACRO", 5: "FBWA", 6: "FBWB",
               7: "CRUISE", 8: "AUTOTUNE", 10: "AUTO", 11: "RTL", 12: "LOITER", 13: "TAKEOFF", 14: "AVOID_ADSB",
               15: "GUIDED", 16: "INITIALISING"}
GUIDED, AVOID_ADSB, CRUISE = 15, 14, 7
#: scenario epoch published in SYSTEM_TIME (UNIX s): 2024-01-01T00:00:00Z
SCENARIO_EPOCH_UNIX = 1_704_067_200
UINT32_MAX = 2**32 - 1


def mode_name(mode: int) -> str:
    """The ArduPlane name of mode number ``mode`` (``MODE<n>`` for a number it does not have)."""
    return PLANE_MODES.get(int(mode), f"MODE{int(mode)}")


def time_ms(t: float) -> int:
    """Sim seconds -> uint32 ms (``time_boot_ms``), rounded and clamped; NaN -> 0."""
    v = t * 1000.0
    if not math.isfinite(v):
        return 0
    return int(max(0, min(UINT32_MAX, round(v))))


def system_time(t: float) -> "M.MAVLink_message":
    """SYSTEM_TIME at sim time ``t`` (s): UNIX µs from the scenario epoch, and ``time_boot_ms``."""
    return M.MAVLink_system_time_message(int((SCENARIO_EPOCH_UNIX + t) * 1e6), time_ms(t))
