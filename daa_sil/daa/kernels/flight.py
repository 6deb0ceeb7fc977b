"""Truth motion, compiled: :func:`daa_sil.geometry.kinematics.advance` (intruders, scripted turn rate and
accelerations), :func:`~daa_sil.geometry.kinematics.fly_command` (the ownship toward a command) and the arc
they are made of (:func:`~daa_sil.geometry.kinematics.horizontal_segment`, also SM's phase starts), one
element at a time with the numpy code's operations in its order (``docs/daa.md``, "Compiled kernels").

Every input is a 1-d array of the batch's length or of length 1 (one value for every element: numpy's
broadcast of a scalar); ``dt`` (s) is one float, as ``np.clip(t, 0.0, dt)`` with a scalar bound is
``np.minimum(np.maximum(t, 0.0), dt)`` (with an array bound numpy rounds -0.0 differently). The numpy
functions (``kinematics.advance_reference`` / ``fly_command_reference`` / ``horizontal_segment_reference``)
are the references.
"""

from __future__ import annotations

import math

from numba import boolean, types, void

from daa_sil.daa.kernels.jit import inline, kernel
from daa_sil.daa.kernels.scalar import npmax, npmin, npsign, vertical_toward
from daa_sil.daa.kernels.signatures import A, F, O

_TWO_PI = 2.0 * math.pi
_PI = math.pi


@inline
def at(a, i):
    """Element ``i`` of ``a``, or its one element (a broadcast scalar)."""
    return a[i] if a.shape[0] != 1 else a[0]


@inline
def clip(x, lo, hi):
    """``np.clip(x, lo, hi)`` with scalar bounds."""
    return npmin(npmax(x, lo), hi)


@inline
def segment(x, y, gs0, trk0, w, acc, t, straight):
    """``kinematics.horizontal_segment`` (with its ``_arc``): position (m), speed (m/s) and track (rad)
    after ``t`` s turning at ``w`` (rad/s) and accelerating at ``acc`` (m/s^2)."""
    th1 = trk0 + w * t
    if abs(w) < straight:
        dist = gs0 * t + 0.5 * acc * t * t
        mid = trk0 + 0.5 * w * t
        dx, dy = dist * math.sin(mid), dist * math.cos(mid)
    else:
        c0, s0, c1, s1, w2 = math.cos(trk0), math.sin(trk0), math.cos(th1), math.sin(th1), w * w
        dx = gs0 * (c0 - c1) / w + acc * (-t * c1 / w + (s1 - s0) / w2)
        dy = gs0 * (s1 - s0) / w + acc * (t * s1 / w + (c1 - c0) / w2)
    return x + dx, y + dy, gs0 + acc * t, trk0 + w * t


@kernel(void(A, A, A, A, A, A, A, F, O, O, O, O), lazy=True)
def segment_into(x, y, gs, trk, w, acc, t, straight, ox, oy, ogs, otrk):
    """``kinematics.horizontal_segment`` element by element."""
    for i in range(ox.shape[0]):
        ox[i], oy[i], ogs[i], otrk[i] = segment(at(x, i), at(y, i), at(gs, i), at(trk, i), at(w, i), at(acc, i),
                                                at(t, i), straight)


@inline
def zero_signed(a):
    """True for -0.0."""
    return a == 0.0 and math.copysign(1.0, a) < 0.0


#: records: a state ``(x, y, z, gs, trk, vs)`` (arrays, each of one element or N), per-element inputs (three
#: arrays), the outputs (six arrays of N)
_STATE, _INPUTS, _OUT = types.UniTuple(A, 6), types.UniTuple(A, 3), types.UniTuple(O, 6)


@kernel(void(_STATE, _INPUTS, F, types.UniTuple(F, 4), F, _OUT, boolean[:]))
def advance_into(state, inputs, dt, limits, straight, out, second):
    """``kinematics.advance``: every element of ``state`` moved by ``dt`` s with its ``inputs`` = ``(turn_rate,
    accel, vertical_accel)`` into ``out``; ``limits`` = ``(max_turn, min_gs, max_gs, max_vs)``. ``second[0]`` is
    set when the speed-limit segment was flown (numpy's batch-wide rule: some element has time left after
    its speed limit, or a zero-length segment would change a bit somewhere)."""
    x, y, z, gs, trk, vs = state
    turn_rate, accel, vertical_accel = inputs
    max_turn, min_gs, max_gs, max_vs = limits
    ox, oy, oz, ogs, otrk, ovs = out
    n = ox.shape[0]
    any_rest, keeps = False, True
    for i in range(n):
        w = clip(at(turn_rate, i), -max_turn, max_turn)
        acc = at(accel, i)
        g = at(gs, i)
        limit = max_gs if acc > 0 else min_gs
        t_sat = (limit - g) / (acc if acc != 0 else 1.0) if acc != 0 else math.inf
        t_sat = clip(t_sat, 0.0, dt)
        xi, yi, gi, ti = segment(at(x, i), at(y, i), g, at(trk, i), w, acc, t_sat, straight)
        ox[i], oy[i], ogs[i], otrk[i] = xi, yi, gi, ti
        rest = dt - t_sat
        ovs[i] = rest  # (kept here until the second pass)
        if rest != 0.0:
            any_rest = True
        if not math.isfinite(gi + ti + w):
            keeps = False
        if zero_signed(xi) or zero_signed(yi) or zero_signed(gi) or zero_signed(ti):
            keeps = False
    second[0] = any_rest or not keeps
    for i in range(n):
        if second[0]:
            w = clip(at(turn_rate, i), -max_turn, max_turn)
            ox[i], oy[i], ogs[i], otrk[i] = segment(ox[i], oy[i], ogs[i], otrk[i], w, 0.0, ovs[i], straight)
        av = at(vertical_accel, i)
        v0 = at(vs, i)
        vs_target = max_vs if av > 0 else (-max_vs if av < 0 else v0)
        tv = (vs_target - v0) / (av if av != 0 else 1.0) if av != 0 else dt
        tv = clip(tv, 0.0, dt)
        vs1 = v0 + av * tv
        oz[i] = at(z, i) + v0 * tv + 0.5 * av * tv * tv + vs1 * (dt - tv)
        ovs[i] = vs1
        otrk[i] = otrk[i] % _TWO_PI


@inline
def toward(g, tr, v, ct, cv, cg, max_turn, h_acc, min_gs, max_gs, max_vs):
    """The maneuver from ground speed ``g``, track ``tr`` and vertical speed ``v`` toward the command
    (``ct``, ``cv``, ``cg``; nan = keep) at the limits, as ``kinematics.fly_command`` (and SM's
    ``_CommandMotion``) set it up: ``(commanded track, target ground speed, target vertical speed, track
    change, turn rate, turn time, speed change, acceleration, speed-change time)``."""
    ct = tr if ct != ct else ct  # Command.resolved
    cv = v if cv != cv else cv
    cg = g if cg != cg else cg
    tgt_gs = clip(cg, min_gs, max_gs)
    tgt_vs = clip(cv, -max_vs, max_vs)
    dpsi = (ct - tr + _PI) % _TWO_PI - _PI
    w = npsign(dpsi) * max_turn
    t_turn = abs(dpsi) / max_turn if max_turn > 0 else 0.0
    dgs = tgt_gs - g
    acc = npsign(dgs) * h_acc
    t_spd = abs(dgs) / h_acc if h_acc > 0 else 0.0
    return ct, tgt_gs, tgt_vs, dpsi, w, t_turn, dgs, acc, t_spd


@kernel(void(_STATE, _INPUTS, F, types.UniTuple(F, 6), F, _OUT))
def fly_command_into(state, cmd, dt, limits, straight, out):
    """``kinematics.fly_command``: every element of ``state`` flown ``dt`` s toward its command ``cmd`` = ``(trk,
    vs, gs)`` (nan = keep) into ``out``; ``limits`` = ``(max_turn, h_acc, v_acc, min_gs, max_gs, max_vs)``."""
    x, y, z, gs, trk, vs = state
    cmd_trk, cmd_vs, cmd_gs = cmd
    max_turn, h_acc, v_acc, min_gs, max_gs, max_vs = limits
    ox, oy, oz, ogs, otrk, ovs = out
    for i in range(ox.shape[0]):
        g, tr, v = at(gs, i), at(trk, i), at(vs, i)
        ct, tgt_gs, tgt_vs, dpsi, w, t_turn, dgs, acc, t_spd = toward(
            g, tr, v, at(cmd_trk, i), at(cmd_vs, i), at(cmd_gs, i), max_turn, h_acc, min_gs, max_gs, max_vs)
        t_turn = npmin(t_turn, dt)
        t_spd = npmin(t_spd, dt)
        b1 = npmin(t_turn, t_spd)
        b2 = npmax(t_turn, t_spd)
        px, py, pg, pt = at(x, i), at(y, i), g, tr
        # the three pieces (0, b1), (b1, b2), (b2, dt)
        px, py, pg, pt = segment(px, py, pg, pt, w if t_turn > 0.0 else 0.0, acc if t_spd > 0.0 else 0.0,
                                 npmax(b1 - 0.0, 0.0), straight)
        px, py, pg, pt = segment(px, py, pg, pt, w if t_turn > b1 else 0.0, acc if t_spd > b1 else 0.0,
                                 npmax(b2 - b1, 0.0), straight)
        px, py, pg, pt = segment(px, py, pg, pt, w if t_turn > b2 else 0.0, acc if t_spd > b2 else 0.0,
                                 npmax(dt - b2, 0.0), straight)
        if abs(dpsi) <= max_turn * dt:
            pt = ct
        if abs(dgs) <= h_acc * dt:
            pg = tgt_gs
        oz[i], ovs[i] = vertical_toward(at(z, i), v, tgt_vs, v_acc, dt)
        ox[i], oy[i], ogs[i], otrk[i] = px, py, pg, pt % _TWO_PI
