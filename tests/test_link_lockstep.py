"""The tick protocol's two ends (:class:`daa_sil.sil.lockstep.TickPeer`) without sockets."""

from __future__ import annotations

import hashlib

import pytest

from daa_sil.link.codec import CONTROL_LINK_ID, MavCodec
from daa_sil.sil.lockstep import TickPeer


def _decode(codec: MavCodec, data: bytes):
    (msg,) = codec.decode(data)
    return msg


def test_vehicle_end_counts_answers_only_to_ticks_it_sent():
    veh = TickPeer("vehicle", MavCodec(1, 1))
    msg = _decode(MavCodec(255, 190), veh.tick(0, 0.0))
    assert (msg.get_type(), msg.tick, msg.time_ms) == ("SIM_TICK", 0, 0) and veh.sent == 0
    assert veh.answered("gcs", 3, now=0.1) is None and veh.newest["gcs"] == -1  # never sent: nothing
    assert veh.partner == "none" and veh.confirmed(0)  # nobody answers: free-running
    veh.answered("gcs", 0, now=0.1)
    assert veh.partner == "gcs" and veh.ready(0) and not veh.ready(1)
    veh.tick(1, 1.0)
    veh.answered("shim", 1, now=0.2)  # behind a shim its echo of tick k >= 1 is enough
    assert veh.partner == "shim" and veh.ready(1) and not veh.ready(1, need_ack=True)
    assert veh.confirmed(1) and not veh.confirmed(2)
    veh.answered("gcs", 0, now=0.3)  # a late repeat changes nothing (acks are cumulative)
    assert veh.newest == {"shim": 1, "gcs": 0}


def test_tick_zero_waits_for_the_gcs_even_behind_a_shim():
    veh = TickPeer("vehicle", MavCodec(1, 1))
    veh.tick(0, 0.0)
    veh.answered("shim", 0, now=0.0)
    assert not veh.ready(0)
    veh.answered("gcs", 0, now=0.0)
    assert veh.ready(0)


def test_gcs_end_steps_each_new_tick_once_and_counts_skipped_ones():
    gcs = TickPeer("gcs", MavCodec(255, 190))
    assert gcs.on_tick(0, 0.0, now=0.0) == (True, None)
    gcs.ack(0, 0)
    assert gcs.on_tick(0, 0.0, now=0.1) == (False, None)  # repeated: ack again, no second step
    assert gcs.on_tick(3, 3.0, now=0.2) == (True, None)
    assert gcs.on_tick(3, 3.0, now=0.25) == (True, None)  # its step did not finish (no ack): run it again
    ack = _decode(MavCodec(1, 1), gcs.ack(3, 3000, sent=70000))
    assert (ack.get_type(), ack.tick, ack.time_ms, ack.sent) == ("SIM_TICK_ACK", 3, 3000, 65535)
    assert gcs.sent == 3 and gcs.heard["vehicle"] == 4 and gcs.newest_t == 3.0
    assert gcs.on_tick(2, 2.0, now=0.3) == (False, None) and gcs.newest_t == 3.0
    assert gcs.skipped == 4  # ticks 1 and 2, counted at each of the two tries of tick 3


@pytest.mark.parametrize("role,who", [("vehicle", "shim"), ("gcs", "vehicle")])
def test_silence_is_reported_once_and_its_end_once(role, who):
    peer = TickPeer(role, MavCodec(1, 1) if role == "vehicle" else MavCodec(255, 190))
    after = peer.silence[who].after_s
    assert peer.check_silence(100.0) == []  # never heard: never silent
    if role == "vehicle":
        peer.tick(0, 0.0)
        heard = lambda now: peer.answered(who, 0, now)  # noqa: E731
    else:
        heard = lambda now: peer.on_tick(0, 0.0, now)[1]  # noqa: E731
    assert heard(10.0) is None
    assert peer.check_silence(10.0 + after - 0.01) == []
    assert peer.check_silence(10.0 + after + 0.5) == [(who, pytest.approx(after + 0.5))]
    assert peer.check_silence(10.0 + after + 5.0) == []  # once
    assert heard(20.0 + after) == pytest.approx(10.0 + after)  # back after that much silence
    assert peer.silence_warnings == 1


def test_the_gcs_behind_a_silent_shim_is_not_reported():
    veh = TickPeer("vehicle", MavCodec(1, 1))
    veh.tick(0, 0.0)
    veh.answered("shim", 0, now=0.0)
    veh.answered("gcs", 0, now=0.0)
    assert veh.check_silence(60.0) == [("shim", 60.0)]
    assert veh.silence["gcs"].silent


def test_signed_control_messages_travel_on_their_own_stream():
    key = hashlib.sha256(b"k").digest()
    veh = TickPeer("vehicle", MavCodec(1, 1, key=key))
    assert veh.link_id == CONTROL_LINK_ID
    data = veh.tick(0, 0.0)
    assert data[-13] == CONTROL_LINK_ID  # the signature block starts with the link id
    assert TickPeer("vehicle", MavCodec(1, 1)).link_id is None
    with pytest.raises(ValueError):
        TickPeer("shim", MavCodec(1, 1))
