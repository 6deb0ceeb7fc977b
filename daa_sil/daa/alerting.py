"""DO-365 alert levels (straight-line projection, DAIDALUS ``Alerter``) and ProjL (paper Eq. 10)."""

from __future__ import annotations

import numpy as np

from daa_sil.config.settings import PROJL_HORIZON

from daa_sil.geometry import wellclear as wc
from daa_sil.geometry.kinematics import AircraftState
from .config import DaaConfig
from .intervals import interval_soa

#: False: the straight-line intervals below come from :func:`daa_sil.geometry.wellclear.violation_interval`
#: (the numpy reference the tests compare the compiled :func:`daa_sil.daa.intervals.interval_soa` with)
COMPILED = True


def straight_t_in(s: np.ndarray, v: np.ndarray, volumes, length: float) -> list:
    """First violation time (s, inf = none) over ``[0, length]`` of the straight relative lines ``s + t v``
    (``(N, M, 3)``) for each volume of ``volumes``: the compiled interval on the components laid out
    once, the same numbers as ``wc.violation_interval(s, v, th, 0.0, length)[0]``."""
    if not COMPILED:
        return [wc.violation_interval(s, v, th, 0.0, length)[0] for th in volumes]
    shape = s.shape[:-1] if s.shape == v.shape else np.broadcast_shapes(s.shape[:-1], v.shape[:-1])
    comp = [np.ascontiguousarray(a[..., i] if a.shape[:-1] == shape else np.broadcast_to(a[..., i], shape),
                                 dtype=float).reshape(-1) for a in (s, v) for i in range(3)]
    span = np.full(comp[0].shape[0], float(length))
    return [interval_soa(*comp, span, th)[0].reshape(shape) for th in volumes]


def relative_state(own: AircraftState, intr: AircraftState) -> tuple[np.ndarray, np.ndarray]:
    """``(s, v)`` ownship minus intruder, ``(N, M, 3)``, for ownship ``(N,)`` and intruders ``(N, M)``."""
    return wc.relative(own.position()[:, None], own.velocity()[:, None], intr.position(), intr.velocity())


def safe_avoidance(own: AircraftState, intr: "AircraftState | None", alert_level) -> np.ndarray:
    """(N,) bool: the encounter has been safely avoided as seen from ``own`` (N,) and ``intr`` (N, M):
    no DAA alert (``alert_level``, the maximum over intruders, is 0) and every intruder past its
    closest point of approach (horizontal relative position . relative velocity > 0: diverging).
    False where a state is unknown (nan) or no intruder is given."""
    n = own.shape[0]
    if intr is None or intr.shape[-1] == 0:
        return np.zeros(n, bool)
    s, v = relative_state(own, intr)
    with np.errstate(invalid="ignore"):
        diverging = (s[..., 0] * v[..., 0] + s[..., 1] * v[..., 1]) > 0.0  # nan compares False
    return (np.broadcast_to(np.asarray(alert_level), (n,)) == 0) & diverging.all(axis=1)


def _alerting_times(cfg: DaaConfig, early_level, shape) -> np.ndarray:
    """Alerting time (s) of levels 1..3 per intruder, broadcastable to ``(3, N, M)``: a level's early alerting
    time where ``early_level`` (N, M) equals that level (DAIDALUS hysteresis), else its alerting time (then
    one value per level, ``(3, 1, 1)``)."""
    times = np.array([cfg.alert_time_preventive_s, cfg.alert_time_corrective_s, cfg.alert_time_warning_s])
    if early_level is None:
        return times[:, None, None]
    early = np.array([cfg.early_alert_time_preventive_s, cfg.early_alert_time_corrective_s,
                      cfg.early_alert_time_warning_s])
    out = np.broadcast_to(times[:, None, None], (3,) + shape).copy()
    e = np.asarray(early_level)
    for lv in (1, 2, 3):
        out[lv - 1] = np.where(e == lv, early[lv - 1], out[lv - 1])
    return out


def _conflict_before(t_in, t_al) -> np.ndarray:
    """DAIDALUS ``conflictBefore``: the violation starts now (``t_in == 0``) or before ``t_al``."""
    return (t_in == 0.0) | (t_in < t_al)


def alert_levels(own: AircraftState, intr: AircraftState, cfg: "DaaConfig | None" = None,
                 prev: "np.ndarray | None" = None) -> np.ndarray:
    """Raw alert level per intruder ``(N, M)`` int8: 0 none, 1 preventive, 2 corrective, 3 warning.

    Level i is raised when the straight-line time to violation ``t_in`` of its volume over
    ``[0, lookahead]`` satisfies DAIDALUS ``conflictBefore(t_al)`` (``t_in == 0`` or ``t_in < t_al``),
    checked from 3 down to 1 (``docs/daa.md``). Volumes: warning and corrective use ``cfg.th``;
    preventive uses ZTHR = ``cfg.preventive_zthr`` (700 ft). Alerting times 25 / 55 / 55 s. ``prev``
    (N, M): the intruder's current (filtered) level from :class:`daa_sil.daa.DaaState`; the level equal
    to it uses its early alerting time (55 / 75 / 75 s), as DAIDALUS does. No M-of-N here.
    """
    cfg = cfg or DaaConfig()
    s, v = relative_state(own, intr)
    t_c, t_p = straight_t_in(s, v, (cfg.th, cfg.th_preventive), cfg.lookahead_s)
    t_al = _alerting_times(cfg, prev, t_c.shape)
    level = np.zeros(t_c.shape, np.int8)
    for lv, t_in in ((3, t_c), (2, t_c), (1, t_p)):
        hit = _conflict_before(t_in, t_al[lv - 1])
        level = np.where((level == 0) & hit, lv, level).astype(np.int8)
    return level


def conflict_lists(own: AircraftState, intr: AircraftState, cfg: "DaaConfig | None" = None,
                   early_level: "np.ndarray | None" = None) -> tuple[np.ndarray, np.ndarray]:
    """(NEAR, MID) *conflict aircraft* flags ``(N, M)``: the straight-line violation of the warning /
    corrective volume starts within that level's alerting time (25 / 55 s; the early time 55 / 75 s
    where ``early_level`` equals the level). Their bands use the whole lookahead (DAIDALUS
    ``conflict_aircraft``); the other intruders are *peripheral* (:mod:`daa_sil.daa.bands`)."""
    cfg = cfg or DaaConfig()
    s, v = relative_state(own, intr)
    t_c, = straight_t_in(s, v, (cfg.th,), cfg.lookahead_s)
    t_al = _alerting_times(cfg, early_level, t_c.shape)
    return _conflict_before(t_c, t_al[2]), _conflict_before(t_c, t_al[1])


def proj_lowc(own: AircraftState, intr: AircraftState, cfg: "DaaConfig | None" = None,
              horizon_s: float = PROJL_HORIZON.default) -> np.ndarray:
    """ProjL (paper Eq. 10), bool ``(N, M)``: a loss of well clear (``cfg.th``) is predicted within the
    next ``horizon_s`` seconds (including now) on the current straight-line trajectories (exact
    :func:`daa_sil.geometry.wellclear.violation_interval`, no sampling)."""
    cfg = cfg or DaaConfig()
    s, v = relative_state(own, intr)
    t_in, = straight_t_in(s, v, (cfg.th,), float(horizon_s))
    return np.isfinite(t_in)
