"""An encounter played by the vehicle, the delay shim and the GCS in this process, on real loopback
sockets, with a tap socket; used by the hostile-message tests (``tests/test_hostile_messages.py``,
``tests/test_message_guard.py``)."""

from __future__ import annotations

import asyncio
import socket

from daa_sil.link.codec import MavCodec, mavlink as M
from daa_sil.sil.endpoint import format_udp_address
from daa_sil.sil.scenario import delay_models, parse_scenario
from daa_sil.sil.shim import DelayShim
from daa_sil.sil.shim_config import ShimConfig
from gcs.node import GcsNode, GcsOptions
from vehicle.node import VehicleNode, VehicleOptions

HANG_GUARD_S = 300.0  # only to fail instead of hanging
INJECT_STEP = 3
STEPS = 30  #: the scenario's duration_s
REALTIME_SPEED = 5.0
#: 30 s head-on, 2 s each way: no_wait, blend and wait decisions (the wait map), so W_T and DAA_ENABLE matter
SCENARIO = """\
name: head-on-hostile
description: short head-on for the hostile-message property test
seed: 11
duration_s: 30
ownship: {alt_m: 1000, gs_mps: 55, track_deg: 0}
intruders:
  - callsign: HEAD1
    initial: {x_m: 150, y_m: 6900, alt_m: 1000, gs_mps: 60, track_deg: 180}
link: {up: "const:2", down: "const:2"}
pilot: {mode: model, model: {response: deterministic}}
allocation: {group: ID-1}
"""


def msg_class(mtype: str):
    return M.mavlink_map[getattr(M, f"MAVLINK_MSG_ID_{mtype}")]


def pack(mtype: str, fields: dict, sysid: int, compid: int) -> bytes:
    """One packet from its own codec (header seq 0, so a reference run packs the same bytes)."""
    return MavCodec(sysid, compid).encode(msg_class(mtype)(**fields))


async def play(clock: str, inject=None) -> dict:
    """The scenario in ``clock`` with a tap; ``inject(veh, gcs, shim, tap)`` is called after step INJECT_STEP."""
    sc = parse_scenario(SCENARIO, "hostile.yaml")
    up, down = delay_models(sc)
    speed = REALTIME_SPEED if clock == "realtime" else 1.0
    shim = DelayShim(ShimConfig(delay_down=down, delay_up=up, listen_vehicle="udp:127.0.0.1:0",
                                listen_gcs="udp:127.0.0.1:0", epoch_s=sc.link.epoch_s, seed=sc.seed, clock=clock,
                                speed=speed))
    await shim.start()
    tap = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    tap.bind(("127.0.0.1", 0))
    tap.setblocking(False)
    gcs = GcsNode(sc, GcsOptions(vehicle=format_udp_address(shim.gcs_side), listen="udp:127.0.0.1:0", clock=clock,
                                 speed=speed, display=False))
    veh = VehicleNode(sc, VehicleOptions(out=format_udp_address(shim.vehicle_side), clock=clock, speed=speed,
                                         tick_sync="wait", tick_timeout_s=60.0, tap=format_udp_address(tap.getsockname())))
    received = []
    try:
        await gcs.start()
        await veh.start()

        def on_step(node, _out):
            if inject is not None and node.k == INJECT_STEP:
                inject(veh, gcs, shim, tap)

        gtask = asyncio.create_task(gcs.run())
        await asyncio.wait_for(veh.run(on_step=on_step), HANG_GUARD_S)
        await asyncio.sleep(0.05)  # the last answers to the tap
        gcs.stop.set()
        await asyncio.wait_for(gtask, 30)
        while True:
            try:
                received.append(tap.recv(65535))
            except BlockingIOError:
                break
    finally:
        tap.close()
        veh.close()
        gcs.close()
        await shim.close()
    return {"rows": veh.core.rows, "veh": veh, "gcs": gcs, "shim": shim, "tap_rx": received}


GCS_CANARY = pack("PARAM_SET", {"target_system": 1, "target_component": 1, "param_id": b"DAA_WT",
                                "param_value": 7.5, "param_type": M.MAV_PARAM_TYPE_REAL32}, 255, 190)
TAP_CANARY_US = 424242
TAP_CANARY = pack("PING", {"time_usec": TAP_CANARY_US, "seq": 7, "target_system": 0, "target_component": 0}, 255, 190)
VEHICLE_CANARY = pack("PARAM_VALUE", {"param_id": b"CANARY", "param_value": 42.0, "param_type": 9,
                                      "param_count": 1, "param_index": 0}, 1, 1)
