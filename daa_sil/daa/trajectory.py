"""Conflict detection along kinematic ownship trajectories against straight-line intruders.

A *knot path* is the ownship sampled at knot times ``t_0 = 0 < t_1 < ... < t_J`` while it
maneuvers (turn / accelerate at the limits). Candidate ``k`` of the path flies the path up to
knot ``k`` and then continues straight with the knot-``k`` velocity. Between knots the relative
motion is taken as the chord (straight line) between the sampled relative positions; each chord
and each straight tail is checked with the exact closed form of
:func:`daa_sil.wellclear.violation_interval` (re-stated on contiguous component arrays in
:func:`interval_soa`, which gives identical numbers about 2x faster). The only approximation is the chord (sagitta
``R (1 - cos(dpsi/2))``, about 1 m for a 5 deg turn at 55 m/s; ``a h^2 / 8`` for accelerations).
"""

from __future__ import annotations

import numpy as np

from .. import wellclear as wc
from ..frames import wrap_pi
from ..kinematics import AircraftState, Command, fly_command
from ..thresholds import Thresholds
from .config import DaaConfig


def _components(a: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Contiguous x, y, z arrays of a ``(..., 3)`` array (the kernels below read each many times)."""
    return (np.ascontiguousarray(a[..., 0]), np.ascontiguousarray(a[..., 1]), np.ascontiguousarray(a[..., 2]))


def interval_soa(sx, sy, sz, vx, vy, vz, length, th: Thresholds) -> tuple[np.ndarray, np.ndarray]:
    """:func:`daa_sil.wellclear.violation_interval` over ``[0, length]`` for 1-D component arrays.

    The same window functions (:func:`~daa_sil.wellclear.vertical_window`,
    :func:`~daa_sil.wellclear.horizontal_window`), so the results are identical; it is faster because (1) the components are contiguous arrays instead of strided views of ``(..., 3)`` arrays
    and (2) the horizontal part, which is most of the work, runs only where the vertical window is
    not empty (elsewhere the answer is ``(inf, -inf)`` in both).
    """
    D, H, TT, TC = th.dthr, th.zthr, th.tthr, th.tcoa
    n = sx.shape[0]
    t_in = np.full(n, np.inf)
    t_out = np.full(n, -np.inf)
    # -- vertical window (wellclear.violation_interval, t0 = 0, t1 = length) --------------------
    vlo, vhi = wc.vertical_window(sz, vz, 0.0, length, H, TC)
    idx = np.flatnonzero(vlo <= vhi)
    if not idx.size:
        return t_in, t_out
    t_lo = vlo[idx]
    L = vhi[idx] - t_lo
    hx, hy = vx[idx], vy[idx]
    # -- horizontal interval on [0, L] from p = s + t_lo v, only inside the vertical window -------
    px = sx[idx] + t_lo * hx
    py = sy[idx] + t_lo * hy
    hlo, hhi = wc.horizontal_window(px, py, hx, hy, L, D, TT)
    point = L == 0
    if np.any(point):  # a single-instant vertical window: the predicate there (as DAIDALUS does)
        j = np.flatnonzero(point)
        p3 = np.stack([px[j], py[j], sz[idx[j]] + t_lo[j] * vz[idx[j]]], axis=-1)
        at = wc.wcv(p3, np.stack([hx[j], hy[j], vz[idx[j]]], axis=-1), th)
        hlo[j] = np.where(at, 0.0, np.inf)
        hhi[j] = np.where(at, 0.0, -np.inf)
    good = hlo <= hhi
    t_in[idx] = np.where(good, hlo + t_lo, np.inf)
    t_out[idx] = np.where(good, hhi + t_lo, -np.inf)
    return t_in, t_out


def filtered_interval(s, v, th: Thresholds, length) -> tuple[np.ndarray, np.ndarray]:
    """:func:`daa_sil.wellclear.violation_interval` over ``[0, length]`` for relative positions ``s``
    and velocities ``v`` (``(..., 3)``, broadcast together), via :func:`interval_soa`."""
    shape = np.broadcast_shapes(s.shape[:-1], v.shape[:-1], np.shape(length))
    comp = [np.ascontiguousarray(np.broadcast_to(a[..., i], shape)).ravel() for a in (s, v) for i in range(3)]
    t_in, t_out = interval_soa(*comp, np.ascontiguousarray(np.broadcast_to(length, shape)).ravel(), th)
    return t_in.reshape(shape), t_out.reshape(shape)


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
    m = intr.shape[1]
    shape = (n, m, p, k)
    tt = np.broadcast_to(np.asarray(t, float), (n, p, k))[:, None]  # (N, 1, P, K)
    ipos, ivel = intr.position(), intr.velocity()  # (N, M, 3)
    own_c, ovel_c = _components(own_pos), _components(own_vel)
    # relative position ownship - intruder at the knots, per component (N, M, P, K)
    s = [own_c[i][:, None] - (ipos[..., i][:, :, None, None] + tt * ivel[..., i][:, :, None, None]) for i in range(3)]
    tt = np.broadcast_to(tt, shape)
    if k > 1:
        h = tt[..., 1:] - tt[..., :-1]
        seg_shape = shape[:-1] + (k - 1,)
        comp = [np.ascontiguousarray(c[..., :-1]).ravel() for c in s]
        vel = [((c[..., 1:] - c[..., :-1]) / h).ravel() for c in s]
        seg_in, seg_out = interval_soa(*comp, *vel, np.ascontiguousarray(h).ravel(), th)
        seg_in = seg_in.reshape(seg_shape) + tt[..., :-1]
        seg_out = seg_out.reshape(seg_shape) + tt[..., :-1]
        pre_in = np.minimum.accumulate(seg_in, axis=-1)
        pre_out = np.maximum.accumulate(seg_out, axis=-1)
        inf = np.full(pre_in.shape[:-1] + (1,), np.inf)
        pre_in = np.concatenate([inf, pre_in], axis=-1)
        pre_out = np.concatenate([-inf, pre_out], axis=-1)
    else:
        pre_in = np.full(shape, np.inf)
        pre_out = np.full(shape, -np.inf)
    if not all_tails:
        s = [c[..., -1:] for c in s]
        tt, pre_in, pre_out = tt[..., -1:], pre_in[..., -1:], pre_out[..., -1:]
        own_vel = own_vel[..., -1:, :]
        ovel_c = _components(own_vel)
    tail_shape = tt.shape
    vel = [np.broadcast_to(ovel_c[i][:, None] - ivel[..., i][:, :, None, None], tail_shape).ravel() for i in range(3)]
    comp = [np.ascontiguousarray(np.broadcast_to(c, tail_shape)).ravel() for c in s]
    tail_in, tail_out = interval_soa(*comp, *vel, np.maximum(t_end - tt, 0.0).ravel(), th)
    tail_in, tail_out = tail_in.reshape(tail_shape), tail_out.reshape(tail_shape)
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
