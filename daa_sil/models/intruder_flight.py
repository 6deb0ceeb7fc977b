"""How the scripted intruders of an encounter fly: their performance limits, their maneuver segments
flown on the simulator's step grid, their placement for a prescribed closest approach and the closest
approach they realise (the construction in ``docs/models.md``, "Encounters")."""

from __future__ import annotations

import numpy as np

from daa_sil.geometry.frames import wrap_pi
from daa_sil.geometry.kinematics import AircraftState, Performance, advance
from daa_sil.geometry.units import DEG

#: limits used to advance scripted intruders (faster and more agile than the ownship defaults)
INTRUDER_PERFORMANCE = Performance(max_turn_rate=10.0 * DEG, horizontal_accel=5.0, vertical_accel=10.0,
                                   max_vs=60.0, min_gs=5.0, max_gs=450.0)


def segment_controls(seg, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Turn rate (rad/s), acceleration and vertical acceleration (m/s^2) the segments ``seg`` command at
    step time ``t`` (s): a segment ``[start, end)`` is active iff ``start <= t < end``; summed over segments."""
    start, end, w, a, av = seg
    act = (start <= t) & (t < end)
    return (np.where(act, w, 0.0).sum(-1), np.where(act, a, 0.0).sum(-1), np.where(act, av, 0.0).sum(-1))


def fly_segments(state: AircraftState, seg, t_end: float, dt: float, sub: float, on_sample=None) -> AircraftState:
    """Fly ``state`` along the maneuver segments ``seg`` from 0 to ``t_end`` (s) on the step grid
    ``dt`` (s; controls fixed per step), in sub-steps ``sub`` (s); ``on_sample(t, state)`` is called
    at every sub-step time (incl. 0)."""
    n_sub = max(1, int(round(dt / sub)))
    h = dt / n_sub
    s = state
    if on_sample is not None:
        on_sample(0.0, s)
    k = 0
    while k * dt < t_end - 1e-9:
        t_k = k * dt
        w, a, av = segment_controls(seg, t_k)
        for j in range(n_sub):
            step = min(h, t_end - (t_k + j * h))
            if step <= 1e-12:
                break
            s = advance(s, w, a, av, step, INTRUDER_PERFORMANCE)
            if on_sample is not None:
                on_sample(t_k + j * h + step, s)
        k += 1
    return s


def place_intruders(own0: AircraftState, intr_gs, intr_vs, intr_trk0, seg, t_c, hmd_abs, vmd, hint_bearing,
           dt: float) -> tuple[AircraftState, np.ndarray]:
    """Intruder initial states so that at ``t_c`` (s) the horizontal offset from the straight
    ownship is ``hmd_abs`` perpendicular to the relative velocity (side nearest ``hint_bearing``,
    clockwise rad from the ownship track) and the vertical offset is ``vmd``. Returns the states and
    the realised CPA bearing (clockwise rad from the ownship track, in [-pi, pi))."""
    shape = np.shape(intr_gs)
    zero = np.zeros(shape)
    tmpl0 = AircraftState(zero, zero, zero, intr_gs, intr_trk0, intr_vs)
    tc = float(t_c)
    tmpl_c = fly_segments(tmpl0, seg, tc, dt, dt)
    ov = own0.velocity()
    own_c = own0.position() + ov * tc
    own_c = np.broadcast_to(own_c[:, None, :], shape + (3,)) if len(shape) == 2 else own_c
    ov_b = np.broadcast_to(ov[:, None, :], shape + (3,)) if len(shape) == 2 else ov
    vr = tmpl_c.velocity() - ov_b
    nrm = np.hypot(vr[..., 0], vr[..., 1])
    nrm = np.where(nrm > 1e-9, nrm, 1.0)
    nx, ny = vr[..., 1] / nrm, -vr[..., 0] / nrm  # right-hand normal of v_r
    own_trk = own0.trk[:, None] if len(shape) == 2 else own0.trk
    b_pos = wrap_pi(np.arctan2(nx, ny) - own_trk)
    b_neg = wrap_pi(b_pos + np.pi)
    use_pos = np.abs(wrap_pi(b_pos - hint_bearing)) <= np.abs(wrap_pi(b_neg - hint_bearing))
    sgn = np.where(use_pos, 1.0, -1.0)
    rx, ry = sgn * hmd_abs * nx, sgn * hmd_abs * ny
    target = np.stack([own_c[..., 0] + rx, own_c[..., 1] + ry, own_c[..., 2] + vmd], axis=-1)
    off = target - tmpl_c.position()
    init = AircraftState(off[..., 0], off[..., 1], off[..., 2], intr_gs, intr_trk0, intr_vs)
    return init, np.where(use_pos, b_pos, b_neg)


def realised_cpa(own0: AircraftState, init: AircraftState, seg, duration: float, dt: float, sub: float):
    """The intruders' closest approach to the straight ownship over [0, duration] (s), sampled on a
    ``sub`` (s) grid: arrays of horizontal miss distance (m), vertical offset at it (m) and its time (s)."""
    ov = own0.velocity()
    op = own0.position()
    two_d = init.x.ndim == 2
    best = {"r": np.full(init.shape, np.inf), "t": np.zeros(init.shape), "dz": np.zeros(init.shape)}

    def sample(t, s):
        o = op + ov * t
        if two_d:
            o = o[:, None, :]
        dx, dy, dz = s.x - o[..., 0], s.y - o[..., 1], s.z - o[..., 2]
        r = np.hypot(dx, dy)
        better = r < best["r"]
        best["r"] = np.where(better, r, best["r"])
        best["t"] = np.where(better, t, best["t"])
        best["dz"] = np.where(better, dz, best["dz"])

    fly_segments(init, seg, duration, dt, sub, sample)
    return best["r"], best["dz"], best["t"]
