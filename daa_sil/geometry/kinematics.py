"""Batched point-mass aircraft kinematics (ENU, SI), exact for constant-rate turns.

An :class:`AircraftState` holds arrays of any common shape (e.g. ``(N,)`` ownships or ``(N, M)``
intruders): position ``x, y, z`` (m), ground speed ``gs`` (m/s), compass track ``trk`` (rad,
clockwise from north) and vertical speed ``vs`` (m/s, up).

Two ways to move aircraft by ``dt``:

* :func:`advance` -- constant turn rate (rad/s, compass sense: + = right), along-track
  acceleration (m/s^2) and vertical acceleration (m/s^2) over the step. Position is integrated in
  closed form (arc with linearly varying speed), so a constant-rate turn is exact for any ``dt``.
  Speed and vertical speed saturate at the :class:`Performance` limits inside the step (the step
  is split at the saturation time).
* :func:`fly_command` -- fly toward a :class:`Command` (target track, vertical speed, ground
  speed) with the performance limits: turn the short way at the maximum turn rate until the target
  track is reached, then straight; likewise for speed and vertical speed. Exact piecewise.

Both (and :func:`horizontal_segment`) run as compiled kernels (:mod:`daa_sil.daa.kernels.flight`, the same
numbers) in a process that has loaded the DAA's kernels, and as the numpy functions ``*_reference`` (their
test oracles) in one that has not: moving aircraft never starts numba itself (:mod:`daa_sil.runtime.compiled`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from daa_sil.config.settings import STEP
from daa_sil.runtime.compiled import loaded_kernels
from .frames import TWO_PI, track_from_velocity, wrap_2pi, wrap_pi
from .units import DEG, FPM, G0, KT

#: |turn rate| (rad/s) below which a path is flown as a straight line (the closed-form arc divides by it)
STRAIGHT_TURN_RATE = 1e-6


@dataclass
class AircraftState:
    """Batched aircraft state (all arrays share one shape)."""

    x: np.ndarray
    y: np.ndarray
    z: np.ndarray
    gs: np.ndarray
    trk: np.ndarray
    vs: np.ndarray

    def __post_init__(self):
        d = self.__dict__
        vals = [d[name] for name in _STATE_FIELDS]
        if not _same_float_arrays(vals):
            vals = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in vals))
        for name, a in zip(_STATE_FIELDS, vals):
            d[name] = np.array(a, dtype=float)

    @property
    def shape(self) -> tuple:
        return self.x.shape

    def position(self) -> np.ndarray:
        """ENU position ``(..., 3)``, m."""
        out = np.empty(self.x.shape + (3,))
        out[..., 0], out[..., 1], out[..., 2] = self.x, self.y, self.z
        return out

    def velocity(self) -> np.ndarray:
        """ENU velocity ``(..., 3)``, m/s."""
        out = np.empty(self.x.shape + (3,))
        out[..., 0], out[..., 1], out[..., 2] = self.gs * np.sin(self.trk), self.gs * np.cos(self.trk), self.vs
        return out

    @classmethod
    def from_pos_vel(cls, pos, vel) -> "AircraftState":
        """Build from ENU position and velocity arrays ``(..., 3)``."""
        pos, vel = np.asarray(pos, float), np.asarray(vel, float)
        return cls(pos[..., 0], pos[..., 1], pos[..., 2], np.hypot(vel[..., 0], vel[..., 1]),
                   track_from_velocity(vel[..., 0], vel[..., 1]), vel[..., 2])

    def copy(self) -> "AircraftState":
        return AircraftState(*(getattr(self, name).copy() for name in _STATE_FIELDS))

    @classmethod
    def adopt(cls, *parts: np.ndarray) -> "AircraftState":
        """A state made of six new float64 arrays of one shape (x, y, z, gs, trk, vs), taken as they are:
        no copy (the caller gives them up)."""
        out = object.__new__(cls)
        out.__dict__.update(zip(_STATE_FIELDS, parts))
        return out

    def __getitem__(self, idx) -> "AircraftState":
        parts = [getattr(self, name)[idx] for name in _STATE_FIELDS]
        if isinstance(idx, list) or (isinstance(idx, np.ndarray) and idx.ndim >= 1):
            # advanced indexing already returned six new float arrays of one shape: no second copy
            return AircraftState.adopt(*parts)
        return AircraftState(*parts)  # basic indexing gives views: copy them (no aliasing of the parent)

    def where(self, mask, other: "AircraftState") -> "AircraftState":
        """Element-wise choose ``self`` where ``mask`` else ``other``."""
        return AircraftState(*(np.where(mask, getattr(self, name), getattr(other, name)) for name in _STATE_FIELDS))

    def as_array(self) -> np.ndarray:
        """Stacked ``(..., 6)`` array (x, y, z, gs, trk, vs)."""
        return np.stack([getattr(self, name) for name in _STATE_FIELDS], axis=-1)

    @classmethod
    def from_array(cls, a) -> "AircraftState":
        a = np.asarray(a, float)
        return cls(*(a[..., k] for k in range(6)))


_STATE_FIELDS = ("x", "y", "z", "gs", "trk", "vs")


def _same_float_arrays(vals: list) -> bool:
    """True if every value is a float64 ndarray of one shape: ``np.broadcast_arrays`` would return them
    unchanged, so the constructors copy them directly (the same arrays, without its per-call cost)."""
    shape = None
    for v in vals:
        if type(v) is not np.ndarray or v.dtype != np.float64:
            return False
        if shape is None:
            shape = v.shape
        elif v.shape != shape:
            return False
    return True


@dataclass(frozen=True)
class Performance:
    """Ownship (or intruder) performance limits, SI. Defaults follow DAIDALUS DO-365B kinematics."""

    max_turn_rate: float = 3.0 * DEG  #: rad/s
    horizontal_accel: float = 2.0  #: m/s^2
    vertical_accel: float = 0.25 * G0  #: m/s^2
    max_vs: float = 6000.0 * FPM  #: m/s, symmetric climb/descent limit
    min_gs: float = 10.0 * KT  #: m/s
    max_gs: float = 700.0 * KT  #: m/s


DEFAULT_PERFORMANCE = Performance()

#: physical bounds of an aircraft state (component, lo, hi, unit; ENU m and m/s): a value outside is an
#: error (a typo, a corrupt or hostile message), never an aircraft. Used by ``daa-sil geometry`` and by
#: the GCS for the telemetry it takes in.
STATE_BOUNDS = (("x", -1e7, 1e7, "m"), ("y", -1e7, 1e7, "m"), ("z", -1e4, 1e5, "m"),
                ("vx", -1000.0, 1000.0, "m/s"), ("vy", -1000.0, 1000.0, "m/s"), ("vz", -500.0, 500.0, "m/s"))


def state_in_bounds(x: float, y: float, z: float, vx: float, vy: float, vz: float) -> bool:
    """True if the ENU state (m, m/s) is finite and within :data:`STATE_BOUNDS` (NaN is outside)."""
    return all(lo <= v <= hi for v, (_, lo, hi, _) in zip((x, y, z, vx, vy, vz), STATE_BOUNDS))


@dataclass
class Command:
    """A maneuver command: target compass track (rad), vertical speed (m/s), ground speed (m/s).

    ``nan`` in a field means "keep the current value". Arrays of any common shape.
    """

    trk: np.ndarray = field(default_factory=lambda: np.array(np.nan))
    vs: np.ndarray = field(default_factory=lambda: np.array(np.nan))
    gs: np.ndarray = field(default_factory=lambda: np.array(np.nan))

    def __post_init__(self):
        vals = [self.trk, self.vs, self.gs]
        if not _same_float_arrays(vals):
            vals = np.broadcast_arrays(*(np.asarray(v, float) for v in vals))
        self.trk, self.vs, self.gs = (np.array(a) for a in vals)

    @property
    def shape(self) -> tuple:
        return self.trk.shape

    @classmethod
    def hold(cls, state: AircraftState) -> "Command":
        """The command that keeps the current track, vertical speed and ground speed."""
        return cls(state.trk.copy(), state.vs.copy(), state.gs.copy())

    def resolved(self, state: AircraftState) -> "Command":
        """Replace nan fields by the state's current values."""
        return Command(np.where(np.isnan(self.trk), state.trk, self.trk),
                       np.where(np.isnan(self.vs), state.vs, self.vs),
                       np.where(np.isnan(self.gs), state.gs, self.gs))

    def where(self, mask, other: "Command") -> "Command":
        return Command(np.where(mask, self.trk, other.trk), np.where(mask, self.vs, other.vs),
                       np.where(mask, self.gs, other.gs))

    def __getitem__(self, idx) -> "Command":
        return Command(self.trk[idx], self.vs[idx], self.gs[idx])

    def copy(self) -> "Command":
        return Command(self.trk.copy(), self.vs.copy(), self.gs.copy())


def _arc(gs0, acc, trk0, w, t):
    """Displacement (dx, dy) after time t with speed gs0 + acc*t and compass track trk0 + w*t."""
    small = np.abs(w) < STRAIGHT_TURN_RATE
    ws = np.where(small, 1.0, w)
    th1 = trk0 + w * t
    # each sine, cosine and power once (the same numbers as writing them where they are used)
    c0, s0, c1, s1, ws2 = np.cos(trk0), np.sin(trk0), np.cos(th1), np.sin(th1), ws ** 2
    # x: int (gs0 + a t) sin(trk0 + w t) dt ; y: int (gs0 + a t) cos(trk0 + w t) dt
    dx_turn = gs0 * (c0 - c1) / ws + acc * (-t * c1 / ws + (s1 - s0) / ws2)
    dy_turn = gs0 * (s1 - s0) / ws + acc * (t * s1 / ws + (c1 - c0) / ws2)
    dist = gs0 * t + 0.5 * acc * t * t
    mid = trk0 + 0.5 * w * t
    return np.where(small, dist * np.sin(mid), dx_turn), np.where(small, dist * np.cos(mid), dy_turn)


def horizontal_segment(x, y, gs, trk, w, acc, t):
    """Position ``x, y`` (m), ground speed (m/s) and track (rad) after ``t`` s at turn rate ``w``
    (rad/s, + = right) and along-track acceleration ``acc`` (m/s^2); exact (closed-form arc)."""
    k = loaded_kernels()
    if k is not None:
        shape = next((np.shape(v) for v in (x, y, gs, trk, w, acc, t) if np.ndim(v)), ())
        flat = flat_inputs(shape, (x, y, gs, trk, w, acc, t)) if shape else None  # (0-d: numpy scalars out)
        if flat is not None:
            out = _outputs(math.prod(shape), 4)
            k.segment_into(*flat, STRAIGHT_TURN_RATE, *out)
            return tuple(a.reshape(shape) for a in out)
    return horizontal_segment_reference(x, y, gs, trk, w, acc, t)


def horizontal_segment_reference(x, y, gs, trk, w, acc, t):
    """:func:`horizontal_segment` in numpy (the compiled kernel's reference)."""
    dx, dy = _arc(gs, acc, trk, w, t)
    return x + dx, y + dy, gs + acc * t, trk + w * t


def _zero_length_keeps(x, y, gs, trk, w) -> bool:
    """True when :func:`horizontal_segment` of length 0 (acceleration 0) would return ``x, y, gs, trk``
    exactly: ``gs, trk, w`` finite, so the arc and ``w * 0`` are signed zeros, and no ``x, y, gs, trk`` is
    -0.0, the one value to which adding +0.0 is not the identity. (:func:`advance` then skips its second
    segment, whose arc took a quarter of sampling an encounter set.)"""
    with np.errstate(invalid="ignore", over="ignore"):
        if not np.isfinite(gs + trk + w).all():  # inf - inf is nan: "not finite" too
            return False
    for a in (x, y, gs, trk):
        zero = a == 0
        if zero.any() and np.signbit(a[zero]).any():
            return False
    return True


def vertical_toward(z, vs, target_vs, v_accel, dt):
    """Altitude (m) and vertical speed (m/s) after ``dt`` s moving toward ``target_vs`` (m/s) with
    |acceleration| = ``v_accel`` (m/s^2); exact."""
    dv = target_vs - vs
    t1 = np.minimum(np.abs(dv) / v_accel, dt) if v_accel > 0 else np.where(dv == 0, 0.0, dt)
    a = np.sign(dv) * v_accel
    vs1 = vs + a * t1
    z_new = z + vs * t1 + 0.5 * a * t1 * t1 + vs1 * (dt - t1)
    return z_new, np.where(np.abs(dv) <= v_accel * dt, target_vs, vs1)


def flat_inputs(shape: tuple, values) -> "list[np.ndarray] | None":
    """Each value as a 1-d float64 array of the batch's elements (or of its one element, a scalar numpy
    would broadcast), or None when one broadcasts otherwise (then the numpy reference runs)."""
    out = []
    for v in values:
        a = v if type(v) is np.ndarray and v.dtype == np.float64 else np.asarray(v, dtype=float)
        if a.shape == shape:
            out.append(a.reshape(-1))
        elif a.ndim == 0:
            out.append(a.reshape(1))
        else:
            return None
    return out


def _outputs(n: int, k: int = 6) -> tuple[np.ndarray, ...]:
    """``k`` new float64 arrays of ``n`` elements (a compiled kernel's outputs)."""
    return tuple(np.empty(n) for _ in range(k))


def _moved_compiled(kernel: str, state: AircraftState, inputs: tuple, dt, limits: tuple, *extra) -> "AircraftState | None":
    """``state`` moved by the compiled ``kernel`` (``advance_into`` / ``fly_command_into``: the state, the
    per-element ``inputs``, ``dt``, the performance ``limits``, the straight-line turn rate, six outputs,
    then ``extra``), or None where the numpy reference must run (kernels not loaded, an array ``dt``, or
    inputs that broadcast otherwise)."""
    k = loaded_kernels()
    if k is None or not isinstance(dt, (float, int)):
        return None
    s = state
    flat = flat_inputs(s.shape, (s.x, s.y, s.z, s.gs, s.trk, s.vs, *inputs))
    if flat is None:
        return None
    out = _outputs(s.x.size)
    getattr(k, kernel)(tuple(flat[:6]), tuple(flat[6:9]), float(dt), tuple(map(float, limits)), STRAIGHT_TURN_RATE,
                       out, *extra)
    return AircraftState.adopt(*(a.reshape(s.shape) for a in out))


def advance(state: AircraftState, turn_rate=0.0, accel=0.0, vertical_accel=0.0, dt: float = STEP.default,
            perf: Performance = DEFAULT_PERFORMANCE) -> AircraftState:
    """Move aircraft by ``dt`` s with constant turn rate (rad/s, + = right), along-track acceleration
    and vertical acceleration (m/s^2). Turn rate is clipped to ``perf.max_turn_rate``; speed and
    vertical speed saturate at the limits inside the step (the step is split there).
    """
    moved = _moved_compiled("advance_into", state, (turn_rate, accel, vertical_accel), dt,
                            (perf.max_turn_rate, perf.min_gs, perf.max_gs, perf.max_vs), np.zeros(1, bool))
    return moved if moved is not None else advance_reference(state, turn_rate, accel, vertical_accel, dt, perf)


def advance_reference(state: AircraftState, turn_rate=0.0, accel=0.0, vertical_accel=0.0, dt: float = STEP.default,
                      perf: Performance = DEFAULT_PERFORMANCE) -> AircraftState:
    """:func:`advance` in numpy (the compiled kernel's reference)."""
    s = state
    w = np.clip(np.asarray(turn_rate, float), -perf.max_turn_rate, perf.max_turn_rate)
    acc = np.asarray(accel, float)
    acc = np.broadcast_to(acc, s.shape) if acc.ndim == 0 else acc
    # speed saturation time within the step
    limit = np.where(acc > 0, perf.max_gs, perf.min_gs)
    with np.errstate(all="ignore"):
        t_sat = np.where(acc != 0, (limit - s.gs) / np.where(acc != 0, acc, 1.0), np.inf)
    t_sat = np.clip(t_sat, 0.0, dt)
    x, y, gs, trk = horizontal_segment_reference(s.x, s.y, s.gs, s.trk, w, acc, t_sat)
    rest = dt - t_sat
    if np.any(rest) or not _zero_length_keeps(x, y, gs, trk, w):  # (no speed limit reached: nothing left)
        x, y, gs, trk = horizontal_segment_reference(x, y, gs, trk, w, 0.0, rest)
    # vertical: constant acceleration toward the limit
    av = np.asarray(vertical_accel, float)
    vs_target = np.where(av > 0, perf.max_vs, np.where(av < 0, -perf.max_vs, s.vs))
    with np.errstate(all="ignore"):
        tv = np.where(av != 0, (vs_target - s.vs) / np.where(av != 0, av, 1.0), dt)
    tv = np.clip(tv, 0.0, dt)
    vs1 = s.vs + av * tv
    z = s.z + s.vs * tv + 0.5 * av * tv * tv + vs1 * (dt - tv)
    return AircraftState(x, y, z, gs, wrap_2pi(trk), vs1)


def fly_command(state: AircraftState, cmd: Command, dt: float = STEP.default,
                perf: Performance = DEFAULT_PERFORMANCE) -> AircraftState:
    """Fly ``dt`` s toward ``cmd`` at the performance limits (exact piecewise motion).

    Track: shortest direction at ``max_turn_rate`` until the target is reached, then straight.
    Ground speed: ``horizontal_accel`` toward the target (clipped to [min_gs, max_gs]).
    Vertical speed: ``vertical_accel`` toward the target (clipped to +-max_vs).
    """
    moved = _moved_compiled("fly_command_into", state, (cmd.trk, cmd.vs, cmd.gs), dt,
                            (perf.max_turn_rate, perf.horizontal_accel, perf.vertical_accel, perf.min_gs,
                             perf.max_gs, perf.max_vs))
    return moved if moved is not None else fly_command_reference(state, cmd, dt, perf)


def fly_command_reference(state: AircraftState, cmd: Command, dt: float = STEP.default,
                          perf: Performance = DEFAULT_PERFORMANCE) -> AircraftState:
    """:func:`fly_command` in numpy (the compiled kernel's reference)."""
    s = state
    c = cmd.resolved(s)
    tgt_gs = np.clip(c.gs, perf.min_gs, perf.max_gs)
    tgt_vs = np.clip(c.vs, -perf.max_vs, perf.max_vs)
    dpsi = wrap_pi(c.trk - s.trk)
    w = np.sign(dpsi) * perf.max_turn_rate
    t_turn = np.abs(dpsi) / perf.max_turn_rate if perf.max_turn_rate > 0 else np.zeros_like(dpsi)
    dgs = tgt_gs - s.gs
    acc = np.sign(dgs) * perf.horizontal_accel
    t_spd = np.abs(dgs) / perf.horizontal_accel if perf.horizontal_accel > 0 else np.zeros_like(dgs)
    t_turn = np.minimum(t_turn, dt)
    t_spd = np.minimum(t_spd, dt)
    b1 = np.minimum(t_turn, t_spd)
    b2 = np.maximum(t_turn, t_spd)
    x, y, gs, trk = s.x, s.y, s.gs, s.trk
    for lo, hi in ((0.0, b1), (b1, b2), (b2, dt)):
        seg = np.maximum(hi - lo, 0.0)
        w_seg = np.where(t_turn > lo, w, 0.0)
        a_seg = np.where(t_spd > lo, acc, 0.0)
        x, y, gs, trk = horizontal_segment_reference(x, y, gs, trk, w_seg, a_seg, seg)
    reached_trk = np.abs(dpsi) <= perf.max_turn_rate * dt
    reached_gs = np.abs(dgs) <= perf.horizontal_accel * dt
    trk = np.where(reached_trk, c.trk, trk)
    gs = np.where(reached_gs, tgt_gs, gs)
    z, vs = vertical_toward(s.z, s.vs, tgt_vs, perf.vertical_accel, dt)
    return AircraftState(x, y, z, gs, wrap_2pi(trk), vs)


def turn_direction(from_trk, to_trk) -> np.ndarray:
    """+1 if the short way from ``from_trk`` to ``to_trk`` is a right turn, -1 left, 0 none."""
    return np.sign(wrap_pi(np.asarray(to_trk, float) - np.asarray(from_trk, float)))


__all__ = ["AircraftState", "Performance", "DEFAULT_PERFORMANCE", "Command", "advance", "fly_command",
           "advance_reference", "fly_command_reference", "horizontal_segment_reference",
           "turn_direction", "TWO_PI",
           "horizontal_segment", "vertical_toward", "STRAIGHT_TURN_RATE", "flat_inputs"]
