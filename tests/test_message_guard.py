"""Issue 20 §1, the class: no message handler can take a process down or the rest of its datagram with it.

* the instance: COMMAND_LONG ARM_DISARM with param2 NaN from the read-only tap killed the vehicle in
  lockstep (``int(NaN)``) and, in realtime, lost the PING behind it in the same datagram. Now the
  run completes, both are answered, and the step log is the clean run's;
* the class: a handler that raises (simulated here by making one handler fail, as a bug not yet
  found would) costs its own message only: it is counted as malformed (``malformed_content``), one
  warning names it (then a summary with counts at most every 10 s), the other messages of the
  datagram are handled -- in the vehicle (lockstep and realtime), the GCS and the shim;
* :class:`daa_sil.sil.msgguard.MessageGuard` itself: counting, reporting, and Ctrl-C / cancellation
  never swallowed.
"""

from __future__ import annotations

import asyncio
import math
import socket

import pytest

from daa_sil.link.codec import MavCodec, mavlink as M
from daa_sil.sil.endpoint import open_endpoint
from daa_sil.sil.msgguard import MessageGuard
from daa_sil.steplog import cells_equal
from hostile_helpers import STEPS, VEHICLE_CANARY, pack, play


def _arm_nan_and_ping() -> bytes:
    arm = pack("COMMAND_LONG", {"target_system": 1, "target_component": 1, "command": M.MAV_CMD_COMPONENT_ARM_DISARM,
                                "confirmation": 0, "param1": 0.0, "param2": math.nan, "param3": 0.0, "param4": 0.0,
                                "param5": 0.0, "param6": 0.0, "param7": 0.0}, 255, 190)
    ping = pack("PING", {"time_usec": 777, "seq": 1, "target_system": 0, "target_component": 0}, 255, 190)
    return arm + ping


def _tap_replies(run: dict) -> list:
    return [m for d in run["tap_rx"] for m in MavCodec(255, 190).decode(d)]


@pytest.mark.parametrize("clock", ["lockstep", "realtime"])
def test_arm_disarm_with_nan_from_the_tap_is_answered_and_changes_nothing(clock):
    """The issue's datagram: the vehicle refuses the disarm (airborne), answers the PING behind it, flies on."""
    clean = asyncio.run(play(clock))
    run = asyncio.run(play(clock, lambda veh, gcs, shim, tap: tap.sendto(_arm_nan_and_ping(), veh.ep.local_address)))
    assert run["veh"].stats.steps == STEPS
    got = _tap_replies(run)
    acks = [m for m in got if m.get_type() == "COMMAND_ACK" and m.command == M.MAV_CMD_COMPONENT_ARM_DISARM]
    assert [a.result for a in acks] == [M.MAV_RESULT_FAILED]  # disarm refused: airborne
    assert any(m.get_type() == "PING" and m.time_usec == 777 for m in got)  # the message behind it too
    assert run["veh"].guard.total == 0  # handled, not caught: the conversion is checked
    if clock == "lockstep" or (run["veh"].stats.steps_unconfirmed == 0 and clean["veh"].stats.steps_unconfirmed == 0
                               and run["shim"].counters["released_late"] == 0
                               and clean["shim"].counters["released_late"] == 0):
        assert all(cells_equal(a[k], b[k]) for a, b in zip(run["rows"], clean["rows"]) for k in a)


@pytest.mark.parametrize("clock", ["lockstep", "realtime"])
def test_a_vehicle_handler_that_raises_loses_only_its_message(clock, monkeypatch, capfd):
    """A PING whose handling raises (a bug standing in for any unforeseen content): counted, warned once,
    and the PARAM_REQUEST_READ behind it in the same datagram is still answered."""
    from vehicle.services import GcsServices

    real_read = GcsServices.read

    def read(self, msg, *args):
        if msg.get_type() == "PING":
            raise ValueError("boom in PING")
        return real_read(self, msg, *args)

    monkeypatch.setattr(GcsServices, "read", read)
    ping = pack("PING", {"time_usec": 1, "seq": 1, "target_system": 0, "target_component": 0}, 255, 190)
    req = pack("PARAM_REQUEST_READ", {"target_system": 1, "target_component": 1, "param_id": b"DAA_WT",
                                      "param_index": -1}, 255, 190)

    def inject(veh, gcs, shim, tap):
        for _ in range(3):
            tap.sendto(ping + req, veh.ep.local_address)

    run = asyncio.run(play(clock, inject))
    assert run["veh"].stats.steps == STEPS
    values = [m for m in _tap_replies(run) if m.get_type() == "PARAM_VALUE" and m.param_id == "DAA_WT"]
    assert len(values) == 3 and all(v.param_value == 4.0 for v in values)
    g = run["veh"].guard
    assert g.total == 3 and dict(g.by_type) == {"PING": 3}
    assert run["veh"].ep.stats()["malformed_content"] == 3
    err = capfd.readouterr().err
    warned = [x for x in err.splitlines() if "malformed PING" in x]
    assert len(warned) == 1 and warned[0].startswith("daa-vehicle: warning: malformed PING from udp:127.0.0.1:")
    assert "ValueError: boom in PING" in warned[0]


def test_a_gcs_handler_that_raises_loses_only_its_message(monkeypatch):
    """Telemetry whose handling raises at the GCS: counted; the PARAM_VALUE behind it reaches the view."""
    from gcs.view import View

    real_take = View.take

    def take(self, m, *a, **kw):
        if m.get_type() == "STATUSTEXT":
            raise RuntimeError("boom in STATUSTEXT")
        return real_take(self, m, *a, **kw)

    monkeypatch.setattr(View, "take", take)
    text = pack("STATUSTEXT", {"severity": 6, "text": b"hello", "id": 0, "chunk_seq": 0}, 1, 1)

    def inject(veh, gcs, shim, tap):
        veh.ep.transport.sendto(text + VEHICLE_CANARY, shim.vehicle_side)

    run = asyncio.run(play("lockstep", inject))
    assert run["veh"].stats.steps == STEPS
    assert run["gcs"].view.params.get("CANARY") == 42.0
    assert run["gcs"].ep.guard.by_type["STATUSTEXT"] >= 1  # the vehicle's own STATUSTEXTs raise too


def test_a_shim_datagram_whose_handling_raises_does_not_stop_the_shim(monkeypatch):
    """The shim's unit is the datagram: one that raises is counted; the next one is relayed."""
    from daa_sil.models.latency import Constant
    from daa_sil.sil.shim import DelayShim
    from daa_sil.sil.shim_config import ShimConfig

    async def go():
        shim = DelayShim(ShimConfig(delay_down=Constant(0.2), delay_up=Constant(0.2), listen_vehicle="udp:127.0.0.1:0",
                                    listen_gcs="udp:127.0.0.1:0", clock="realtime", seed=1))
        await shim.start()
        real = shim._on_datagram
        seen = []

        def on_datagram(side, data, addr, t_rx=None):
            if data.endswith(b"BOOM"):
                raise KeyError("boom")
            seen.append(data)
            real(side, data, addr, t_rx)

        monkeypatch.setattr(shim, "_on_datagram", on_datagram)
        lines = []
        shim.warn = lines.append
        hb = MavCodec(1, 1).encode(M.MAVLink_heartbeat_message(1, 3, 0, 0, 4, 3))
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            for data in (hb + b"BOOM", hb, hb + b"BOOM", hb):
                s.sendto(data, shim.vehicle_side)
            for _ in range(200):
                if len(seen) == 2 and shim.guard.total == 2:
                    break
                await asyncio.sleep(0.01)
        stats = shim.stats()
        await shim.close()
        return seen, stats, lines, shim.guard

    seen, stats, lines, guard = asyncio.run(go())
    assert len(seen) == 2 and guard.total == 2 and stats["counters"]["malformed_content"] == 2
    assert len([x for x in lines if "malformed datagram from the vehicle side" in x]) == 1


def test_endpoint_on_message_that_raises_drops_that_message_only():
    async def go():
        got = []

        def on_message(r):
            if r.msg.get_type() == "PING":
                raise OverflowError("boom")
            got.append(r.msg.get_type())

        lines = []
        async with await open_endpoint(MavCodec(1, 1), on_message=on_message, warn=lines.append,
                                       name="daa-test") as ep:
            c = MavCodec(255, 190)
            dgram = c.encode_many([M.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3), M.MAVLink_ping_message(1, 1, 0, 0),
                                   M.MAVLink_system_time_message(0, 5)])
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
                s.sendto(dgram, ep.local_address)
                for _ in range(200):
                    if ep.counters.datagrams_received:
                        break
                    await asyncio.sleep(0.01)
            inbox = [ep.inbox.get_nowait().msg.get_type() for _ in range(ep.inbox.qsize())]
            return got, inbox, ep.stats(), lines

    got, inbox, stats, lines = asyncio.run(go())
    assert got == ["HEARTBEAT", "SYSTEM_TIME"] and inbox == ["HEARTBEAT", "SYSTEM_TIME"]
    assert stats["malformed_content"] == 1 and stats["dropped"] == 1
    assert len(lines) == 1 and lines[0].startswith("daa-test: warning: malformed PING from udp:127.0.0.1:")


def test_message_guard_counts_reports_and_never_swallows_an_interrupt():
    now = [0.0]
    lines: list = []
    g = MessageGuard("daa-x", emit=lines.append, every_s=10.0, clock=lambda: now[0])

    def bad(_):
        raise ValueError("nope")

    assert g.call(lambda x: None, 1, what="HEARTBEAT") is True
    for i in range(5):
        assert g.call(bad, i, what="COMMAND_LONG", source=("127.0.0.1", 5)) is False
    assert g.call(bad, 0, what="PARAM_SET") is False
    # one line per new type at once, nothing more until 10 s passed
    assert len(lines) == 2 and "malformed COMMAND_LONG from udp:127.0.0.1:5" in lines[0] and "PARAM_SET" in lines[1]
    now[0] = 10.5
    g.call(bad, 0, what="COMMAND_LONG")
    assert len(lines) == 3 and "still dropping malformed messages" in lines[2]
    assert "7 in all" in lines[2] and "COMMAND_LONG: 6" in lines[2]
    assert g.total == 7 and g.by_type == {"COMMAND_LONG": 6, "PARAM_SET": 1}
    assert g.summary() == "malformed messages dropped: 7 (COMMAND_LONG: 6, PARAM_SET: 1)"
    for exc in (KeyboardInterrupt, asyncio.CancelledError, SystemExit):
        def stop(_, e=exc):
            raise e()

        with pytest.raises(exc):
            g.call(stop, 0)
    assert g.total == 7
