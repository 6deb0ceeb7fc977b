"""The intruder turn-rate estimate that picks the wait map (same object in fast-time and the SIL)."""

import numpy as np
import pytest

from daa_sil.geometry.kinematics import AircraftState
from daa_sil.onboard import TurnRateEstimator


def _intr(trk_deg):
    t = np.radians(np.asarray(trk_deg, float)).reshape(1, -1)
    z = np.zeros_like(t)
    return AircraftState(z, z, z, z + 100.0, t, z)


def test_hand_worked_track_history():
    est = TurnRateEstimator((1, 2))
    # intruder 0 turns right at 3 deg/s from t = 2 s; intruder 1 turns left at 5 deg/s across north
    tracks = [(90, 2), (90, 357), (90, 352), (93, 347), (96, 342), (99, 337)]
    want = [(0, 0), (0, -5), (0, -5), (1.5, -5), (3, -5), (3, -5)]  # window 3: 2 s behind at most
    for k, (trk, exp) in enumerate(zip(tracks, want)):
        got = np.degrees(est.update(float(k), _intr(trk)))[0]
        assert got == pytest.approx(exp, abs=1e-9), (k, got)


def test_window_and_bad_arguments():
    with pytest.raises(ValueError):
        TurnRateEstimator((1, 1), window=1)
    est = TurnRateEstimator((1, 1), window=2)
    est.update(0.0, _intr([10]))
    assert np.degrees(est.update(1.0, _intr([12]))) == pytest.approx(2.0)
    assert np.degrees(est.update(2.0, _intr([12]))) == pytest.approx(0.0)  # only the last two count


def test_every_map_of_the_family_is_read_in_a_campaign_with_turning_intruders():
    """Fast-time over sampled Table 6 encounters (58 % of intruders turn, U(-5, 5) deg/s): the
    decisions read all five conditioning maps."""
    from daa_sil import waitmap
    from daa_sil.models.encounters import sample_encounters
    from daa_sil.study.simulation.fasttime import simulate
    from daa_sil.config.groups import group_spec

    es = sample_encounters(300, seed=2024, preset="paper")
    spec = group_spec("ID-2")
    model = spec.delay_model()
    fam = waitmap.family_for("paper")
    _, dec, _ = simulate(es, spec.policy(), model, model, wait_family=fam, preset="paper", group="ID-2")
    kinds = np.isin(np.asarray(dec.column("decision").to_pylist()), ["wait", "no_wait"])
    maps = np.asarray(dec.column("wait_map_turn_dps").to_numpy(zero_copy_only=False))[kinds]
    counts = {m: int(np.sum(maps == m)) for m in (-5.0, -2.5, 0.0, 2.5, 5.0)}
    assert all(c > 0 for c in counts.values()), counts
    turn = np.asarray(dec.column("wait_turn_dps").to_numpy(zero_copy_only=False))[kinds]
    # the map read is the nearest condition to the estimate (compass sense), ties to the smaller |rate|
    nearest = np.array([-5.0, -2.5, 0.0, 2.5, 5.0])[np.argmin(np.abs(turn[:, None] - [-5, -2.5, 0, 2.5, 5])
                                                        + 1e-9 * np.abs([-5, -2.5, 0, 2.5, 5]), axis=1)]
    np.testing.assert_array_equal(maps, nearest)
