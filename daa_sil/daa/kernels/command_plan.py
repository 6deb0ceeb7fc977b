"""SM's command paths planned in one compiled pass: :func:`daa_sil.daa.safety.command_paths` without its
numpy arithmetic per encounter (the maneuver times, the knot spacing and count, the bounds on the path's
acceleration and jerk, and the motion's three phases that ``_CommandMotion`` builds), one element at a
time with the numpy code's operations in its order (``docs/daa.md``, "Compiled kernels").

The numpy code (``safety.command_paths`` with ``safety.COMPILED = False``) is the reference.
"""

from __future__ import annotations

import math

import numpy as np
from numba import boolean, types

from daa_sil.daa.kernels.flight import at, segment, toward
from daa_sil.daa.kernels.jit import kernel
from daa_sil.daa.kernels.plan_layout import ACC_H, ACC_V, H, JERK, KINK_GS, KINK_TRK, N_KNOTS, T_VS
from daa_sil.daa.kernels.scalar import npmax, npmin
from daa_sil.daa.kernels.signatures import A, F, O2

INF = math.inf


@kernel(boolean(types.UniTuple(A, 6), types.UniTuple(A, 3), types.UniTuple(F, 6), types.UniTuple(F, 3),
                types.UniTuple(F, 3), F, F, types.Array(types.float64, 3, "C"), O2, O2))
def command_plan_into(own, cmd, perf, rates, knot, straight, eps, phases, enc, plan):
    """Per encounter ``i``: the motion's phases ``phases[i]`` (3, 9: start time, x, y, gs, trk, turn rate,
    acceleration, sine and cosine of the start track; ``_CommandMotion``), its constants ``enc[i]`` (7:
    track change, commanded track, speed change, target speed, altitude, vertical speed, target vertical
    speed) and ``plan[i]`` (columns: :mod:`daa_sil.daa.kernels.plan_layout`). The first six inputs are the ownship, the next
    three the command (nan = keep), then the performance limits and the configuration's rates and knot
    spacings. Returns True when some phase turns slower than ``straight`` (rad/s) without being straight:
    the numpy motion then treats it as straight, and the caller must use the numpy reference. Records:
    ``own`` = ``(x, y, z, gs, trk, vs)``, ``cmd`` = ``(trk, vs, gs)``, ``perf`` = ``(max_turn, h_acc, v_acc,
    min_gs, max_gs, max_vs)``, ``rates`` = ``(turn_rate, v_acc, h_acc)`` and ``knot`` = ``(trk, vs, gs)`` of the
    configuration."""
    x, y, z, gs, trk, vs = own
    cmd_trk, cmd_vs, cmd_gs = cmd
    max_turn, h_acc, v_acc, min_gs, max_gs, max_vs = perf
    turn_rate, cfg_v_acc, cfg_h_acc = rates
    knot_trk, knot_vs, knot_gs = knot
    exotic = False
    for i in range(phases.shape[0]):
        g, tr, v = at(gs, i), at(trk, i), at(vs, i)
        # _CommandMotion (the performance limits; the command resolved)
        ct, tgt_gs, tgt_vs, dpsi, w, t_turn, dgs, acc, t_spd = toward(
            g, tr, v, at(cmd_trk, i), at(cmd_vs, i), at(cmd_gs, i), max_turn, h_acc, min_gs, max_gs, max_vs)
        # maneuver_times (the configuration's rates; its wrapped track change and clipped targets are the same
        # operations on the same numbers as the motion's)
        t_trk = abs(dpsi) / turn_rate
        t_vs = abs(tgt_vs - v) / cfg_v_acc
        t_gs = abs(tgt_gs - g) / cfg_h_acc
        # the knots: the finest spacing of the axes the command changes
        k_trk = knot_trk if t_trk > eps else INF
        k_vs = knot_vs if t_vs > eps else INF
        k_gs = knot_gs if t_gs > eps else INF
        knots = npmin(npmin(k_trk, k_vs), k_gs)
        t_man = npmax(npmax(t_trk, t_vs), t_gs)
        h = knots if math.isfinite(knots) else 1.0
        plan[i, H] = h
        plan[i, N_KNOTS] = np.ceil(t_man / h - 1e-9) if t_man > eps else 0.0  # (a float, as numpy's)
        gs_max = npmax(g, tgt_gs)
        plan[i, ACC_H] = (gs_max * turn_rate if t_trk > eps else 0.0) + (cfg_h_acc if t_gs > eps else 0.0)
        plan[i, ACC_V] = cfg_v_acc if t_vs > eps else 0.0
        w_k = turn_rate if t_trk > eps else 0.0
        plan[i, JERK] = 2.0 * (cfg_h_acc if t_gs > eps else 0.0) * w_k + gs_max * w_k * w_k
        plan[i, KINK_TRK] = t_trk if t_trk > eps else INF
        plan[i, KINK_GS] = t_gs if t_gs > eps else INF
        plan[i, T_VS] = t_vs
        b1, b2 = npmin(t_turn, t_spd), npmax(t_turn, t_spd)
        px, py, pg, pt = at(x, i), at(y, i), g, tr
        for p in range(3):
            lo = 0.0 if p == 0 else (b1 if p == 1 else b2)
            w_p = w if t_turn > lo else 0.0
            a_p = acc if t_spd > lo else 0.0
            ph = phases[i, p]
            ph[0], ph[1], ph[2], ph[3], ph[4], ph[5], ph[6] = lo, px, py, pg, pt, w_p, a_p
            ph[7], ph[8] = math.sin(pt), math.cos(pt)
            if w_p != 0.0 and abs(w_p) < straight:
                exotic = True
            if p < 2:
                hi = b1 if p == 0 else b2
                px, py, pg, pt = segment(px, py, pg, pt, w_p, a_p, npmax(hi - lo, 0.0), straight)
        e = enc[i]
        e[0], e[1], e[2], e[3], e[4], e[5], e[6] = dpsi, ct, dgs, tgt_gs, at(z, i), v, tgt_vs
    return exotic
