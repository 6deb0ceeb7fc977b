"""Remote-pilot model: delay components, deterministic timeline, maneuver rules, RNG streams."""

import numpy as np
import pytest

from daa_sil.geometry.kinematics import AircraftState
from daa_sil.models.pilot import PilotModel
from daa_sil.models.pilot_choice import choose_maneuver, sample_response_components
from daa_sil.models.pilot_config import Guidance, PilotConfig
from daa_sil.geometry.units import DEG, FPM
from daa_sil.errors import UsageError


def _own(n=1, trk=0.0):
    z = np.zeros(n)
    return AircraftState(z, z, z + 1000, z + 55.0, z + trk, z)


def _guid(n=1, alert=2, lt=340, ll=0, rt=25, rl=0, up=2.0, ul=0, dn=-2.0, dl=0):
    f = lambda v: np.full(n, float(v))  # noqa: E731
    return Guidance(alert_level=f(alert), left_trk=f(lt) * DEG, left_level=f(ll), right_trk=f(rt) * DEG,
                    right_level=f(rl), up_vs=f(up), up_level=f(ul), down_vs=f(dn), down_level=f(dl))


def test_delay_components_match_models_md():
    d = sample_response_components(np.random.default_rng(1), 100_000, PilotConfig())
    # Exp(5), Gamma(5.5, 2): mean 11 sd sqrt(22), Exp(3), Rayleigh(3.989): mean sigma*sqrt(pi/2)
    for key, mean, sd in (("init", 5.0, 5.0), ("coord", 11.0, np.sqrt(22.0)), ("exec", 3.0, 3.0),
                          ("rayleigh", 3.989 * np.sqrt(np.pi / 2), 3.989 * np.sqrt((4 - np.pi) / 2))):
        assert abs(d[key].mean() - mean) < 0.03 * mean, key
        assert abs(d[key].std() - sd) < 0.03 * sd, key
    tot = d["init"] + d["coord"] + d["exec"]
    assert abs(tot.mean() - 19.0) < 0.03 * 19.0


def test_deterministic_timeline_and_left_turn_plus_30():
    m = PilotModel(1, cfg=PilotConfig(mode="deterministic"))
    own, g = _own(), _guid()
    none = _guid(alert=0)
    outs = [m.step(float(t), own, none if t < 3 else g) for t in range(0, 40)]
    assert not outs[2].send[0] and outs[3].send[0]
    # hold from t = 3 (alert seen) to 3 + 19 - 1, then min-deviation left (20 deg) + 30 = 310 deg
    for t in range(3, 22):
        assert outs[t].cmd.trk[0] == pytest.approx(0.0) and outs[t].axis[0] == 0
    assert outs[22].cmd.trk[0] == pytest.approx(310 * DEG)
    assert outs[22].axis_names()[0] == "horizontal" and outs[22].direction_names()[0] == "left"
    # corrective follow-up: decide 6 + 3 s after sending (t = 31), sent 3 s later (t = 34)
    assert outs[33].maneuver[0] == 1 and outs[34].maneuver[0] == 2
    assert [o.seq[0] for o in outs[3:6]] == [0, 1, 2]
    # alert clears: streaming stops
    assert not m.step(40.0, own, none).send[0]


def test_deterministic_vertical_when_turns_are_worse():
    m = PilotModel(1, cfg=PilotConfig(mode="deterministic"))
    g = _guid(ll=3, rl=4, ul=0, dl=0, up=2.0, dn=-2.0)  # both turns still in a band; vertical clear
    out = [m.step(float(t), _own(), g) for t in range(20)][-1]
    assert out.axis_names()[0] == "vertical" and out.direction_names()[0] == "up"  # tie: climb
    assert out.cmd.vs[0] == pytest.approx(2.0 + 500 * FPM)


@pytest.mark.parametrize("seed", range(3))
def test_turn_direction_never_reverses_minimum_suggestion(seed):
    rng = np.random.default_rng(seed)
    n = 5000
    cur = rng.uniform(0, 2 * np.pi, n)
    dl, dr = rng.uniform(0, 120, n) * DEG, rng.uniform(0, 120, n) * DEG
    g = Guidance(alert_level=np.full(n, 2), left_trk=cur - dl, left_level=rng.integers(0, 4, n),
                 right_trk=cur + dr, right_level=rng.integers(0, 4, n), up_vs=np.full(n, np.nan),
                 up_level=np.full(n, np.inf), down_vs=np.full(n, np.nan), down_level=np.full(n, np.inf))
    from daa_sil.models.pilot_choice import draw_decisions

    cfg = PilotConfig()
    draws = {k: v for k, v in draw_decisions(rng, cfg, n).items()}
    cmd, axis, direction = choose_maneuver(cur, np.zeros(n), np.full(n, 55.0), g, draws, cfg)
    assert np.all(axis == 1)
    turn = ((cmd.trk - cur + np.pi) % (2 * np.pi)) - np.pi
    left = direction == 1
    assert np.all(turn[left] <= 1e-9) and np.all(turn[~left] >= -1e-9)
    # a better band level always wins the direction
    lv_l, lv_r = np.where(g.left_level <= 1, 0, g.left_level), np.where(g.right_level <= 1, 0, g.right_level)
    assert np.all(left[lv_l < lv_r]) and not np.any(left[lv_r < lv_l])
    # the commanded track is on the 5-degree grid
    deg = np.degrees(cmd.trk)
    assert np.allclose(np.round(deg / 5) * 5, deg, atol=1e-6)


def test_rng_stream_reproducible_per_encounter():
    cfg = PilotConfig(mode="guendel")
    seeds = [np.random.SeedSequence(123, spawn_key=(i,)) for i in range(6)]
    big = PilotModel(6, seeds, cfg)
    small = PilotModel(2, seeds[3:5], cfg)
    assert np.array_equal(big.response_delay_s[3:5], small.response_delay_s)
    own, g = _own(6), _guid(6)
    a = [big.step(float(t), own, g) for t in range(60)]
    b = [small.step(float(t), own[3:5], _guid(2)) for t in range(60)]
    for x, y in zip(a, b):
        assert np.array_equal(x.cmd.trk[3:5], y.cmd.trk, equal_nan=True)
        assert np.array_equal(x.maneuver[3:5], y.maneuver)
    assert len(set(np.round(big.response_delay_s, 6))) == 6


def test_modes_and_errors():
    for mode, mean in (("no_atc", 8.0), ("nasa_rayleigh5", 5.0)):
        m = PilotModel(4000, list(range(4000)), PilotConfig(mode=mode))
        assert abs(m.response_delay_s.mean() - mean) < 0.06 * mean
    assert np.all(PilotModel(3, [1, 2, 3], PilotConfig(mode="fixed")).response_delay_s == 19.0)
    with pytest.raises(UsageError):
        PilotConfig(mode="telepathic").validate()
    with pytest.raises(UsageError):
        PilotModel(2, [1], PilotConfig())


def _state(z, trk_deg, vs=0.0):
    return AircraftState(np.zeros(1), np.zeros(1), np.full(1, float(z)), np.full(1, 55.0),
                         np.full(1, trk_deg * DEG), np.full(1, float(vs)))


def test_return_to_plan_after_a_vertical_maneuver():
    """Deterministic: alert at t = 0, climb (vertical clear, turns worse) sent at t = 19; alert clears
    at t = 30 -> level-off command at once; plan resumed 12 + 12 s later (follow-up at level none)
    at vs = dz / 15 s limited to 500 fpm, and the plan itself once the seen altitude is within 15 m."""
    plan = _state(1000.0, 0.0)
    m = PilotModel(1, cfg=PilotConfig(mode="deterministic"), plan=plan)
    climb = _guid(ll=3, rl=4, ul=0, dl=0, up=2.0, dn=-2.0)
    none = _guid(alert=0)
    outs = {t: m.step(float(t), _state(1000.0, 0.0), climb) for t in range(0, 30)}
    assert outs[19].axis_names()[0] == "vertical" and outs[19].cmd.vs[0] == pytest.approx(2.0 + 500 * FPM)
    seen = _state(1150.0, 20.0, vs=4.5)  # what the GCS sees after the maneuver
    out = m.step(30.0, seen, none)
    assert out.send[0] and out.cmd.vs[0] == 0.0 and out.cmd.trk[0] == pytest.approx(0.0)  # level off
    quiet = [m.step(float(t), seen, none) for t in range(31, 54)]
    assert not any(o.send[0] for o in quiet)  # waiting the follow-up time 12 + 12 s
    out = m.step(54.0, seen, none)
    assert out.send[0] and out.cmd.trk[0] == pytest.approx(0.0) and out.cmd.gs[0] == pytest.approx(55.0)
    assert out.cmd.vs[0] == pytest.approx(-500 * FPM)  # -150 m / 15 s = -10 m/s, limited to 500 fpm
    out = m.step(55.0, _state(1030.0, 0.0), none)
    assert out.cmd.vs[0] == pytest.approx(-30.0 / 15.0)  # proportional inside the limit
    out = m.step(56.0, _state(1010.0, 0.5), none)
    assert out.send[0] and out.cmd.vs[0] == 0.0  # within 15 m and 1 deg: the plan, level
    assert not m.step(57.0, _state(1010.0, 0.5), none).send[0]  # done: nothing more


def test_no_plan_keeps_the_last_command():
    m = PilotModel(1, cfg=PilotConfig(mode="deterministic"))
    climb = _guid(ll=3, rl=4)
    for t in range(0, 30):
        m.step(float(t), _own(), climb)
    assert not m.step(30.0, _own(), _guid(alert=0)).send[0]
    assert not any(m.step(float(t), _own(), _guid(alert=0)).send[0] for t in range(31, 80))


def test_return_waits_until_the_way_back_is_clear():
    """Same timeline as above, but an intruder sits on the plan track 3 km ahead, head-on: turning
    back is a LoWC within the corrective time, so the pilot keeps its course; once the intruder seen
    is behind (diverging), it turns back."""
    from daa_sil.daa import DaaConfig

    plan = _state(1000.0, 0.0)
    m = PilotModel(1, cfg=PilotConfig(mode="deterministic"), plan=plan, daa_cfg=DaaConfig(thresholds="do365"))
    climb = _guid(ll=3, rl=4, ul=0, dl=0, up=2.0, dn=-2.0)
    none = _guid(alert=0)
    for t in range(0, 30):
        m.step(float(t), _state(1000.0, 0.0), climb)
    seen = AircraftState(np.full(1, 2500.0), np.zeros(1), np.full(1, 1000.0), np.full(1, 55.0),
                         np.full(1, 270.0 * DEG), np.zeros(1))  # 2.5 km east of the plan, flying west
    ahead = AircraftState(np.zeros((1, 1)), np.full((1, 1), 3000.0), np.full((1, 1), 1000.0), np.full((1, 1), 60.0),
                          np.full((1, 1), 180.0 * DEG), np.zeros((1, 1)))  # on the plan track, head-on
    behind = AircraftState(np.zeros((1, 1)), np.full((1, 1), -6000.0), np.full((1, 1), 1000.0), np.full((1, 1), 60.0),
                           np.full((1, 1), 180.0 * DEG), np.zeros((1, 1)))  # passed, flying away
    m.step(30.0, seen, none, ahead)  # level-off (already level: nothing to send)
    outs = [m.step(float(t), seen, none, ahead) for t in range(31, 60)]
    assert not any(o.send[0] for o in outs)  # recovery due at 54 s, but the way back is not clear
    out = m.step(60.0, seen, none, behind)
    assert out.send[0] and out.cmd.trk[0] == pytest.approx(0.0) and out.cmd.vs[0] == 0.0


def test_reading_without_hold_commands_sends_only_the_maneuver():
    """stream_hold=False: the same timeline as the default, minus the 19 hold commands before the
    first maneuver (sent at t = 3 + 19 = 22)."""
    m = PilotModel(1, cfg=PilotConfig(mode="deterministic", stream_hold=False))
    own, g, none = _own(), _guid(), _guid(alert=0)
    outs = [m.step(float(t), own, none if t < 3 else g) for t in range(0, 30)]
    assert not any(o.send[0] for o in outs[:22])
    assert outs[22].send[0] and outs[22].cmd.trk[0] == pytest.approx(310 * DEG) and outs[22].seq[0] == 0
    assert all(o.send[0] for o in outs[22:])


def test_reading_streaming_from_first_detection_holds_until_the_corrective_alert():
    """stream_level_min=0: hold of the seen state from the first telemetry; the maneuver still
    follows the corrective alert (t = 3) by the response delay (19 s)."""
    m = PilotModel(1, cfg=PilotConfig(mode="deterministic", stream_level_min=0))
    g, none = _guid(), _guid(alert=0)
    outs = [m.step(float(t), _own(trk=t * 0.01), none if t < 3 else g) for t in range(0, 30)]
    assert all(o.send[0] and o.axis[0] == 0 for o in outs[:22])
    assert outs[1].cmd.trk[0] == pytest.approx(0.01)  # the state seen at that step
    assert outs[22].axis_names()[0] == "horizontal" and outs[22].seq[0] == 22
    with pytest.raises(UsageError, match="stream_level_min"):
        PilotConfig(stream_level_min=3).validate()
