"""Conflict detection along kinematic ownship trajectories against straight-line intruders.

A *knot path* is the ownship sampled at knot times ``t_0 = 0 < t_1 < ... < t_J`` while it
maneuvers (turn / accelerate at the limits). Candidate ``k`` of the path flies the path up to
knot ``k`` and then continues straight with the knot-``k`` velocity. Between knots the relative
motion is taken as the chord (straight line) between the sampled relative positions; each chord
and each straight tail is checked with the exact closed form
:func:`daa_sil.wellclear.violation_interval`. The only approximation is the chord (sagitta
``R (1 - cos(dpsi/2))``, about 1 m for a 5 deg turn at 55 m/s; ``a h^2 / 8`` for accelerations).
"""

from __future__ import annotations

import numpy as np

from .. import wellclear as wc
from ..frames import wrap_pi
from ..kinematics import AircraftState, Command, fly_command
from ..thresholds import Thresholds
from .config import DaaConfig


def _intruder_rel(own_pos, t, intr: AircraftState) -> np.ndarray:
    """Relative position ownship minus intruder ``(N, M, ...knots, 3)`` for own ``(N, ...knots, 3)``."""
    extra = own_pos.ndim - 2  # number of knot axes after N
    ip = intr.position().reshape(intr.shape + (1,) * extra + (3,))
    iv = intr.velocity().reshape(intr.shape + (1,) * extra + (3,))
    return own_pos[:, None] - (ip + t[:, None, ..., None] * iv)


def _cannot_violate(s, v, th: Thresholds, length) -> np.ndarray:
    """Cheap sufficient test that straight-line motion ``s + t v``, t in [0, length], never violates.

    Vertical (TCOA = 0 only): ``|z|`` stays above ZTHR. Horizontal: a violation needs
    ``r <= r* = (TTHR |v| + sqrt(TTHR^2 |v|^2 + 4 DTHR^2)) / 2`` (from ``tau_mod <= TTHR``, which implies
    ``r^2 - DTHR^2 <= TTHR r |v|``), and ``r >= max(d_cpa, r0 - |v| length)`` along the line.
    """
    z0 = s[..., 2]
    z1 = z0 + v[..., 2] * length
    vert = (z0 * z1 > 0) & (np.minimum(np.abs(z0), np.abs(z1)) > th.zthr) if th.tcoa == 0 else False
    vv = np.hypot(v[..., 0], v[..., 1])
    r0 = np.hypot(s[..., 0], s[..., 1])
    tv = th.tthr * vv
    r_star = 0.5 * (tv + np.sqrt(tv * tv + 4.0 * th.dthr * th.dthr)) + 1e-6
    with np.errstate(invalid="ignore", divide="ignore"):
        dcpa = np.abs(s[..., 0] * v[..., 1] - s[..., 1] * v[..., 0]) / np.where(vv > 0, vv, np.inf)
    dcpa = np.where(vv > 0, dcpa, r0)
    horiz = (np.maximum(dcpa, r0 - vv * length) > r_star)
    return vert | horiz


def filtered_interval(s, v, th: Thresholds, length) -> tuple[np.ndarray, np.ndarray]:
    """:func:`daa_sil.wellclear.violation_interval` over ``[0, length]``, evaluated only where
    :func:`_cannot_violate` does not already rule a violation out (same result, less work)."""
    shape = s.shape[:-1]
    length = np.broadcast_to(length, shape)
    todo = np.nonzero(~_cannot_violate(s, v, th, length).ravel())[0]
    t_in = np.full(shape, np.inf)
    t_out = np.full(shape, -np.inf)
    if todo.size:
        a, b = wc.violation_interval(s.reshape(-1, 3)[todo], np.broadcast_to(v, s.shape).reshape(-1, 3)[todo],
                                     th, 0.0, length.ravel()[todo])
        t_in.ravel()[todo] = a
        t_out.ravel()[todo] = b
    return t_in, t_out


def knot_path_conflicts(own_pos, own_vel, t, intr: AircraftState, th: Thresholds, t_end: float,
                        all_tails: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """First violation time and last exit time (s) per intruder and candidate.

    ``own_pos``/``own_vel``: ``(N, P, K, 3)`` ownship at the knots of P paths; ``t``: knot times
    broadcastable to ``(N, P, K)``; ``intr``: intruders ``(N, M)``. Returns ``(t_in, t_out)`` of shape
    ``(N, M, P, K)`` for candidate k (path to knot k, then straight) over ``[0, t_end]``; no violation
    is ``(inf, -inf)``. With ``all_tails=False`` only the last knot's candidate is evaluated (the
    result has K = 1).
    """
    n, p, k = own_pos.shape[:3]
    t = np.broadcast_to(np.asarray(t, float), (n, p, k))
    s = _intruder_rel(own_pos, t, intr)  # (N, M, P, K, 3)
    iv = intr.velocity().reshape(intr.shape + (1, 1, 3))
    tt = np.broadcast_to(t[:, None], s.shape[:-1])
    if k > 1:
        h = tt[..., 1:] - tt[..., :-1]
        v_seg = (s[..., 1:, :] - s[..., :-1, :]) / h[..., None]
        seg_in, seg_out = filtered_interval(s[..., :-1, :], v_seg, th, h)
        seg_in = seg_in + tt[..., :-1]
        seg_out = seg_out + tt[..., :-1]
        pre_in = np.minimum.accumulate(seg_in, axis=-1)
        pre_out = np.maximum.accumulate(seg_out, axis=-1)
        inf = np.full(pre_in.shape[:-1] + (1,), np.inf)
        pre_in = np.concatenate([inf, pre_in], axis=-1)
        pre_out = np.concatenate([-inf, pre_out], axis=-1)
    else:
        pre_in = np.full(s.shape[:-1], np.inf)
        pre_out = np.full(s.shape[:-1], -np.inf)
    if not all_tails:
        s, tt, pre_in, pre_out = s[..., -1:, :], tt[..., -1:], pre_in[..., -1:], pre_out[..., -1:]
        own_vel = own_vel[..., -1:, :]
    v_tail = own_vel[:, None] - iv
    tail_in, tail_out = filtered_interval(s, v_tail, th, np.maximum(t_end - tt, 0.0))
    in_window = tt <= t_end
    tail_in = np.where(in_window, tail_in + tt, np.inf)
    tail_out = np.where(in_window, tail_out + tt, -np.inf)
    t_in = np.minimum(pre_in, tail_in)
    t_out = np.maximum(pre_out, tail_out)
    t_in = np.where(t_in <= t_end, t_in, np.inf)
    return t_in, np.where(np.isfinite(t_in), np.minimum(t_out, t_end), -np.inf)


def maneuver_times(own: AircraftState, cmd: Command, cfg: DaaConfig) -> tuple[np.ndarray, ...]:
    """Time (s) to reach the commanded track, vertical speed and ground speed at the limits."""
    c = cmd.resolved(own)
    t_trk = np.abs(wrap_pi(c.trk - own.trk)) / cfg.turn_rate
    t_vs = np.abs(np.clip(c.vs, -cfg.max_vs, cfg.max_vs) - own.vs) / cfg.vertical_accel
    t_gs = np.abs(np.clip(c.gs, cfg.min_gs, cfg.max_gs) - own.gs) / cfg.horizontal_accel
    return t_trk, t_vs, t_gs


def command_conflicts(own: AircraftState, intr: AircraftState, cmd: Command, cfg: DaaConfig,
                      t_end: float) -> tuple[np.ndarray, np.ndarray]:
    """``(t_in, t_out)`` per intruder ``(N, M)`` when the ownship flies ``cmd`` (kinematically, as
    :func:`daa_sil.kinematics.fly_command`) and the intruders fly straight, over ``[0, t_end]`` s.

    The maneuver phase is sampled at the knot spacing of the axes the command changes (the finest
    one if several), so a single-axis command gives exactly the same answer as its band candidate.
    """
    cmd = cmd.resolved(own)
    t_trk, t_vs, t_gs = maneuver_times(own, cmd, cfg)
    eps = 1e-9
    knots = np.stack([np.where(t_trk > eps, cfg.knot_trk, np.inf), np.where(t_vs > eps, cfg.knot_vs, np.inf),
                      np.where(t_gs > eps, cfg.knot_gs, np.inf)], axis=-1).min(axis=-1)
    t_man = np.maximum(np.maximum(t_trk, t_vs), t_gs)
    h = np.where(np.isfinite(knots), knots, 1.0)
    n_knots = np.where(t_man > eps, np.ceil(t_man / h - 1e-9), 0.0)
    j_max = int(n_knots.max()) if n_knots.size else 0
    t = np.arange(j_max + 1)[None, :] * h[:, None]  # (N, J+1)
    path = fly_command(own[:, None], cmd[:, None], dt=t, perf=cfg.performance())
    pos = path.position()[:, None]
    vel = path.velocity()[:, None]
    t_in, t_out = knot_path_conflicts(pos, vel, t[:, None], intr, cfg.th, t_end, all_tails=False)
    return t_in[..., 0, 0], t_out[..., 0, 0]


def safety_metric(own: AircraftState, intr: AircraftState, cmd: Command, cfg: DaaConfig,
                  horizon_s: "float | None" = None) -> np.ndarray:
    """Safety metric SM(u), s, ``(N,)``: ``min(t_LoWC(u), H + margin) - H``.

    ``t_LoWC(u)`` is the first time the ownship, flying command ``u`` kinematically from its current
    state (turn at ``cfg.turn_rate``, accelerate at the limits, then straight), violates well clear
    (``cfg.th``) with **any** intruder (intruders straight-line), searched over ``[0, H + margin]``;
    ``H = horizon_s`` (default ``cfg.sm_horizon_s`` = 55 s, the corrective alerting time) and
    ``margin = cfg.sm_margin_s``. So SM > 0 iff following u keeps the ownship well clear of every
    intruder for H seconds; SM = -H when violating now; SM = margin when clear over H + margin.
    """
    horizon = cfg.sm_horizon_s if horizon_s is None else float(horizon_s)
    t_end = horizon + cfg.sm_margin_s
    t_in, _ = command_conflicts(own, intr, cmd, cfg, t_end)
    return sm_from_tin(t_in.min(axis=-1) if t_in.shape[-1] else np.full(own.shape, np.inf), horizon, cfg)


def sm_from_tin(t_in, horizon: float, cfg: DaaConfig) -> np.ndarray:
    """SM (s) from the first LoWC time (s; inf = none) for horizon ``horizon`` s."""
    return np.minimum(t_in, horizon + cfg.sm_margin_s) - horizon
