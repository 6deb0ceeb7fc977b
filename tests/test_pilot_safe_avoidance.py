"""The pilot streams "from the beginning of an encounter till safe avoidance" (reading paper): safe
avoidance is no alert on the pilot's display and every intruder past its closest point of approach."""

import numpy as np
import pytest

from daa_sil.errors import UsageError
from daa_sil.geometry.kinematics import AircraftState
from daa_sil.daa.alerting import safe_avoidance
from daa_sil.models.pilot import PilotModel
from daa_sil.models.pilot_config import Guidance, PilotConfig


def _own():
    return AircraftState(np.zeros(1), np.zeros(1), np.full(1, 1000.0), np.full(1, 55.0), np.zeros(1), np.zeros(1))


def _intr(y):
    """One intruder on the ownship's track line at north offset ``y`` (m), flying south at 60 m/s."""
    return AircraftState(*(np.array([[v]]) for v in (0.0, y, 1000.0, 60.0, np.pi, 0.0)))


def _guidance(level):
    """The display: alert ``level``; clear tracks 30 deg either side, clear vertical speeds +-5 m/s."""
    a = lambda v: np.full(1, float(v))  # noqa: E731
    return Guidance(a(level), a(-0.5236), a(0), a(0.5236), a(0), a(5.0), a(0), a(-5.0), a(0))


def test_safe_avoidance_needs_no_alert_and_every_intruder_diverging():
    own = _own()
    assert not safe_avoidance(own, _intr(3000.0), 0)[0]  # approaching
    assert safe_avoidance(own, _intr(-200.0), 0)[0]  # behind, moving away
    assert not safe_avoidance(own, _intr(-200.0), 1)[0]  # still alerted (preventive)
    two = AircraftState(*(np.array([[0.0, 0.0], [-200.0, 4000.0], [1000.0] * 2, [60.0] * 2, [np.pi] * 2, [0.0] * 2])))
    assert not safe_avoidance(own, two, 0)[0]  # one of two still converging
    nan = AircraftState(*(np.full(1, np.nan) for _ in range(6)))
    assert not safe_avoidance(nan, _intr(-200.0), 0)[0] and not safe_avoidance(own, None, 0)[0]


@pytest.mark.parametrize("until, sends_after_pass", [("alert", True), ("safe-avoidance", False)])
def test_detection_stream_stops_at_safe_avoidance(until, sends_after_pass):
    cfg = PilotConfig(mode="deterministic", stream_level_min=0, stream_until=until)
    pilot = PilotModel(1, cfg=cfg)
    sent = []
    for t in range(40):
        y = 1500.0 - 115.0 * t  # passes the ownship's position at t ~ 13 s
        sent.append(bool(pilot.step(float(t), _own(), _guidance(0), _intr(y)).send[0]))
    assert all(sent[:13])  # 'hold' from the first telemetry while the intruder closes
    assert any(sent[14:]) is sends_after_pass
    if until == "safe-avoidance":
        assert pilot.t_safe[0] == 14.0  # the first step seen diverging (y < 0)


def test_an_engaged_pilot_streams_its_command_until_safe_avoidance_and_a_new_alert_restarts_it():
    cfg = PilotConfig(mode="deterministic", stream_level_min=0, stream_until="safe-avoidance", recover=False)
    pilot = PilotModel(1, cfg=cfg)
    own = _own()
    levels = [2] * 25 + [0] * 10  # corrective alert, then clear while still converging
    sent = []
    for t, lvl in enumerate(levels):
        sent.append(bool(pilot.step(float(t), own, _guidance(lvl), _intr(9000.0)).send[0]))
    assert all(sent)  # alerted: streaming; cleared but not past CPA: the command it flies, every step
    out = pilot.step(35.0, own, _guidance(0), _intr(-500.0))
    assert not out.send[0] and pilot.safe[0]  # safe avoidance: the stream ends
    assert pilot.step(36.0, own, _guidance(2), _intr(3000.0)).send[0]  # a new corrective alert restarts it
    assert not pilot.safe[0]


def test_stream_until_is_validated():
    with pytest.raises(UsageError, match="stream_until must be one of alert, safe-avoidance"):
        PilotConfig(stream_until="never").validate()
