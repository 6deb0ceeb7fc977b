"""Shared builders and an independent brute-force oracle for the DAA / agent tests."""

from __future__ import annotations

import numpy as np

from daa_sil.agent.memory import PilotInput
from daa_sil.daa import alert_levels
from daa_sil.geometry import wellclear as wc
from daa_sil.geometry.kinematics import AircraftState, Command, fly_command


def own_state(n=1, x=0.0, y=0.0, z=1000.0, gs=55.0, trk=0.0, vs=0.0) -> AircraftState:
    f = lambda a: np.broadcast_to(np.asarray(a, float), (n,)).copy()  # noqa: E731
    return AircraftState(f(x), f(y), f(z), f(gs), f(trk), f(vs))


def intruders(rows) -> AircraftState:
    """rows: list (N) of lists (M) of (x, y, z, gs, trk_rad, vs)."""
    a = np.asarray(rows, float)
    return AircraftState.from_array(a)


def brute_first_lowc(own: AircraftState, intr: AircraftState, cmd: Command, perf, th, t_end: float,
                     dt: float = 0.05) -> np.ndarray:
    """First sampled time (s) of WCV with any intruder when the ownship flies ``cmd`` (exact kinematics,
    instantaneous velocities), sampled every ``dt`` s over [0, t_end]; inf if none. Shape (N,)."""
    t = np.arange(0.0, t_end + 1e-9, dt)
    path = fly_command(own[:, None], cmd[:, None], dt=np.broadcast_to(t, own.shape + t.shape), perf=perf)
    op, ov = path.position(), path.velocity()  # (N, T, 3)
    ip = intr.position()[:, :, None, :] + t[None, None, :, None] * intr.velocity()[:, :, None, :]
    s = op[:, None] - ip
    v = ov[:, None] - intr.velocity()[:, :, None, :]
    hit = wc.wcv(s, v, th).any(axis=1)  # (N, T)
    first = np.where(hit.any(axis=1), t[np.argmax(hit, axis=1)], np.inf)
    return first


def hold_into_head_on(cfg):
    """A head-on intruder 3 km ahead, co-altitude: the pilot's 'hold' (the course it saw: north) is unsafe
    (checked: the alert level reaches 2 under ``cfg``). Returns ``(own, intruders, PilotInput)``."""
    own = own_state(gs=30.0)
    intr = intruders([[[0.0, 3000.0, 1000.0, 20.0, np.pi, 0.0]]])
    hold = Command(np.array([0.0]), np.array([0.0]), np.array([30.0]))
    pin = PilotInput(np.array([True]), hold, np.array([9.0]), np.array([10.0]), np.array([10.0]))
    assert alert_levels(own, intr, cfg)[0, 0] >= 2
    return own, intr, pin
