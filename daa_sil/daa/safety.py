"""The safety metric SM(u) of a command (paper Alg. 1 and 2).

The command is flown as a maneuver path at the DO-365B performance limits, its conflicts with
every intruder are found (:mod:`daa_sil.daa.trajectory`), and SM is the time to predicted LoWC
beyond the alerting time (s; positive = safe). The exact definition is in docs/daa.md.
"""

from __future__ import annotations

import numpy as np

from daa_sil.daa import kernels
from daa_sil.daa.kernels import plan_layout as plan_cols
from daa_sil.daa.config import DaaConfig
from daa_sil.daa.trajectory import ManeuverPaths, path_conflicts
from daa_sil.geometry.frames import wrap_2pi, wrap_pi
from daa_sil.geometry.kinematics import (STRAIGHT_TURN_RATE, AircraftState, Command, flat_inputs, fly_command,
                                         horizontal_segment, vertical_toward)

#: False: :func:`command_paths` planned in numpy and its knot states from the numpy ``_CommandMotion.state``
#: (the oracles the tests compare the compiled ``kernels.command_plan`` and
#: ``kernels.motion.command_states_into`` with)
COMPILED = True
#: a maneuver time (s) at or below this is no change of that axis
_EPS = 1e-9


def maneuver_times(own: AircraftState, cmd: Command, cfg: DaaConfig) -> tuple[np.ndarray, ...]:
    """Time (s) to reach the commanded track, vertical speed and ground speed at the limits."""
    c = cmd.resolved(own)
    perf = cfg.performance()
    t_trk = np.abs(wrap_pi(c.trk - own.trk)) / cfg.turn_rate
    t_vs = np.abs(np.clip(c.vs, -perf.max_vs, perf.max_vs) - own.vs) / cfg.vertical_accel
    t_gs = np.abs(np.clip(c.gs, perf.min_gs, perf.max_gs) - own.gs) / cfg.horizontal_accel
    return t_trk, t_vs, t_gs


class _CommandMotion:
    """:func:`daa_sil.geometry.kinematics.fly_command` from one state, with the start of each of its three phases
    (turn and speed change together, then the longer one alone, then straight) computed once. The state
    at a time is then one piece of one phase: the same operations as ``fly_command`` (so the same
    numbers), with the sines and cosines of each phase's initial track reused (4 instead of 20 per state)."""

    def __init__(self, own: AircraftState, cmd: Command, perf):
        c = cmd.resolved(own)
        self.own, self.perf, self.trk_cmd = own, perf, c.trk
        self.tgt_gs = np.clip(c.gs, perf.min_gs, perf.max_gs)
        self.tgt_vs = np.clip(c.vs, -perf.max_vs, perf.max_vs)
        self.dpsi = wrap_pi(c.trk - own.trk)
        w = np.sign(self.dpsi) * perf.max_turn_rate
        t_turn = np.abs(self.dpsi) / perf.max_turn_rate if perf.max_turn_rate > 0 else np.zeros_like(self.dpsi)
        self.dgs = self.tgt_gs - own.gs
        acc = np.sign(self.dgs) * perf.horizontal_accel
        t_spd = np.abs(self.dgs) / perf.horizontal_accel if perf.horizontal_accel > 0 else np.zeros_like(self.dgs)
        b1, b2 = np.minimum(t_turn, t_spd), np.maximum(t_turn, t_spd)
        starts = [(own.x, own.y, own.gs, own.trk)]
        params = []
        for lo, hi in ((0.0, b1), (b1, b2), (b2, None)):
            w_p, a_p = np.where(t_turn > lo, w, 0.0), np.where(t_spd > lo, acc, 0.0)
            params.append((w_p, a_p))
            if hi is not None:
                starts.append(horizontal_segment(*starts[-1], w_p, a_p, np.maximum(hi - lo, 0.0)))
        #: (3, N) phase start times, x, y, gs, trk, turn rate, acceleration, and sin / cos of the start track
        self.t0 = np.stack([np.zeros_like(b1), b1, b2])
        self.x, self.y, self.gs, self.trk = (np.stack([st[i] for st in starts]) for i in range(4))
        self.w, self.acc = (np.stack([pr[i] for pr in params]) for i in range(2))
        self.sin0, self.cos0 = np.sin(self.trk), np.cos(self.trk)
        self.exotic = bool(np.any((self.w != 0.0) & (np.abs(self.w) < STRAIGHT_TURN_RATE)))  # (as _arc's "small" branch)

    def kin(self) -> "tuple | None":
        """The motion as data for the compiled kernels (:attr:`ManeuverPaths.kin`), None when exotic."""
        if self.exotic:
            return None
        phases = np.stack([self.t0, self.x, self.y, self.gs, self.trk, self.w, self.acc, self.sin0, self.cos0], axis=-1)
        o = self.own
        enc = np.stack([self.dpsi, self.trk_cmd, self.dgs, self.tgt_gs, o.z, o.vs, self.tgt_vs], axis=-1)
        p = self.perf
        return ("command", np.ascontiguousarray(phases.transpose(1, 0, 2), dtype=float), np.asarray(enc, float),
                float(p.max_turn_rate), float(p.horizontal_accel), float(p.vertical_accel))

    def state(self, n: np.ndarray, tau: np.ndarray) -> tuple:
        """Position and velocity (six arrays) of encounters ``n`` at times ``tau`` (broadcast together)."""
        if self.exotic:  # a turn rate _arc treats as straight: the reference implementation
            st = fly_command(self.own[n], Command(self.trk_cmd[n], self.tgt_vs[n], self.tgt_gs[n]), dt=tau,
                             perf=self.perf)
            return st.x, st.y, st.z, st.gs * np.sin(st.trk), st.gs * np.cos(st.trk), st.vs
        n, tau = np.broadcast_arrays(n, tau)
        ph = (tau > self.t0[1, n]).astype(np.intp) + (tau > self.t0[2, n])
        g = lambda a: a[ph, n]  # noqa: E731
        t = tau - g(self.t0)
        gs0, acc, w, trk0, s0, c0 = g(self.gs), g(self.acc), g(self.w), g(self.trk), g(self.sin0), g(self.cos0)
        turning = w != 0.0
        ws = np.where(turning, w, 1.0)
        th1 = trk0 + w * t
        s1, c1 = np.sin(th1), np.cos(th1)
        dist = gs0 * t + 0.5 * acc * t * t
        # _arc's two branches (straight: w = 0, so trk0 + 0.5 w t = trk0 exactly)
        dx = np.where(turning, gs0 * (c0 - c1) / ws + acc * (-t * c1 / ws + (s1 - s0) / ws ** 2), dist * s0)
        dy = np.where(turning, gs0 * (s1 - s0) / ws + acc * (t * s1 / ws + (c1 - c0) / ws ** 2), dist * c0)
        x, y = g(self.x) + dx, g(self.y) + dy
        gs, trk = gs0 + acc * t, th1
        perf = self.perf
        trk = np.where(np.abs(self.dpsi[n]) <= perf.max_turn_rate * tau, self.trk_cmd[n], trk)
        gs = np.where(np.abs(self.dgs[n]) <= perf.horizontal_accel * tau, self.tgt_gs[n], gs)
        o = self.own
        z, vs = vertical_toward(o.z[n], o.vs[n], self.tgt_vs[n], perf.vertical_accel, tau)
        trk = wrap_2pi(trk)
        return x, y, z, gs * np.sin(trk), gs * np.cos(trk), vs


def command_paths(own: AircraftState, cmd: Command, cfg: DaaConfig) -> ManeuverPaths:
    """The single path (P = 1) of each ownship flying ``cmd`` kinematically (as
    :func:`daa_sil.geometry.kinematics.fly_command`), with knots at the spacing of the axes the command changes
    (the finest one if several), so a single-axis command has the knots of its band candidate. Each path
    ends at its own last knot (``n_seg``: the end of its maneuver) and has its own ``vz_const``, so that an
    encounter's path is the one a call of its own makes, whatever the other encounters' commands.

    Planned in one compiled pass (``kernels.command_plan``) for a batch of ownships ``(N,)``; the numpy
    code (:func:`command_paths_reference`, also where ``COMPILED`` is False) gives the same numbers."""
    perf = cfg.performance()
    flat = flat_inputs(own.shape, (own.x, own.y, own.z, own.gs, own.trk, own.vs, cmd.trk, cmd.vs, cmd.gs)) \
        if COMPILED and len(own.shape) == 1 else None
    if flat is None:
        return command_paths_reference(own, cmd, cfg)
    k = kernels.get()
    n = own.shape[0]
    phases, enc, plan = np.empty((n, 3, 9)), np.empty((n, 7)), np.empty((n, plan_cols.N_PLAN))
    if k.command_plan_into(tuple(flat[:6]), tuple(flat[6:9]),
                           (float(perf.max_turn_rate), float(perf.horizontal_accel), float(perf.vertical_accel),
                            float(perf.min_gs), float(perf.max_gs), float(perf.max_vs)),
                           (float(cfg.turn_rate), float(cfg.vertical_accel), float(cfg.horizontal_accel)),
                           (float(cfg.knot_trk), float(cfg.knot_vs), float(cfg.knot_gs)), STRAIGHT_TURN_RATE, _EPS,
                           phases, enc, plan):
        return command_paths_reference(own, cmd, cfg)  # a turn rate the numpy motion treats as straight
    h = plan[:, plan_cols.H]
    j_max = int(plan[:, plan_cols.N_KNOTS].max()) if n else 0
    t = np.arange(j_max + 1)[None, :] * h[:, None]  # (N, J+1)
    kin = ("command", phases, enc, float(perf.max_turn_rate), float(perf.horizontal_accel), float(perf.vertical_accel))
    out = np.empty((6,) + t.shape)
    k.command_states_into(*kin[1:], t, out)
    px, py, pz, vx, vy, vz = out
    motion: list = []  # the numpy motion, made only if a caller evaluates the true path itself

    def state_at(n_, p):
        if not motion:
            motion.append(_CommandMotion(own, cmd.resolved(own), perf))
        return lambda tq: motion[0].state(n_, tq)

    col = lambda c: plan[:, c, None]  # noqa: E731  ((N, 1): one path per encounter)
    return ManeuverPaths((px[:, None], py[:, None], pz[:, None]), (vx[:, None], vy[:, None], vz[:, None]),
                         t[:, None], state_at, col(plan_cols.ACC_H), col(plan_cols.ACC_V),
                         vz_const=~(plan[:, plan_cols.T_VS] > _EPS), jerk_h=col(plan_cols.JERK),
                         kink_t=plan[:, None, plan_cols.KINK_TRK:plan_cols.KINK_GS + 1], kin=kin,
                         n_seg=plan[:, plan_cols.N_KNOTS].astype(np.int64))


def command_paths_reference(own: AircraftState, cmd: Command, cfg: DaaConfig) -> ManeuverPaths:
    """:func:`command_paths` in numpy (the compiled plan's reference; its knot states still come from the
    compiled ``command_states_into`` unless ``COMPILED`` is False)."""
    cmd = cmd.resolved(own)
    perf = cfg.performance()
    t_trk, t_vs, t_gs = maneuver_times(own, cmd, cfg)
    eps = _EPS
    knots = np.stack([np.where(t_trk > eps, cfg.knot_trk, np.inf), np.where(t_vs > eps, cfg.knot_vs, np.inf),
                      np.where(t_gs > eps, cfg.knot_gs, np.inf)], axis=-1).min(axis=-1)
    t_man = np.maximum(np.maximum(t_trk, t_vs), t_gs)
    h = np.where(np.isfinite(knots), knots, 1.0)
    n_knots = np.where(t_man > eps, np.ceil(t_man / h - 1e-9), 0.0)
    j_max = int(n_knots.max()) if n_knots.size else 0
    t = np.arange(j_max + 1)[None, :] * h[:, None]  # (N, J+1)
    motion = _CommandMotion(own, cmd, perf)
    kin = motion.kin()
    if COMPILED and kin is not None:
        out = np.empty((6,) + t.shape)
        kernels.get().command_states_into(*kin[1:], t, out)
        px, py, pz, vx, vy, vz = out
    else:
        px, py, pz, vx, vy, vz = motion.state(np.arange(own.shape[0])[:, None], t)
    gs_max = np.maximum(own.gs, np.clip(cmd.gs, perf.min_gs, perf.max_gs))
    acc_h = np.where(t_trk > eps, gs_max * cfg.turn_rate, 0.0) + np.where(t_gs > eps, cfg.horizontal_accel, 0.0)
    acc_v = np.where(t_vs > eps, cfg.vertical_accel, 0.0)
    # v = g(t) u(trk(t)): |v''| <= 2 |g'| w + g w^2 between the instants the turn or the speed change
    # ends (the horizontal acceleration jumps there)
    w = np.where(t_trk > eps, cfg.turn_rate, 0.0)
    jerk = 2.0 * np.where(t_gs > eps, cfg.horizontal_accel, 0.0) * w + gs_max * w * w
    kink = np.stack([np.where(t_trk > eps, t_trk, np.inf), np.where(t_gs > eps, t_gs, np.inf)], axis=-1)

    def state_at(n, p):
        return lambda tq: motion.state(n, tq)

    return ManeuverPaths((px[:, None], py[:, None], pz[:, None]), (vx[:, None], vy[:, None], vz[:, None]),
                         t[:, None], state_at,
                         acc_h[:, None], acc_v[:, None], vz_const=~(t_vs > eps), jerk_h=jerk[:, None],
                         kink_t=kink[:, None], kin=kin, n_seg=n_knots.astype(np.int64))


def command_conflicts(own: AircraftState, intr: AircraftState, cmd: Command, cfg: DaaConfig,
                      t_end: float, exits: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """``(t_in, t_out)`` per intruder ``(N, M)`` when the ownship flies ``cmd`` (kinematically, as
    :func:`daa_sil.geometry.kinematics.fly_command`, evaluated on the true trajectory) and the intruders fly
    straight, over ``[0, t_end]`` s. With ``exits=False`` only ``t_in`` is exact (``t_out`` may be
    late by up to one knot interval during the maneuver)."""
    paths = command_paths(own, cmd, cfg)
    pc = path_conflicts(paths, intr, cfg.th, t_end, tails="last", exits=exits)
    pre_in, pre_out = pc.prefix()  # (the segments past a path's last knot are clear: the last prefix is its own)
    last = paths.n_seg[:, None, None, None]  # the tail from each path's own last knot
    t_in = np.minimum(pre_in[..., -1], np.take_along_axis(pc.tail_in, last, -1)[..., 0])
    t_out = np.maximum(pre_out[..., -1], np.take_along_axis(pc.tail_out, last, -1)[..., 0])
    t_in = np.where(t_in <= t_end, t_in, np.inf)
    t_out = np.where(np.isfinite(t_in), np.minimum(t_out, t_end), -np.inf)
    return t_in[..., 0], t_out[..., 0]


def _command_first_entry(own: AircraftState, intr: AircraftState, cmd: Command, cfg: DaaConfig,
                         t_end: float) -> np.ndarray:
    """The ``t_in`` (N, M) of :func:`command_conflicts` with ``exits=False``, by the same operations, without
    its ``t_out`` (:func:`safety_metric` reads only the first entries)."""
    paths = command_paths(own, cmd, cfg)
    pc = path_conflicts(paths, intr, cfg.th, t_end, tails="last", exits=False)
    pre_in = pc.prefix_in()  # (the segments past a path's last knot are clear: the last prefix is its own)
    n = paths.n_seg.shape[0]
    t_in = np.minimum(pre_in[..., -1], pc.tail_in[np.arange(n), :, :, paths.n_seg])  # (each path's own last tail)
    return np.where(t_in <= t_end, t_in, np.inf)[..., 0]


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
    t_in = _command_first_entry(own, intr, cmd, cfg, t_end)
    return sm_from_tin(t_in.min(axis=-1) if t_in.shape[-1] else np.full(own.shape, np.inf), horizon, cfg)


def sm_from_tin(t_in, horizon: float, cfg: DaaConfig) -> np.ndarray:
    """SM (s) from the first LoWC time (s; inf = none) for horizon ``horizon`` s."""
    return np.minimum(t_in, horizon + cfg.sm_margin_s) - horizon
