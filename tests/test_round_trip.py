"""The latency rules: a group's value applied one-way on both links, or as the round trip split
evenly between them (the paper: "The round-trip latency duration can be in the range of 0.2 to 10
seconds"), from one draw per epoch on the uplink stream."""

import numpy as np
import pytest

from daa_sil.config.groups import policy_for_group
from daa_sil.errors import UsageError
from daa_sil.models.delay_process import BatchedDelay, DelayProcess, batched_link_delays, link_delay_processes
from daa_sil.models.delay_spec import delay_model_from_dict, parse_delay_spec
from daa_sil.models.latency import Constant, TruncatedGaussian
from daa_sil.models.link_rule import HalfRoundTrip, link_legs
from daa_sil.models.pilot_config import PilotConfig
from daa_sil.sil.scenario import encounter_set, load_scenario
from daa_sil.study.simulation.fasttime import simulate

GAUSS = TruncatedGaussian(5.0, 3.0)


def _steps(legs, seed=11):
    sc = load_scenario("scenarios/head_on.yaml")
    _, _, log = simulate(encounter_set(sc), policy_for_group("B-2"), legs.up, legs.down,
                         PilotConfig(mode="deterministic"), seeds=np.array([seed]), preset="paper",
                         duration_s=sc.duration_s, record_steps=True, link_legs=legs)
    return {k: np.asarray(log.column(k).to_numpy()) for k in ("delay_up_s", "delay_down_s")}


@pytest.mark.parametrize("model", [Constant(4.0), GAUSS], ids=["const 4 s", "gauss 5,3"])
def test_round_trip_split_halves_each_leg_on_a_scripted_encounter(model):
    one = _steps(link_legs(model, "one-way"))
    rt = _steps(link_legs(model, "round-trip"))
    # each leg gets exactly half of what the one-way reading applies to the uplink (the same stream)
    assert np.array_equal(rt["delay_up_s"], 0.5 * one["delay_up_s"])
    assert np.array_equal(rt["delay_down_s"], rt["delay_up_s"])  # both legs: halves of one round trip
    if isinstance(model, Constant):
        assert np.all(rt["delay_up_s"] == 2.0) and np.all(one["delay_down_s"] == 4.0)
    else:  # one-way draws the two links independently; the round trip of an epoch is one draw
        assert not np.array_equal(one["delay_up_s"], one["delay_down_s"])
        rt_sum = rt["delay_up_s"] + rt["delay_down_s"]
        assert 0.2 <= rt_sum.min() and rt_sum.max() <= 10.0
        assert len(np.unique(rt_sum)) > 3  # a new draw per 10 s epoch


def test_legs_processes_and_validation():
    legs = link_legs(GAUSS, "round-trip")
    assert legs.shared and legs.up == legs.down == HalfRoundTrip(GAUSS)
    assert HalfRoundTrip(GAUSS).mean() == pytest.approx(GAUSS.mean() / 2)
    assert delay_model_from_dict(legs.up.to_dict()) == legs.up
    assert link_legs(GAUSS).shared is False and link_legs(GAUSS).up is GAUSS
    with pytest.raises(UsageError, match="one delay"):
        link_legs(GAUSS, "round-trip", down=Constant(4.0))
    with pytest.raises(UsageError, match="latency rule must be one of one-way, round-trip"):
        link_legs(GAUSS, "both")
    # SIL processes and fast-time batches agree draw for draw, and the downlink reads the uplink stream
    p = link_delay_processes(legs, 7, 8, epoch_s=10.0)
    up, down = batched_link_delays(legs, [7], [8], 10.0, 240.0)
    for t in np.arange(0.0, 240.0, 10.0):
        assert p["up"].delay(t) == p["down"].delay(t) == up.delay_at(t)[0] == down.delay_at(t)[0]
        assert p["up"].delay(t) == 0.5 * DelayProcess(GAUSS, 7, epoch_s=10.0).delay(t)
    one = link_delay_processes(link_legs(GAUSS), 7, 8)
    assert one["down"].delay(0.0) == BatchedDelay(GAUSS, [8]).delay_at(0.0)[0] != one["up"].delay(0.0)
    # each leg's validation accepts 0.1-5 s (half of the paper's 0.2-10 s round trip)
    assert parse_delay_spec("const:0.1").mean() == 0.1 and parse_delay_spec("const:5").mean() == 5.0
    half = HalfRoundTrip(TruncatedGaussian(5.0, 3.0)).sample(np.random.default_rng(3), np.zeros(20_000))
    assert 0.1 <= half.min() and half.max() <= 5.0
    with pytest.raises(UsageError, match=r"within \[0.1, 10\]"):
        parse_delay_spec("const:0.05")
