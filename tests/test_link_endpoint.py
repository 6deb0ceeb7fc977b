"""MavEndpoint on loopback: peers, allow-lists, hostile datagrams, signing; address parsing."""

from __future__ import annotations

import asyncio
import hashlib
import socket

import pytest

from daa_sil.errors import UsageError
from daa_sil.link.codec import MavCodec, mavlink as d
from daa_sil.sil.endpoint import format_udp_address, open_endpoint, parse_udp_address

KEY = hashlib.sha256(b"endpoint test").digest()


def hb():
    return d.MAVLink_heartbeat_message(d.MAV_TYPE_GCS, d.MAV_AUTOPILOT_INVALID, 0, 0, 4, 3)


@pytest.mark.parametrize("text,expected", [
    ("udp:127.0.0.1:14601", ("127.0.0.1", 14601)),
    ("udpin:0.0.0.0:0", ("0.0.0.0", 0)),
    ("localhost:5", ("localhost", 5)),
    ("udp:[::1]:14550", ("::1", 14550)),
])
def test_parse_udp_address(text, expected):
    assert parse_udp_address(text) == expected
    assert parse_udp_address(format_udp_address(expected)) == expected


@pytest.mark.parametrize("text", ["udp:127.0.0.1", "udp:127.0.0.1:70000", "udp:127.0.0.1:abc", "tcp:1.2.3.4:5",
                                  "udp::::1:5", ""])
def test_parse_udp_address_errors_are_one_line(text):
    with pytest.raises(UsageError) as ei:
        parse_udp_address(text, "--gcs")
    assert str(ei.value).startswith("--gcs") and "\n" not in str(ei.value)


@pytest.mark.asyncio
async def test_round_trip_and_learned_peer():
    async with await open_endpoint(MavCodec(1, 1)) as veh:
        async with await open_endpoint(MavCodec(255, 190), peer=veh.local_address) as gcs:
            assert veh.peer is None and not veh.send(hb())  # nobody to answer yet
            assert gcs.send(hb())
            r = await veh.recv(timeout=2)
            assert r.msg.get_type() == "HEARTBEAT" and r.msg.get_srcSystem() == 255
            assert veh.peer == gcs.local_address  # learned from the first good datagram
            veh.send_many([d.MAVLink_sim_tick_message(1, 1000), d.MAVLink_sim_tick_message(2, 2000)])
            got = [(await gcs.recv(timeout=2)).msg.tick for _ in range(2)]
            assert got == [1, 2]
            assert gcs.stats()["received"] == 2 and veh.stats()["sent"] == 2 and veh.stats()["send_no_peer"] == 1
            gcs.send_many([hb(), d.MAVLink_sim_tick_message(9, 9000)])
            assert (await veh.recv_match("SIM_TICK", timeout=2)).msg.tick == 9  # the HEARTBEAT is skipped
            with pytest.raises(asyncio.TimeoutError):
                await veh.recv_match("SIM_TICK", timeout=0.05)


@pytest.mark.asyncio
async def test_hostile_datagrams_counted_endpoint_keeps_working():
    async with await open_endpoint(MavCodec(1, 1)) as veh:
        raw = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            raw.bind(("127.0.0.1", 0))
            good = MavCodec(255, 190).encode(hb())
            corrupt = bytearray(good)
            corrupt[-2] ^= 0x55
            for pkt in (b"\xfd\x09", b"hello", bytes(corrupt), good[:-3]):
                raw.sendto(pkt, veh.local_address)
            raw.sendto(good, veh.local_address)
            r = await veh.recv(timeout=2)
            assert r.msg.get_type() == "HEARTBEAT"
            s = veh.stats()
            assert s["bad_crc"] == 1 and s["truncated"] == 2 and s["bad_prefix"] == 1
            assert s["dropped"] == 4 and s["received"] == 1
            assert veh.peer == raw.getsockname()  # garbage did not claim the peer, the good datagram did
        finally:
            raw.close()


@pytest.mark.asyncio
async def test_allow_lists():
    async with await open_endpoint(MavCodec(1, 1), allow_sysids={255}) as veh, \
            await open_endpoint(MavCodec(200, 1), peer=veh.local_address) as intruder, \
            await open_endpoint(MavCodec(255, 190), peer=veh.local_address) as gcs:
        intruder.send(hb())
        gcs.send(hb())
        r = await veh.recv(timeout=2)
        assert r.msg.get_srcSystem() == 255 and veh.stats()["rejected_sysid"] == 1
    async with await open_endpoint(MavCodec(1, 1), allow_peers=[("127.0.0.1", 9)]) as closed:
        async with await open_endpoint(MavCodec(255, 190), peer=closed.local_address) as gcs:
            gcs.send(hb())
            for _ in range(50):
                if closed.stats()["rejected_peer"]:
                    break
                await asyncio.sleep(0.01)
            assert closed.stats()["rejected_peer"] == 1 and closed.inbox.empty()


@pytest.mark.asyncio
async def test_signed_endpoints_reject_unsigned_sender():
    async with await open_endpoint(MavCodec(1, 1, key=KEY)) as veh, \
            await open_endpoint(MavCodec(255, 190), peer=veh.local_address) as plain, \
            await open_endpoint(MavCodec(255, 191, key=KEY), peer=veh.local_address) as signed:
        plain.send(hb())
        signed.send(hb())
        r = await veh.recv(timeout=2)
        assert r.msg.get_srcComponent() == 191 and r.msg.get_signed()
        assert veh.stats()["unsigned"] == 1


@pytest.mark.asyncio
async def test_bind_error_is_usage_error():
    async with await open_endpoint(MavCodec(1, 1)) as a:
        with pytest.raises(UsageError, match="cannot bind"):
            await open_endpoint(MavCodec(1, 1), a.local_address)
