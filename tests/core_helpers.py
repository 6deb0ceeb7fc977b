"""The vehicle's and the GCS's protocol cores driven with bytes alone: no socket, no clock, no process.

:func:`vehicle_protocol` builds a :class:`vehicle.protocol.VehicleProtocol` whose pilot link is
:data:`PILOT` (the shim's address, as the vehicle sees it) with an observer at :data:`TAP`;
:func:`fly` plays a scenario on it the way the node's loop does (each step: handle what waits,
step the simulation, publish), with a hook after a step's publish to hand it datagrams;
:func:`gcs_protocol` builds a :class:`gcs.protocol.GcsProtocol` taking the vehicle side at :data:`VEHICLE`.
"""

from __future__ import annotations

from daa_sil.link.codec import MavCodec
from daa_sil.sil.intake import Intake
from daa_sil.sil.outputs import output_specs
from gcs.pilot import make_pilot
from gcs.protocol import READ_IDS, GcsOptions, GcsProtocol
from vehicle.core import VehicleCore
from vehicle.protocol import VehicleProtocol
from vehicle.tick_rules import TickOptions

PILOT = ("127.0.0.1", 40000)
TAP = ("127.0.0.1", 40001)
VEHICLE = ("127.0.0.1", 40002)
LISTEN = ("127.0.0.1", 40003)


def vehicle_protocol(sc, clock: str = "lockstep", plant: "VehicleCore | None" = None, key: "bytes | None" = None,
                     tap: bool = True) -> VehicleProtocol:
    """A vehicle protocol core for scenario ``sc`` (its simulation built unless ``plant`` is given)."""
    specs = output_specs([f"udp:{PILOT[0]}:{PILOT[1]}"], f"udp:{TAP[0]}:{TAP[1]}" if tap else None)
    return VehicleProtocol(plant or VehicleCore(sc), specs, LISTEN, MavCodec(1, 1, key=key), TickOptions(clock=clock))


def fly(proto: VehicleProtocol, steps: "int | None" = None, after_step=None) -> list:
    """Play ``steps`` steps (default: the scenario's) as the node does, one wall second per step (realtime
    reads are answered on arrival at ``k + 0.5`` s when ``after_step(proto, k, wall)`` hands datagrams in);
    returns every datagram sent, per step: ``[[Send, ...], ...]``."""
    n = proto.plant.n_steps if steps is None else steps
    sent = []
    for k in range(n):
        proto.begin_step(k)
        proto.process()
        out = proto.plant.step(proto.t)
        proto.publish(proto.t, out, float(k))
        if after_step is not None:
            after_step(proto, k, float(k) + 0.5)
        sent.append(proto.take_sends())
        proto.take_notices()
    return sent


def decoded(sends, to=None) -> list:
    """The messages of ``sends`` (to address ``to`` only, if given), decoded."""
    codec = MavCodec(255, 190)
    return [m for s in sends if to is None or tuple(s.addr) == tuple(to) for m in codec.decode(s.data)]


def gcs_protocol(sc, clock: str = "lockstep", mode: "str | None" = None) -> GcsProtocol:
    """A GCS protocol core for scenario ``sc`` taking the vehicle side at :data:`VEHICLE`."""
    codec = MavCodec(255, 190, read_ids=READ_IDS)
    intake = Intake(codec, peer=VEHICLE, learn_peer=False, allow_peers=[VEHICLE], allow_sysids=[1])
    from daa_sil.daa.config import DaaConfig

    pilot = make_pilot(sc, mode or sc.pilot.mode, DaaConfig.for_preset(sc.thresholds))
    return GcsProtocol(sc, GcsOptions(clock=clock, display=False), codec, intake, pilot)
