"""DO-365 alert levels (straight-line projection, DAIDALUS ``Alerter``) and ProjL (paper Eq. 10)."""

from __future__ import annotations

import numpy as np

from .. import wellclear as wc
from ..kinematics import AircraftState
from .config import DaaConfig


def relative_state(own: AircraftState, intr: AircraftState) -> tuple[np.ndarray, np.ndarray]:
    """``(s, v)`` ownship minus intruder, ``(N, M, 3)``, for ownship ``(N,)`` and intruders ``(N, M)``."""
    return wc.relative(own.position()[:, None], own.velocity()[:, None], intr.position(), intr.velocity())


def alert_levels(own: AircraftState, intr: AircraftState, cfg: "DaaConfig | None" = None,
                 prev: "np.ndarray | None" = None) -> np.ndarray:
    """Alert level per intruder ``(N, M)`` int8: 0 none, 1 preventive, 2 corrective, 3 warning.

    Level i is raised when the straight-line time to violation ``t_in`` of its volume over
    ``[0, lookahead]`` satisfies DAIDALUS ``conflictBefore(t_al)`` (``t_in == 0`` or ``t_in < t_al``),
    checked from 3 down to 1 (``daa_spec.md`` §3.3). Volumes: warning and corrective use
    ``cfg.th``; preventive uses ZTHR = 700 ft. Alerting times 25 / 55 / 55 s. Hysteresis: if ``prev``
    levels are given, a level the intruder already had uses its early alerting time (55 / 75 / 75 s);
    the M-of-N filter is not applied.
    """
    cfg = cfg or DaaConfig()
    s, v = relative_state(own, intr)
    t_c, _ = wc.violation_interval(s, v, cfg.th, 0.0, cfg.lookahead_s)
    t_p, _ = wc.violation_interval(s, v, cfg.th_preventive, 0.0, cfg.lookahead_s)
    times = np.array([cfg.alert_time_preventive_s, cfg.alert_time_corrective_s, cfg.alert_time_warning_s])
    early = np.array([cfg.early_alert_time_preventive_s, cfg.early_alert_time_corrective_s,
                      cfg.early_alert_time_warning_s])
    level = np.zeros(t_c.shape, np.int8)
    for lv, t_in in ((3, t_c), (2, t_c), (1, t_p)):
        t_al = times[lv - 1]
        if prev is not None:
            t_al = np.where(np.asarray(prev) >= lv, early[lv - 1], t_al)
        hit = (t_in == 0.0) | (t_in < t_al)
        level = np.where((level == 0) & hit, lv, level).astype(np.int8)
    return level


def proj_lowc(own: AircraftState, intr: AircraftState, cfg: "DaaConfig | None" = None,
              horizon_s: float = 25.0) -> np.ndarray:
    """ProjL (paper Eq. 10), bool ``(N, M)``: a loss of well clear (``cfg.th``) is predicted within the
    next ``horizon_s`` seconds (including now) on the current straight-line trajectories (exact
    :func:`daa_sil.wellclear.violation_interval`, no sampling)."""
    cfg = cfg or DaaConfig()
    s, v = relative_state(own, intr)
    t_in, _ = wc.violation_interval(s, v, cfg.th, 0.0, float(horizon_s))
    return np.isfinite(t_in)
