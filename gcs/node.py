"""The asyncio GCS node: one socket, a timer and the loop around a :class:`gcs.protocol.GcsProtocol`.

What the remote pilot sees (downlink-delayed telemetry) and what it sends, the tick protocol and the
free-running clock are the protocol core's (:mod:`gcs.protocol`); the pilot is :mod:`gcs.pilot`.
This module binds the socket (``--listen``, or ``--vehicle udpin:``), hands each datagram to
:meth:`GcsProtocol.receive` as it arrives, sends what the core has to send, prints its status lines
(:mod:`gcs.display`) and warnings, and wakes the core's timer (:meth:`GcsProtocol.on_idle`).
Every command sent is logged (JSONL, written atomically at the end).
"""

from __future__ import annotations

import asyncio
import json
import time
from pathlib import Path

from daa_sil.link.codec import MavCodec
from daa_sil.sil.connstr import LISTEN, SEND, parse_connection
from daa_sil.sil.endpoint import MavEndpoint, format_udp_address, norm_host, open_endpoint
from daa_sil.sil.intake import Intake
from daa_sil.sil.msgguard import MessageGuard

from .pilot import make_pilot
from .protocol import GCS_COMPID, GCS_SYSID, READ_IDS, VEHICLE_SYSID, GcsOptions, GcsProtocol, Notice, Stepped
from daa_sil.daa.config import DaaConfig
from daa_sil.sil.msgguard import stderr_line

__all__ = ["GcsNode", "GcsOptions", "READ_IDS"]


class GcsNode:
    """The GCS process. ``await start()``, then ``await run()`` until stopped."""

    def __init__(self, scenario, opts: GcsOptions):
        self.sc = scenario
        self.opts = opts
        self.vehicle_conn = parse_connection(opts.vehicle, "--vehicle", SEND)
        self.listen_conn = parse_connection(opts.listen, "--listen", LISTEN, allow=(LISTEN,))
        self.codec = MavCodec(GCS_SYSID, GCS_COMPID, key=opts.key, read_ids=READ_IDS)
        self.mode = opts.pilot or (scenario.pilot.mode if scenario is not None else "scripted")

        rc = opts.config
        if scenario is not None:
            self.daa_cfg = rc.daa_config(scenario.thresholds) if rc is not None else DaaConfig.for_preset(scenario.thresholds)
        else:
            self.daa_cfg = rc.daa_config() if rc is not None else DaaConfig()
        pilot = make_pilot(scenario, self.mode, self.daa_cfg, rc)
        #: with the pilot model: step 1, a :class:`daa_sil.models.ground.GroundCore` of one encounter
        self.ground = getattr(pilot, "ground", None)
        guard = MessageGuard("daa-gcs")
        if self.vehicle_conn.listens:  # --vehicle udpin:HOST:PORT: listen there, answer who sends first
            intake = Intake(self.codec, peer=None, learn_peer=True, lock_peer=True, allow_sysids=[VEHICLE_SYSID],
                            name="daa-gcs", guard=guard, peer_label="--vehicle udpin: the first sender",
                            drop_hint="the GCS takes telemetry only from the first vehicle that sent")
        else:
            peer = (norm_host(self.vehicle_conn.addr[0]), self.vehicle_conn.addr[1])
            intake = Intake(self.codec, peer=peer, learn_peer=False, allow_peers=[peer], allow_sysids=[VEHICLE_SYSID],
                            name="daa-gcs", guard=guard, peer_label="--vehicle",
                            drop_hint="if that is the vehicle (or the shim's GCS side), give its address as --vehicle: "
                                      "the GCS takes telemetry only from there")
        assumed_down = 0.0
        if scenario is not None and opts.clock != "lockstep":
            from daa_sil.sil.scenario import delay_models  # lazy: start-up time

            assumed_down = delay_models(scenario)[1].mean()
        #: the protocol: the view, the tick protocol, the pilot's steps, the settings to send
        self.protocol = GcsProtocol(scenario, opts, self.codec, intake, pilot, assumed_down_s=assumed_down,
                                    wall_offset=time.time() - time.monotonic())
        self.ep: "MavEndpoint | None" = None
        self.stop = asyncio.Event()

    # -- the protocol's state, by the names the CLI and the tests read ---------------------------
    @property
    def view(self):
        return self.protocol.view

    @property
    def ticks(self):
        return self.protocol.ticks

    @property
    def sent(self) -> list:
        return self.protocol.sent

    @property
    def steps(self) -> int:
        return self.protocol.steps

    @property
    def peer(self):
        """The vehicle side (``--vehicle``): fixed, or with ``udpin:`` the first address that sent."""
        return self.protocol.peer

    @property
    def local_address(self) -> str:
        return format_udp_address(self.ep.local_address)

    # -- lifecycle -------------------------------------------------------------------------------
    async def start(self) -> None:
        """Bind, then greet the vehicle side with a HEARTBEAT (a shim learns our address from it)."""
        where = self.vehicle_conn.addr if self.vehicle_conn.listens else self.listen_conn.addr
        self.ep = await open_endpoint(self.codec, where, intake=self.protocol.intake, on_datagram=self._on_datagram)
        if not self.vehicle_conn.listens:
            self.protocol.greet()
            self.flush()

    def _on_datagram(self, data: bytes, addr, now: float) -> None:
        self.protocol.receive(data, addr, now)
        self.flush()

    def flush(self) -> None:
        """Send what the protocol has to send; print its status lines and warnings."""
        for s in self.protocol.take_sends():
            if self.ep is None or self.ep.transport is None or self.ep.transport.is_closing():
                continue
            if s.counted:
                self.ep.send_datagram(s.data, s.addr, s.messages)
            else:
                self.ep.transport.sendto(s.data, s.addr)
        for ev in self.protocol.take_events():
            if isinstance(ev, Stepped):
                from .display import render_line  # lazy: start-up time

                render_line(self.protocol, ev.t, ev.n_cmd)
            elif isinstance(ev, Notice):
                stderr_line(f"daa-gcs: {ev.text}")  # (after the status lines gcs.display flushes in batches)

    def close(self) -> None:
        if self.ep is not None:
            self.ep.close()

    def request_stop(self) -> None:
        """Stop :meth:`run` (SIGINT / SIGTERM, ``--duration``) now, also while it waits for its timer."""
        self.stop.set()

    async def run(self) -> None:
        """Run until :attr:`stop` is set: datagrams are handled as they arrive; the core's timer in between."""
        loop = asyncio.get_running_loop()
        while not self.stop.is_set():
            try:
                await asyncio.wait_for(self.stop.wait(), self.protocol.idle_timeout(loop.time()))
            except asyncio.TimeoutError:
                pass
            if self.stop.is_set():
                break
            self.protocol.on_idle(loop.time())
            self.flush()

    def write_log(self) -> "Path | None":
        """Write the commands sent (JSONL) atomically."""
        if self.opts.log is None:
            return None
        from daa_sil.files import atomic_write_text, to_jsonable  # lazy: start-up time

        text = "".join(json.dumps(to_jsonable(r.as_dict()), sort_keys=True) + "\n" for r in self.sent)
        return atomic_write_text(self.opts.log, text)
