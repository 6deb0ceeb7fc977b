"""Ground stations come and go as they do with SITL, at the vehicle's protocol core (bytes only, no socket):

* a ``udpin:`` output answers every ground station heard within ``PEER_TIMEOUT_S`` (pymavlink's ``udpin``
  rule), each with its own rates and reply budget; a stale one never locks a new one out; a new one is
  answered from its first good datagram; at most ``MAX_PEERS`` at once, the rest refused without touching
  the signing state;
* a ``tcpin:`` output serves each connection as a ground station of its own: reconnects, several at once,
  a stream cut anywhere (the framer), a cap on connections;
* signing and the read-only rule of observers hold on every transport.

On main (3e5dc69 + the cores) a ``udpin:`` output locked onto its first sender (a restarted MAVProxy was
dropped: ``test_a_restarted_gcs_is_answered_over_udpin`` fails there) and ``tcpin:`` was a usage error.
"""

from __future__ import annotations

import pytest

from core_helpers import decoded
from daa_sil.link.codec import MavCodec
from daa_sil.link.codec import mavlink as M
from daa_sil.link.framing import MAX_PACKET, StreamFramer
from daa_sil.sil.outputs import output_specs
from daa_sil.sil.scenario import parse_scenario
from test_vehicle_protocol import SCENARIO
from vehicle.ports import MAX_PEERS, PEER_TIMEOUT_S
from vehicle.protocol import VehicleProtocol
from vehicle.tick_rules import TickOptions

SC = parse_scenario(SCENARIO, "stations.yaml")
LISTEN = ("127.0.0.1", 40003)
A, B, C = ("127.0.0.1", 50001), ("127.0.0.1", 50002), ("127.0.0.1", 50003)


@pytest.fixture(scope="module")
def plant_factory():
    from vehicle.core import VehicleCore

    return lambda: VehicleCore(SC)


def proto(plant, outs, key=None, clock="realtime", tap=None) -> VehicleProtocol:
    return VehicleProtocol(plant, output_specs(outs, tap), LISTEN, MavCodec(1, 1, key=key), TickOptions(clock=clock))


def hb(codec: MavCodec) -> bytes:
    return codec.encode(M.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3))


def step(p: VehicleProtocol, k: int, wall: float):
    p.begin_step(k)
    p.process()
    p.publish(p.t, p.plant.step(p.t), wall)
    return p.take_sends()


def to(sends, addr) -> list:
    return [s for s in sends if tuple(s.addr) == addr]


def test_a_restarted_gcs_is_answered_over_udpin(plant_factory):
    """MAVProxy restarted mid-run comes back from a new port: it is answered from its first heartbeat, and the
    old one, silent, is dropped after PEER_TIMEOUT_S (on main the new one was dropped as a stranger)."""
    p = proto(plant_factory(), ["udpin:127.0.0.1:14550"])
    gcs = MavCodec(255, 190)
    assert not step(p, 0, 0.0)  # nobody has spoken: nothing to send to
    p.receive(0, hb(gcs), A, 0.5)
    assert to(step(p, 1, 1.0), A) and p.pilot_heard
    # the GCS is restarted: its new socket speaks at t = 3 s, the old one never again
    p.receive(0, hb(MavCodec(255, 190)), B, 2.5)
    sends = step(p, 2, 3.0)
    assert to(sends, A) and to(sends, B)  # both within the last few seconds
    p.receive(0, GCS_LIST, B, 3.2)
    values = [m for m in decoded(p.take_sends(), B) if m.get_type() == "PARAM_VALUE"]
    assert len(values) == 8  # its reads are answered at once (realtime), in its own budget
    wall = 3.0 + PEER_TIMEOUT_S + 0.5  # A silent for longer than the rule
    p.receive(0, hb(gcs), B, wall - 0.1)
    sends = step(p, 3, wall)
    assert to(sends, B) and not to(sends, A) and p.pilot.expired == 1
    assert p.ports[0].intake.counters.datagrams_rejected_peer == 0


GCS_LIST = MavCodec(255, 191).encode(M.MAVLink_param_request_list_message(1, 1))


def test_the_last_gcs_is_kept_and_every_station_has_its_own_rates(plant_factory):
    """pymavlink keeps answering the one heard last even when it pauses; rates are per ground station."""
    p = proto(plant_factory(), ["udpin:127.0.0.1:14550"])
    p.receive(0, hb(MavCodec(255, 190)), A, 0.0)
    p.receive(0, hb(MavCodec(255, 191)), B, 0.1)
    p.receive(0, MavCodec(255, 191).encode(M.MAVLink_command_long_message(
        1, 1, M.MAV_CMD_SET_MESSAGE_INTERVAL, 0, M.MAVLINK_MSG_ID_VFR_HUD, -1, 0, 0, 0, 0, 0)), B, 0.2)
    p.take_sends()
    sends = step(p, 0, 1.0)
    assert [m for m in decoded(to(sends, A)) if m.get_type() == "VFR_HUD"]
    assert not [m for m in decoded(to(sends, B)) if m.get_type() == "VFR_HUD"]  # B stopped its own only
    sends = step(p, 1, 60.0)  # both silent for a minute: the one heard last is still answered
    assert to(sends, B) and not to(sends, A)


def test_a_listening_output_serves_at_most_max_peers_and_refuses_without_touching_signing(plant_factory):
    key = bytes(range(32))
    p = proto(plant_factory(), ["udpin:127.0.0.1:14550"], key=key)
    stations = [("127.0.0.1", 51000 + i) for i in range(MAX_PEERS + 1)]
    for i, addr in enumerate(stations[:MAX_PEERS]):
        p.receive(0, hb(MavCodec(255, 100 + i, key=key)), addr, 0.0)
    assert len(p.pilot.peers) == MAX_PEERS
    late = MavCodec(255, 99, key=key)
    first = hb(late)
    p.receive(0, first, stations[-1], 0.5)  # every slot live: refused, its signed packet not committed
    assert p.pilot.refused == 1 and stations[-1] not in p.pilot.peers
    assert p.ports[0].intake.counters.rejected_peer == 1
    # an unsigned stranger never takes a slot, even a free one
    p.pilot.drop(stations[0])
    p.receive(0, hb(MavCodec(255, 98)), stations[0], 0.6)
    assert stations[0] not in p.pilot.peers and p.codec.counters.unsigned == 1
    # the refused station's same packet, once a slot is free, is not a replay: nothing was committed
    p.receive(0, first, stations[-1], 0.7)
    assert stations[-1] in p.pilot.peers and p.codec.counters.replayed == 0
    # and once the others are silent past the rule, new ones get their slots
    for i in range(MAX_PEERS + 3):
        p.receive(0, hb(MavCodec(255, 50 + i, key=key)), ("127.0.0.1", 52000 + i), 10.0 + PEER_TIMEOUT_S + i)
    assert len(p.pilot.peers) <= MAX_PEERS and ("127.0.0.1", 52000 + MAX_PEERS + 2) in p.pilot.peers


def test_observers_over_udpin_and_tcpin_stay_read_only(plant_factory):
    p = proto(plant_factory(), ["udp:127.0.0.1:14550", "udpin:127.0.0.1:14560", "tcpin:127.0.0.1:5760"])
    assert [(o.name, o.port) for o in p.outputs] == [("gcs", 0), ("out2", 1), ("out3", 2)]
    assert p.connect(2, C, 0.0)
    gcs = MavCodec(255, 190)
    p.receive(1, gcs.encode(M.MAVLink_param_set_message(1, 1, b"DAA_WT", 9.0, M.MAV_PARAM_TYPE_REAL32)), A, 0.1)
    p.receive_stream(2, gcs.encode(M.MAVLink_param_set_message(1, 1, b"DAA_WT", 8.0, M.MAV_PARAM_TYPE_REAL32)), C, 0.2)
    p.receive_stream(2, gcs.encode(M.MAVLink_command_long_message(
        1, 1, M.MAV_CMD_DO_REPOSITION, 0, -1, 0, 0, 0, 37.5, -122.0, 1000)), C, 0.3)
    step(p, 0, 1.0)
    assert [(e.link, e.status) for e in p.events] == [("out2", "denied_readonly"), ("out3", "denied_readonly")]
    assert p.plant.policy.wait_threshold_s == 4.0 and p.gate.counters.accepted == 0
    assert p.stats.commands_from_observers_ignored == 1


def test_tcpin_serves_each_connection_with_its_stream_cut_anywhere(plant_factory):
    p = proto(plant_factory(), ["tcpin:127.0.0.1:5760"])
    assert [(o.name, o.port) for o in p.outputs] == [("gcs", 1)] and p.ports[1].transport == "tcp"
    gcs = MavCodec(255, 190)
    assert p.connect(1, A, 0.0) and p.connect(1, B, 0.0)
    data = hb(gcs) + gcs.encode(M.MAVLink_param_request_read_message(1, 1, b"DAA_WT", -1))
    for i in range(len(data)):  # one byte at a time: the framer holds the rest
        p.receive_stream(1, data[i:i + 1], A, 0.1)
    got = decoded(p.take_sends(), A)
    assert [(m.get_type(), m.param_id) for m in got] == [("PARAM_VALUE", "DAA_WT")]
    sends = step(p, 0, 1.0)
    assert to(sends, A) and to(sends, B)  # two clients at once
    assert all(s.port == 1 for s in sends)
    p.disconnect(1, A)  # the client goes; it reconnects from a new port
    assert p.connect(1, C, 2.0)
    sends = step(p, 1, 2.0)
    assert not to(sends, A) and to(sends, B) and to(sends, C)
    for i in range(MAX_PEERS - 2):
        assert p.connect(1, ("127.0.0.1", 53000 + i), 3.0)
    assert not p.connect(1, ("127.0.0.1", 54000), 3.0) and p.pilot.refused == 1


def test_the_framer_keeps_at_most_one_packet_and_passes_garbage_to_the_codec():
    gcs = MavCodec(255, 190)
    f = StreamFramer()
    pkt = hb(gcs)
    assert f.feed(b"\x00\x01garbage" + pkt[:5]) == b"\x00\x01garbage" and f.pending == 5
    assert f.feed(pkt[5:] + pkt) == pkt + pkt and f.pending == 0
    rx = MavCodec(1, 1)
    assert [m.get_type() for m in rx.decode(b"\x00\x01garbage" + pkt)] == ["HEARTBEAT"]
    assert rx.counters.bad_prefix == 1
    # a hostile stream never makes it keep more than one packet's worth
    for chunk in (b"\xfd\xff\x01" + bytes(200), bytes(5000), b"\xfd" * 3000, b"\xfe"):
        f.feed(chunk)
        assert f.pending <= MAX_PACKET


def test_signing_holds_on_tcp(plant_factory):
    key = bytes(range(32))
    p = proto(plant_factory(), ["tcpin:127.0.0.1:5760"], key=key)
    assert p.connect(1, A, 0.0)
    p.receive_stream(1, MavCodec(255, 190).encode(M.MAVLink_param_request_read_message(1, 1, b"DAA_WT", -1)), A, 0.1)
    assert not p.take_sends() and p.codec.counters.unsigned == 1
    p.receive_stream(1, MavCodec(255, 190, key=key).encode(M.MAVLink_param_request_read_message(1, 1, b"DAA_WT", -1)),
                     A, 0.2)
    assert [m.get_type() for m in MavCodec(255, 190, key=key).decode(p.take_sends()[0].data)] == ["PARAM_VALUE"]


def test_a_tcp_client_that_does_not_read_has_a_bounded_buffer_and_extra_clients_are_closed():
    """The socket side of ``tcpin:``: what waits for a client that never reads stays under the cap (the rest
    is dropped and counted), and a connection the core refuses is closed at once."""
    import asyncio
    import socket

    from daa_sil.sil.tcp_server import TcpServer

    async def go():
        seen = []
        server = TcpServer(lambda addr, now: len(seen) < 1 and not seen.append(addr), lambda a, d, n: None,
                           lambda a: None, max_buffer=64 * 1024)
        await server.start(("127.0.0.1", 0))
        port = server.local_address[1]
        lazy = socket.create_connection(("127.0.0.1", port))  # connects, never reads
        lazy.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        extra = socket.create_connection(("127.0.0.1", port))
        for _ in range(100):
            await asyncio.sleep(0.02)
            if server.counters.refused:
                break
        chunk = bytes(1000)
        for _ in range(20_000):  # 20 MB to a client that reads nothing
            server.send(seen[0], chunk)
            if server.counters.dropped_slow > 100:
                break
        waiting = server.clients[seen[0]].transport.get_write_buffer_size()
        extra.settimeout(5.0)
        closed = extra.recv(10) == b""  # the refused one: closed by the server
        server.close()
        lazy.close()
        extra.close()
        return server.counters, waiting, closed

    counters, waiting, closed = asyncio.run(go())
    assert counters.refused == 1 and closed
    assert counters.dropped_slow > 100 and waiting <= 64 * 1024
