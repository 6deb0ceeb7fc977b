"""The penetration integral (PI): how deep and how long a loss of well clear goes, vectorised over any
leading batch shape. Relative states ``s``, ``v`` as in :mod:`daa_sil.geometry.wellclear` (ownship minus
intruder, ENU m and m/s); the LoWC interval a segment's PI integrates over is that module's
:func:`~daa_sil.geometry.wellclear.violation_interval`."""

from __future__ import annotations

import numpy as np

from daa_sil.config.settings import STEP

from .thresholds import Thresholds, get_thresholds
from .units import FT
from .wellclear import hmd, tau_mod, wcv


def _f(a):
    return np.asarray(a, dtype=float)


#: the paper's PI constants (its Eq.): ``(DMOD, vertical, tau_mod)`` = 4000 ft, 450 ft, 35 s, in m, m, s
PAPER_PI_CONSTANTS = (4000.0 * FT, 450.0 * FT, 35.0)
#: midpoint nodes per LoWC segment in :func:`segment_penetration`
PI_NODES = 16


def pi_constants(which: "str | Thresholds | None" = None) -> tuple[float, float, float]:
    """``(DMOD m, vertical m, tau_mod s)`` of the PI: ``"paper-eq"`` = the paper's Eq. (4000 ft, 450 ft,
    35 s, :data:`PAPER_PI_CONSTANTS`), otherwise the DTHR/ZTHR/TTHR of a threshold preset (the
    ``paper`` preset has 1220 m / 122 m / 35 s)."""
    if isinstance(which, str) and which == "paper-eq":
        return PAPER_PI_CONSTANTS
    th = get_thresholds(which)
    return th.dthr, th.zthr, th.tthr


def penetration_depth(s, v, dmod: float, zthr: float, tthr: float) -> np.ndarray:
    """The PI integrand without the LoWC indicator (dimensionless, in [0, 1]):
    ``clip(min(1 - HMD/dmod, 1 - |s_z|/zthr), 0, 1) * clip(1 - tau_mod/tthr, 0, 1)`` with HMD the range
    at CPA (current range when diverging) and tau_mod the DO-365 value for ``dmod`` (0 inside it)."""
    s, v = _f(s), _f(v)
    h = hmd(s, v)
    vm = np.abs(s[..., 2])
    depth = np.clip(np.minimum(1.0 - h / dmod, 1.0 - vm / zthr), 0.0, 1.0)
    if tthr > 0:
        tau = tau_mod(s, v, dmod)
        timing = np.clip(1.0 - np.nan_to_num(tau, nan=np.inf) / tthr, 0.0, 1.0)
    else:
        timing = np.ones_like(depth)
    return depth * timing


def penetration_rate(s, v, th: "Thresholds | str | None" = None) -> np.ndarray:
    """Integrand of the penetration integral at an instant (dimensionless, in [0, 1]); 0 outside a LoWC.

    ``1[WCV] * penetration_depth(s, v, DTHR, ZTHR, TTHR)`` with the preset's thresholds. This is the
    paper's PI integrand ``min((4000-HMD)/4000, (450-VMD)/450) (35-tau_mod)/35`` with its constants
    taken from the selected preset, VMD the current vertical separation ``|s_z|``.
    """
    th = get_thresholds(th)
    s, v = _f(s), _f(v)
    return np.where(wcv(s, v, th), penetration_depth(s, v, th.dthr, th.zthr, th.tthr), 0.0)


def penetration_integral(s, v, dt: float = STEP.default, th: "Thresholds | str | None" = None, axis: int = 0
                         ) -> np.ndarray:
    """PI = sum over samples of ``penetration_rate * dt`` (s), along time ``axis`` of ``s``/``v``.

    Sample-based (a LoWC between two samples contributes nothing); the simulator integrates on the
    continuous segments instead (:func:`segment_penetration`). PI < 2 is conventionally benign, > 10
    significant.
    """
    return np.sum(penetration_rate(s, v, th), axis=axis) * dt


def segment_penetration(s0, v, t_in, t_out, constants: "tuple[float, float, float]",
                        nodes: int = PI_NODES) -> np.ndarray:
    """PI contribution (s) of straight-line relative motion ``s0 + t v`` over its LoWC interval
    ``[t_in, t_out]`` (s, from :func:`violation_interval` on the same segment; empty = ``(inf, -inf)``).

    ``integral over [t_in, t_out] of penetration_depth(s0 + t v, v, *constants) dt`` by the composite
    midpoint rule with ``nodes`` equal sub-intervals of the LoWC interval itself, so a LoWC that
    begins and ends between two samples still contributes, and every node lies strictly inside the
    violation. The integrand is piecewise smooth with kinks (the ``min``, CPA, DMOD crossing) and
    bounded by 1, so the error is second order in ``(t_out - t_in)/nodes`` on the smooth pieces and at
    most ``(t_out - t_in)/nodes`` across a kink. Zero for an empty or zero-length interval (a LoWC
    that only touches the boundary has no duration). ``constants`` = ``(DMOD m, vertical m,
    tau_mod s)``, e.g. :data:`PAPER_PI_CONSTANTS` or :func:`pi_constants` of the preset.
    """
    s0, v = _f(s0), _f(v)
    t_in, t_out = _f(t_in), _f(t_out)
    shape = np.broadcast_shapes(s0.shape[:-1], v.shape[:-1], t_in.shape, t_out.shape)
    ok = (np.isfinite(t_in) & np.isfinite(t_out) & (t_out > t_in))
    if not ok.any():
        return np.zeros(shape)
    ok = np.broadcast_to(ok, shape).reshape(-1)
    out = np.zeros(ok.size)
    s0_i = np.broadcast_to(s0, shape + (3,)).reshape(-1, 3)[ok]
    v_i = np.broadcast_to(v, shape + (3,)).reshape(-1, 3)[ok]
    a = np.broadcast_to(t_in, shape).reshape(-1)[ok]
    length = np.broadcast_to(t_out, shape).reshape(-1)[ok] - a
    frac = (np.arange(nodes) + 0.5) / nodes  # (K,)
    tau = a[:, None] + length[:, None] * frac[None, :]  # (n, K)
    pts = s0_i[:, None, :] + tau[..., None] * v_i[:, None, :]
    dep = penetration_depth(pts, np.broadcast_to(v_i[:, None, :], pts.shape), *constants)
    out[ok] = dep.mean(axis=1) * length
    out = out.reshape(shape)
    return out
