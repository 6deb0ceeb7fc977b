"""Drawing constants: trail and arrow lengths (s of sim time), colours (RGB/RGBA 0-255), line widths
(negative = ui points)."""

from __future__ import annotations

import numpy as np

TRAIL_S = 60.0  #: trail length, s of sim time
LEAD_S = 30.0  #: velocity arrows show 30 s of flight
BAND_RADIUS_FACTOR = 1.5  #: band arcs at 1.5 x DTHR around the ownship

REGION_COLORS = {"near": (230, 30, 30, 255), "mid": (255, 140, 0, 255), "far": (255, 215, 0, 255),
                 "recovery": (0, 200, 255, 255), "none": (60, 200, 60, 200)}
REGION_WIDTH = {"near": -4.0, "mid": -4.0, "far": -3.0, "recovery": -3.0, "none": -1.5}  # ui points
ALERT_COLORS = np.array([(200, 200, 200, 255), (255, 215, 0, 255), (255, 140, 0, 255), (230, 30, 30, 255)],
                        np.uint8)
OWN_COLOR, PILOT_COLOR, DAA_COLOR, EXEC_COLOR = (40, 200, 60), (60, 140, 255), (230, 60, 230), (255, 255, 255)
WC_OK, WC_VIOLATED = (40, 200, 60, 35), (230, 30, 30, 60)
