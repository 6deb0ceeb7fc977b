"""Step 1 (the ground station) is one sans-IO object, :class:`daa_sil.models.ground.GroundCore`, that fast-time
and the SIL GCS both run (issue 23): its display changes only for the encounters whose telemetry is
fresh, and both callers step the pilot through it. End-to-end equality of the SIL and fast-time is
tests/test_sil_parity.py's."""

from __future__ import annotations

import numpy as np
import pytest

from daa_sil.daa.config import DaaConfig
from daa_sil.geometry.kinematics import AircraftState
from daa_sil.models.ground import GroundCore
from daa_sil.models.pilot_config import PilotConfig


def _head_on(n: int) -> tuple[AircraftState, AircraftState]:
    """n ownships flying north at 50 m/s and an intruder 3 km ahead flying south (a corrective conflict)."""
    z = np.zeros(n)
    own = AircraftState(z, z, z + 1000.0, z, z + 50.0, z)
    intr = AircraftState(z[:, None], z[:, None] + 3000.0, z[:, None] + 1000.0, z[:, None], z[:, None] - 50.0,
                         z[:, None])
    return own, intr


def _core(n: int) -> GroundCore:
    return GroundCore(n, list(range(n)), PilotConfig(mode="deterministic"), DaaConfig.for_preset("paper"))


def test_only_fresh_encounters_refresh_their_display():
    core = _core(2)
    own, intr = _head_on(2)
    core.step(0.0, own, intr, np.array([0]), np.array([3]))
    g = core.display.guidance()
    assert g.alert_level.tolist() == [3, 0]  # encounter 1's telemetry is not fresh: its display is untouched
    assert np.isfinite(g.left_trk[0]) and np.isfinite(g.right_trk[0])  # bands of the conflict shown for 0
    assert np.isnan(g.left_trk[1]) and np.isnan(g.right_trk[1])
    core.step(1.0, own, intr, np.array([1]), np.array([2]))
    assert core.display.guidance().alert_level.tolist() == [3, 2]


def test_the_guidance_handed_out_is_a_snapshot():
    """The display updates its own arrays row by row; what :meth:`guidance` returned stays as it was, and
    writing into it does not reach the display."""
    core = _core(1)
    own, intr = _head_on(1)
    g0 = core.display.guidance()
    core.step(0.0, own, intr, np.array([0]), np.array([3]))
    assert g0.alert_level.tolist() == [0] and np.isnan(g0.left_trk[0]) and g0.left_level[0] == np.inf
    g1 = core.display.guidance()
    assert g1.alert_level.tolist() == [3] and np.isfinite(g1.left_trk[0])
    g1.alert_level[0], g1.left_trk[0] = 0, 123.0
    g2 = core.display.guidance()
    assert g2.alert_level.tolist() == [3] and g2.left_trk[0] != 123.0
    assert (g2.alert_level.dtype, g2.wcv.dtype, g2.left_level.dtype) == (np.int64, bool, np.float64)


def test_a_step_with_nothing_fresh_keeps_the_display():
    core = _core(1)
    own, intr = _head_on(1)
    core.step(0.0, own, intr, np.array([0]), np.array([3]))
    before = {k: v.copy() for k, v in core.display.bands.items()}
    far = AircraftState(*(np.full(1, 9e4) for _ in range(6)))
    core.step(1.0, far, intr, np.zeros(0, np.int64), np.zeros(0, np.int64))
    for k, v in core.display.bands.items():
        np.testing.assert_array_equal(v, before[k])


def test_fast_time_steps_the_pilot_through_the_ground_core(monkeypatch):
    from daa_sil.config.groups import policy_for_group
    from daa_sil.models.encounters import sample_encounters
    from daa_sil.models.latency import Constant
    from daa_sil.study.simulation.fasttime import simulate

    calls = []
    real = GroundCore.step
    monkeypatch.setattr(GroundCore, "step", lambda self, t, *a: calls.append(t) or real(self, t, *a))
    simulate(sample_encounters(3, seed=5, preset="paper"), policy_for_group("B-1"), Constant(4.0), Constant(4.0),
             duration_s=10.0)
    assert calls == [float(k) for k in range(len(calls))] and len(calls) >= 10


def test_the_gcs_steps_its_pilot_model_through_the_ground_core(monkeypatch):
    from daa_sil.sil.scenario import load_scenario
    from gcs.node import GcsNode, GcsOptions

    calls = []
    real = GroundCore.step
    monkeypatch.setattr(GroundCore, "step", lambda self, t, *a: calls.append((t, a[2].size)) or real(self, t, *a))
    node = GcsNode(load_scenario("scenarios/head_on.yaml"), GcsOptions(clock="lockstep", display=False))
    assert isinstance(node.ground, GroundCore)
    assert node.protocol.pilot.orders(0.0, node.view, node.protocol.order) == []  # no telemetry yet: the pilot
    # steps on an unknown state
    assert calls == [(0.0, 0)]


@pytest.mark.parametrize("n", [1, 3])
def test_the_output_covers_every_encounter(n):
    own, intr = _head_on(n)
    out = _core(n).step(0.0, own, intr, np.arange(n), np.full(n, 3))
    assert out.send.shape == (n,) and out.cmd.trk.shape == (n,)
