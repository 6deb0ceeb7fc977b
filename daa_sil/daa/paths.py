"""The data of conflict detection along maneuver paths (:mod:`daa_sil.daa.trajectory`): the paths
(:class:`ManeuverPaths`, each encounter's with its own knots) and their violation intervals
(:class:`PathConflicts`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from daa_sil.daa import kernels


#: ``state_at(n, p) -> f`` with ``f(t) -> (x, y, z, vx, vy, vz)``: the true ownship state on path ``p[i]`` of
#: encounter ``n[i]`` at time ``t[i]`` (the per-path parameters are gathered once, then ``f`` is cheap)
StateAt = Callable[[np.ndarray, np.ndarray], Callable[[np.ndarray], tuple]]


# --------------------------------------------------------------------------------------------------
# maneuver paths
# --------------------------------------------------------------------------------------------------
@dataclass
class ManeuverPaths:
    """P maneuver paths per encounter sampled at knots, and the exact ownship state at any time.

    ``pos``/``vel`` ownship position / velocity at the knots as three component arrays (x, y, z) each
    broadcastable to ``(N, P, K)``; ``t`` knot times broadcastable to ``(N, P, K)`` (s); ``state_at(n, p)`` a function of time giving the true ownship position and
    velocity (six component arrays) on paths ``p`` of encounters ``n`` (flat index arrays, :data:`StateAt`); ``acc_h``/``acc_v`` ``(N, P)`` bounds
    on the ownship's horizontal / vertical acceleration along the path, m/s^2 (the chord of a piece of
    duration h is then within ``acc h^2 / 8`` of the path and its velocity within ``acc_h h / 2``);
    ``vz_const``: the vertical speed is the same all along every path (turns and speed changes), or ``(N,)``
    per encounter;
    ``jerk_h``/``kink_t`` bound how far the velocity between two instants is from the line between its
    true values there (``jerk h^2 / 8``, or ``acc_h h / 2`` across a kink), used to exclude clips.
    ``pos``/``vel`` None: computed from ``kin`` (a band axis's) when first asked for (:meth:`knot_states`; the
    evaluator computes the relative states at the knots from ``kin`` directly). ``n_seg`` ``(N,)``: encounter
    ``n``'s paths end at knot ``n_seg[n]`` (the knots past it are not part of them: their segments are clear,
    their tails none, and a "last" tail is the one from knot ``n_seg[n]``); None: every path has all K knots.
    So an encounter's paths are those of a call of its own, whatever the other encounters' knot counts.
    """

    pos: "tuple | None"
    vel: "tuple | None"
    t: np.ndarray
    state_at: StateAt
    acc_h: np.ndarray
    acc_v: np.ndarray
    vz_const: bool = False
    jerk_h: "np.ndarray | None" = None  #: (N, P) bound on |d^2 v / dt^2| (m/s^3) away from kinks (None = unknown)
    kink_t: "np.ndarray | None" = None  #: (N, P) or (N, P, Q) s, times the horizontal acceleration jumps (inf = never)
    #: the paths' motion as data for the compiled kernels, which then evaluate ``state_at`` themselves
    #: (None: they call it): ``("axis", axis code, rate, (N, P, 9) rows of KIN_FIELDS)`` for a band axis's
    #: maneuvers, ``("command", (N, 3, 9) PHASE_FIELDS, (N, 7) ENC_FIELDS, max turn rate, horizontal and
    #: vertical acceleration)`` for a command (:mod:`daa_sil.daa.kernels.motion`)
    kin: "tuple | None" = None
    n_seg: "np.ndarray | None" = None
    _shape: "tuple | None" = field(default=None, init=False, repr=False, compare=False)

    @property
    def shape(self) -> tuple[int, int, int]:
        """``(N, P, K)``; computed once (the knot states made later from ``kin`` have this shape)."""
        if self._shape is None:
            knots = () if self.pos is None else self.pos + self.vel
            self._shape = np.broadcast_shapes(*(np.shape(a) for a in knots), np.shape(self.t),
                                              np.shape(self.acc_h) + (1,))
        return self._shape

    def knot_states(self) -> tuple[tuple, tuple]:
        """``(pos, vel)``, computed from ``kin`` (:func:`daa_sil.daa.kernels.motion.axis_knots_into`) the first
        time when they were left to it."""
        if self.pos is None:
            out = np.empty((6,) + self.shape)
            kernels.get().axis_knots_into(self.kin[1], self.kin[2], self.kin[3], self.axis_times(), out)
            self.pos, self.vel = tuple(out[:3]), tuple(out[3:])
        return self.pos, self.vel

    def axis_times(self) -> np.ndarray:
        """The knot times (K,) s, the same on every path (a band axis's paths)."""
        return np.asarray(self.t, float).reshape(-1)

    def stacked(self) -> tuple[np.ndarray, np.ndarray]:
        """Position and velocity at the knots as ``(N, P, K, 3)`` arrays."""
        shape = self.shape
        return tuple(np.stack([np.broadcast_to(a, shape) for a in c], axis=-1) for c in self.knot_states())

    def knot_times(self) -> np.ndarray:
        return np.broadcast_to(np.asarray(self.t, float), self.shape)

    def subset(self, idx: np.ndarray) -> "ManeuverPaths":
        """The paths of encounters ``idx`` (state_at keeps addressing the original encounters)."""
        idx = np.asarray(idx)
        base = self.state_at
        sub = lambda a: None if a is None else a[idx]  # noqa: E731
        vz = self.vz_const if np.ndim(self.vz_const) == 0 else np.asarray(self.vz_const)[idx]
        if self.pos is None and self.kin is not None and self.kin[0] == "axis":  # (knot states made from kin)
            return ManeuverPaths(None, None, self.t, lambda n, p: base(idx[n], p), self.acc_h[idx], self.acc_v[idx], vz,
                                 sub(self.jerk_h), sub(self.kink_t), _kin_subset(self.kin, idx), sub(self.n_seg))
        pos, vel = self.knot_states()
        return ManeuverPaths(tuple(a[idx] for a in pos), tuple(a[idx] for a in vel), self.knot_times()[idx],
                             lambda n, p: base(idx[n], p),
                             self.acc_h[idx], self.acc_v[idx], vz, sub(self.jerk_h), sub(self.kink_t),
                             _kin_subset(self.kin, idx), sub(self.n_seg))

    def truncated(self, knots: int, vz_const: bool) -> "ManeuverPaths":
        """The same paths with their first ``knots`` knots only (every encounter's; ``n_seg`` dropped) and one
        ``vz_const`` for all."""
        pos, vel = self.knot_states()
        cut = lambda a: np.broadcast_to(a, self.shape)[..., :knots]  # noqa: E731
        return ManeuverPaths(tuple(cut(a) for a in pos), tuple(cut(a) for a in vel), self.knot_times()[..., :knots],
                             self.state_at, self.acc_h, self.acc_v, vz_const, self.jerk_h, self.kink_t, self.kin)

    def vz_const_any(self) -> bool:
        """Whether some path keeps its vertical speed (so vertical windows are computed)."""
        return bool(np.any(self.vz_const))


def _kin_subset(kin: "tuple | None", idx: np.ndarray) -> "tuple | None":
    """:attr:`ManeuverPaths.kin` of encounters ``idx``."""
    if kin is None:
        return None
    if kin[0] == "axis":
        return kin[:3] + (kin[3][idx],)
    return (kin[0], kin[1][idx], kin[2][idx]) + kin[3:]


@dataclass
class PathConflicts:
    """Violation intervals (absolute s) of P paths against M intruders, ``t_end`` the horizon.

    ``seg_in``/``seg_out`` ``(N, M, P, K-1)``: first entry and last exit on the true maneuver between
    knots j and j+1; ``tail_in``/``tail_out`` ``(N, M, P, K)``: the straight tail from knot k over
    ``[t_k, t_end]``; ``t`` ``(N, 1, P, K)`` knot times.
    """

    seg_in: np.ndarray
    seg_out: np.ndarray
    tail_in: np.ndarray
    tail_out: np.ndarray
    t: np.ndarray
    t_end: float

    def prefix(self) -> tuple[np.ndarray, np.ndarray]:
        """First entry / last exit on the maneuver up to knot k, ``(N, M, P, K)`` (k = 0: none)."""
        shape = self.tail_in.shape
        if shape[-1] > 1:
            pre_in = np.minimum.accumulate(self.seg_in, axis=-1)
            pre_out = np.maximum.accumulate(self.seg_out, axis=-1)
            edge = np.full(shape[:-1] + (1,), np.inf)
            return np.concatenate([edge, pre_in], axis=-1), np.concatenate([-edge, pre_out], axis=-1)
        return np.full(shape, np.inf), np.full(shape, -np.inf)

    def prefix_in(self) -> np.ndarray:
        """The first entries of :meth:`prefix` alone (the same numbers, without the last exits)."""
        shape = self.tail_in.shape
        out = np.empty(shape)
        out[..., 0] = np.inf
        if shape[-1] > 1:
            np.minimum.accumulate(self.seg_in, axis=-1, out=out[..., 1:])
        return out

    def candidates(self) -> tuple[np.ndarray, np.ndarray]:
        """First violation and last exit of candidate k (maneuver to knot k, then straight) over
        ``[0, t_end]``, ``(N, M, P, K)``; no violation is ``(inf, -inf)`` (compiled)."""
        shape = self.tail_in.shape
        t_in, t_out = np.empty(shape), np.empty(shape)
        flat = lambda a: np.ascontiguousarray(a).reshape(-1)  # noqa: E731
        kernels.get().candidates_into(flat(self.tail_in), flat(self.tail_out), flat(self.seg_in), flat(self.seg_out),
                                      shape[-1], float(self.t_end), t_in.reshape(-1), t_out.reshape(-1))
        return t_in, t_out

    def candidates_reference(self) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`candidates` in numpy (the kernel's test oracle)."""
        t_in, t_out = self.tail_in.copy(), self.tail_out.copy()
        if t_in.shape[-1] > 1:  # min / max with the prefix (k = 0 has none)
            np.minimum(t_in[..., 1:], np.minimum.accumulate(self.seg_in, axis=-1), out=t_in[..., 1:])
            np.maximum(t_out[..., 1:], np.maximum.accumulate(self.seg_out, axis=-1), out=t_out[..., 1:])
        none = ~(t_in <= self.t_end)
        t_in[none] = np.inf
        np.minimum(t_out, self.t_end, out=t_out)
        t_out[none] = -np.inf
        return t_in, t_out


__all__ = ["ManeuverPaths", "PathConflicts", "StateAt"]
