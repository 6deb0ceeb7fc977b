"""The asyncio GCS node: what the remote pilot sees (downlink-delayed telemetry) and what it sends.

Per step ``k`` at sim time ``t_k`` (``docs/architecture.md`` step 1):

* **lockstep**: on ``SIM_TICK(k, t_k)`` (forwarded by the shim after it released every packet due
  at ``t_k``) the node first takes in every message received before the tick, then runs the pilot,
  sends its command(s) and a HEARTBEAT (one datagram), then ``SIM_TICK_ACK(k)`` alone in its
  datagram. A repeated tick is re-acknowledged without stepping again.
* **realtime**: the same: the vehicle paces its ticks (``SIM_TICK``) by the wall clock and the shim
  forwards each one at once, so the GCS steps at the vehicle's sim time ``t_k`` with exactly what
  the lockstep GCS has at that tick, and acknowledges it (nobody waits for that ack). Only with a
  vehicle that sends no ticks does the node fall back to its own clock, synchronised on the first
  telemetry message (``t = time_boot_ms + assumed downlink delay``) and advanced with the wall
  clock x ``speed``, stepping at every whole sim second (that clock is off by the difference
  between the first packet's delay and the assumed one: no lockstep parity).

Ticks that stop after they came (``SILENT_AFTER_S["gcs"]``, :mod:`daa_sil.sil.silence`) are reported
(stderr), naming the address they came from; the tick protocol's state is a
:class:`daa_sil.sil.lockstep.TickPeer`.

Hostile input: only the vehicle side's address and system id are accepted (``--vehicle udpin:``: the
first sender, any other is dropped with a warning); every message is handled under the endpoint's
:class:`daa_sil.sil.msgguard.MessageGuard` (one that raises is counted as malformed, the rest of its
datagram is still handled); telemetry the pilot would see is taken only if its values are physical
(:data:`daa_sil.geometry.kinematics.STATE_BOUNDS`, latitudes/longitudes, DAIDALUS alert levels 0-3),
not older than what the pilot already sees and, when ticks drive the GCS, not stamped after the
newest tick (``View.rejected`` counts the rest).

Pilot: ``model`` = :class:`daa_sil.ground.GroundCore` (N = 1; step 1, the same code fast-time runs: the
pilot's display and :class:`daa_sil.models.pilot.PilotModel`) on the observed ownship
(LOCAL_POSITION_NED, float) and intruders (ADSB_VEHICLE), streaming per the allocation semantics;
``scripted`` = the scenario's ``pilot.commands`` (each sent once per step over ``[t_s, until_s)``).
Commands go out as ``PILOT_MANEUVER`` (absolute setpoint, send time in ``time_boot_ms``, ``cmd_seq``
1, 2, ...). Every command sent is logged (JSONL, written atomically at the end).
"""

from __future__ import annotations

import asyncio
import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from daa_sil.geometry.frames import geodetic_to_enu
from daa_sil.geometry.kinematics import AircraftState
from daa_sil.link.codec import MavCodec
from daa_sil.link.codec import mavlink as M
from daa_sil.sil.connstr import LISTEN, SEND, parse_connection
from daa_sil.sil.endpoint import MavEndpoint, Received, format_udp_address, open_endpoint
from daa_sil.sil.lockstep import TickPeer

from .view import READ_IDS as VIEW_READS, View

#: every message id the GCS reads: the telemetry its view takes in, and the lockstep tick; its codec
#: verifies the rest of the vehicle's stream and counts it as ``unread`` without unpacking it
READ_IDS = VIEW_READS | {M.MAVLINK_MSG_ID_SIM_TICK}

GCS_SYSID, GCS_COMPID = 255, 190
VEHICLE_SYSID = 1


@dataclass
class GcsOptions:
    """Runtime options (addresses ``udp:HOST:PORT``)."""

    vehicle: str = "udp:127.0.0.1:14601"
    listen: str = "udp:127.0.0.1:14550"
    clock: str = "realtime"
    speed: float = 1.0
    key: "bytes | None" = None
    pilot: "str | None" = None  #: "model" / "scripted" (default: the scenario's)
    log: "Path | None" = None
    display: bool = True
    #: settings to send: ``(sim time s, NAME, value)``; NAME ``MODE`` sends DO_SET_MODE (value = mode number)
    settings: tuple = ()
    #: ``--config``: a :class:`daa_sil.config.run_config.RunConfig` whose ``daa`` changes shape the
    #: pilot's display and whose ``pilot`` changes the pilot model (None = the scenario alone)
    config: "object | None" = None


class GcsNode:
    """The GCS process logic. ``await start()``, then ``await run()`` until stopped."""

    def __init__(self, scenario, opts: GcsOptions):
        self.sc = scenario
        self.opts = opts
        self.vehicle_conn = parse_connection(opts.vehicle, "--vehicle", SEND)
        self.listen_conn = parse_connection(opts.listen, "--listen", LISTEN, allow=(LISTEN,))
        self._peer = None if self.vehicle_conn.listens else self.vehicle_conn.addr
        self.pending_settings = sorted(opts.settings, key=lambda s: s[0])
        self.codec = MavCodec(GCS_SYSID, GCS_COMPID, key=opts.key, read_ids=READ_IDS)
        self.ep: "MavEndpoint | None" = None
        self.view = View()
        self.mode = opts.pilot or (scenario.pilot.mode if scenario is not None else "scripted")
        self.origin = scenario.origin if scenario is not None else None
        self.order = [i.id for i in scenario.intruders] if scenario is not None else []
        from daa_sil.daa.config import DaaConfig

        rc = opts.config
        if scenario is not None:
            self.daa_cfg = rc.daa_config(scenario.thresholds) if rc is not None else DaaConfig.for_preset(scenario.thresholds)
        else:
            self.daa_cfg = rc.daa_config() if rc is not None else DaaConfig()
        self.ground = None  #: with the pilot model: step 1, a :class:`daa_sil.ground.GroundCore` of one encounter
        if self.mode == "model":
            from daa_sil.ground import GroundCore
            from daa_sil.models.streams import STREAM_PILOT, encounter_streams
            from daa_sil.sil.scenario import ownship_state

            seed = encounter_streams(scenario.seed if scenario is not None else 0)[STREAM_PILOT]
            # the plan the pilot returns to after the conflict: the scenario ownship's initial course
            mode = scenario.pilot.response if scenario else "guendel"
            from daa_sil.config.readings import reading_for
            from daa_sil.models.pilot_config import PilotConfig

            # the configuration's pilot under its reading; without one, the study's default reading's pilot
            pcfg = rc.pilot_config(mode=mode) if rc is not None else reading_for().pilot_config(PilotConfig(mode=mode))
            # the same step-1 object fast-time runs for N encounters
            self.ground = GroundCore(1, [seed], pcfg, self.daa_cfg,
                                     plan=ownship_state(scenario) if scenario is not None else None)
            from daa_sil.daa import kernels

            kernels.get()  # load the compiled DAA before READY, not at the first conflict in realtime
        self._g_seen = math.nan
        self.seq = 0
        self.sent: list[dict] = []
        self.ticks = TickPeer("gcs", self.codec)  #: the tick protocol: ticks seen, skipped, acked (done), silence
        self.steps = 0
        self.stop = asyncio.Event()
        self._wall0: "float | None" = None
        self._t_sync = 0.0

    async def start(self) -> None:
        """Bind, then greet the vehicle side with a HEARTBEAT (a shim learns our address from it).

        Only datagrams from the ``--vehicle`` address (the shim or the vehicle) and only messages from
        the vehicle's system id are accepted; the rest is counted and dropped (no signing state change).
        """
        if self.vehicle_conn.listens:  # --vehicle udpin:HOST:PORT: listen there, answer who sends first
            self.ep = await open_endpoint(self.codec, self.vehicle_conn.addr, peer=None, learn_peer=True,
                                          lock_peer=True, allow_sysids=[VEHICLE_SYSID], name="daa-gcs",
                                          peer_label="--vehicle udpin: the first sender",
                                          drop_hint="the GCS takes telemetry only from the first vehicle that sent")
            return
        self.ep = await open_endpoint(self.codec, self.listen_conn.addr, peer=self.peer, learn_peer=False,
                                      allow_peers=[self.peer], allow_sysids=[VEHICLE_SYSID], name="daa-gcs",
                                      peer_label="--vehicle",
                                      drop_hint="if that is the vehicle (or the shim's GCS side), give its address "
                                                "as --vehicle: the GCS takes telemetry only from there")
        self.ep.send(self._heartbeat())

    @property
    def peer(self):
        """The vehicle side (``--vehicle``): fixed, or with ``udpin:`` the first address that sent."""
        if self._peer is None and self.ep is not None and self.ep.peer is not None:
            self._peer = tuple(self.ep.peer)
        return self._peer

    @property
    def local_address(self) -> str:
        return format_udp_address(self.ep.local_address)

    def close(self) -> None:
        if self.ep is not None:
            self.ep.close()

    # -- telemetry in ---------------------------------------------------------------------------
    def _enu(self, lat_e7: int, lon_e7: int, alt_mm: int) -> tuple:
        o = self.origin
        lat0, lon0, alt0 = (o.lat_deg, o.lon_deg, o.alt_m) if o is not None else (lat_e7 / 1e7, lon_e7 / 1e7, 0.0)
        x, y, z = geodetic_to_enu(lat_e7 / 1e7, lon_e7 / 1e7, alt_mm / 1000.0, lat0, lon0, alt0)
        return float(x), float(y), float(z)

    def handle(self, r: Received) -> None:
        """Take in one telemetry message (:meth:`gcs.view.View.take`); run it under ``self.ep.guard``."""
        ticks = self.ticks  # no genuine telemetry is newer than the newest tick
        self.view.take(r.msg, self._enu, origin_known=self.origin is not None,
                       newest_tick=ticks.newest_t if ticks.heard["vehicle"] else None)

    def take(self, r: Received) -> None:
        """One message from the vehicle side, under the guard: a tick steps the pilot, the rest is telemetry."""
        self.ep.guard.run(self._on_tick if r.msg.get_type() == "SIM_TICK" else self.handle, r)

    def observed(self) -> "tuple[AircraftState, AircraftState] | None":
        """Observed ownship (1,) and intruders (1, M) in scenario order, or None before telemetry."""
        v = self.view
        if v.own is None or not v.intruders:
            return None
        order = [i for i in self.order if i in v.intruders] or sorted(v.intruders)
        o = v.own
        own = AircraftState(*(np.array([val]) for val in o[1:]))
        arr = np.array([v.intruders[i] for i in order])
        intr = AircraftState(*(arr[None, :, k] for k in range(6)))
        return own, intr

    # -- pilot ------------------------------------------------------------------------------------
    def pilot_commands(self, t: float) -> list[dict]:
        """Commands (dicts: track_deg, vs_mps, gs_mps, kind) the pilot sends at sim time ``t``."""
        if self.mode == "scripted":
            out = []
            for c in (self.sc.pilot.commands if self.sc is not None else []):
                if c.t_s - 1e-9 <= t < c.until_s - 1e-9:
                    out.append({"track_deg": c.track_deg, "vs_mps": c.vs_mps, "gs_mps": c.gs_mps, "kind": "scripted"})
            return out[-1:]
        obs = self.observed()
        none = np.zeros(0, np.int64)
        if obs is None:  # nothing seen yet: the pilot steps on an unknown (nan) state, as in fast-time
            nan = np.full(1, np.nan)
            self.ground.step(t, AircraftState(nan, nan, nan, nan, nan, nan), None, none, none)
            return []
        own, intr = obs
        # the display is refreshed only when newer telemetry is seen (as in fast-time), with the alert
        # level the vehicle sent with that telemetry (DAA_ALERT)
        t_seen = self.view.own[0]
        fresh, alert = none, none
        if t_seen != self._g_seen:
            self._g_seen = t_seen
            level = self.view.alert[1] if self.view.alert[0] == t_seen else self.ground.display.alert[0]
            fresh, alert = np.array([0]), np.array([int(level)])
        po = self.ground.step(t, own, intr, fresh, alert)
        if not bool(po.send[0]):
            return []
        kind = "hold" if int(po.maneuver[0]) == 0 else f"maneuver{int(po.maneuver[0])}"
        trk = float(po.cmd.trk[0])
        return [{"track_deg": math.degrees(trk) % 360.0 if math.isfinite(trk) else math.nan,
                 "vs_mps": float(po.cmd.vs[0]), "gs_mps": float(po.cmd.gs[0]), "kind": kind,
                 "axis": str(po.axis_names()[0]), "dir": str(po.direction_names()[0])}]

    def _heartbeat(self):
        return M.MAVLink_heartbeat_message(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, M.MAV_STATE_ACTIVE, 3)

    def step(self, t: float) -> int:
        """Run the pilot at ``t`` (s) and send its commands plus a HEARTBEAT; returns messages sent."""
        msgs = [self._heartbeat()] + self._settings_due(t)
        for c in self.pilot_commands(t):
            self.seq += 1
            msgs.append(M.MAVLink_pilot_maneuver_message(int(round(t * 1000)), self.seq, VEHICLE_SYSID, 1,
                                                         c["track_deg"], c["vs_mps"], c["gs_mps"]))
            self.sent.append({"t": t, "seq": self.seq, "wall_s": round(time.time(), 3), **c})
        self.ep.send_many(msgs)
        self.steps += 1
        if self.opts.display:
            self.display(t, len(msgs) - 1)
        return len(msgs)

    def _settings_due(self, t: float) -> list:
        """PARAM_SET / DO_SET_MODE for the settings due at ``t``, after a SYSTEM_TIME that stamps their send
        time (the vehicle logs it with the arrival time)."""
        out = []
        while self.pending_settings and self.pending_settings[0][0] <= t + 1e-9:
            _, name, value = self.pending_settings.pop(0)
            if name == "MODE":
                out.append(M.MAVLink_command_long_message(VEHICLE_SYSID, 1, M.MAV_CMD_DO_SET_MODE, 0,
                                                          M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, float(value),
                                                          0, 0, 0, 0, 0))
            else:
                out.append(M.MAVLink_param_set_message(VEHICLE_SYSID, 1, name.encode("ascii"), float(value),
                                                       M.MAV_PARAM_TYPE_REAL32))
            self.sent.append({"t": t, "kind": "mode" if name == "MODE" else "param", "name": name,
                              "value": float(value), "wall_s": round(time.time(), 3)})
        if out:
            from daa_sil.link.plane import system_time

            out.insert(0, system_time(t))
        return out

    def display(self, t: float, n_cmd: int) -> None:
        from .display import render_line

        render_line(self, t, n_cmd)

    # -- loops ------------------------------------------------------------------------------------
    def request_stop(self) -> None:
        """Stop :meth:`run` (SIGINT / SIGTERM, ``--duration``): set :attr:`stop` and wake a loop waiting for a
        datagram, so the GCS ends now instead of after that wait (up to 0.1 s in lockstep, 0.5 s in realtime)."""
        self.stop.set()
        try:
            self.ep.inbox.put_nowait(None)  # type: ignore[arg-type]  (the loops skip it)
        except asyncio.QueueFull:  # a full inbox: the loop is not waiting, it sees the stop at its next message
            pass

    async def run(self) -> None:
        """Run until :attr:`stop` is set (lockstep: driven by ticks; realtime: by the wall clock)."""
        if self.opts.clock == "lockstep":
            await self._run_lockstep()
        else:
            await self._run_realtime()

    def _on_tick(self, r: Received) -> None:
        """``SIM_TICK(k, t_k)``: run step ``t_k`` if ``k`` is new (a repeated tick is only re-acked), then ack."""
        k, t = int(r.msg.tick), r.msg.time_ms / 1000.0
        step, back = self.ticks.on_tick(k, t, asyncio.get_running_loop().time())
        if back is not None:
            self._say(f"ticks from {self._peer_text()} are back at t = {t:g} s (silent for {back:.1f} s)")
        n = self.step(t) if step else 0
        self.ep.transport.sendto(self.ticks.ack(k, r.msg.time_ms, min(n, 65535)), self.peer)

    def _check_silence(self) -> None:
        """Report (once until they come back) ticks that stopped for the role's SILENT_AFTER_S."""
        for _, quiet in self.ticks.check_silence(asyncio.get_running_loop().time()):
            done = self.ticks.sent
            self._say(f"warning: no SIM_TICK from {self._peer_text()} for {quiet:.1f} s (last: tick "
                      f"{done}): has the vehicle (or the shim) stopped?")

    def _peer_text(self) -> str:
        return format_udp_address(self.peer) if self.peer is not None else self.vehicle_conn.text

    @staticmethod
    def _say(text: str) -> None:
        from daa_sil.sil.msgguard import stderr_line

        stderr_line(f"daa-gcs: {text}")  # (after the status lines gcs.display flushes in batches)

    async def _run_lockstep(self) -> None:
        inbox = self.ep.inbox
        while not self.stop.is_set():
            try:  # what already arrived first: a tick's datagrams come together, one wait per burst
                r = inbox.get_nowait()
            except asyncio.QueueEmpty:
                try:
                    r = await asyncio.wait_for(inbox.get(), 0.1)
                except asyncio.TimeoutError:
                    if self.ticks.sent < 0:  # nothing yet: greet again (a shim may have started after us)
                        self.ep.send(self._heartbeat())
                    self._check_silence()
                    continue
            if r is not None:  # None: request_stop's wake-up
                self.take(r)

    def sim_now(self, loop) -> "float | None":
        if self._wall0 is None:
            return None
        return self._t_sync + (loop.time() - self._wall0) * self.opts.speed

    async def _run_realtime(self) -> None:
        from daa_sil.sil.scenario import delay_models

        loop = asyncio.get_running_loop()
        assumed_down = delay_models(self.sc)[1].mean() if self.sc is not None else 0.0
        next_t = None
        while not self.stop.is_set():
            free = not self.ticks.heard["vehicle"]  # no ticks (yet): our own clock, synchronised on telemetry
            now = self.sim_now(loop) if free else None
            timeout = 0.2 if now is None or next_t is None else max(0.0, (next_t - now) / self.opts.speed)
            try:
                r = await asyncio.wait_for(self.ep.inbox.get(), min(timeout, 0.5))
                if r is None:  # request_stop's wake-up
                    continue
                self.take(r)
                if r.msg.get_type() == "SIM_TICK":
                    continue
                if self._wall0 is None and math.isfinite(self.view.last_t):
                    self._wall0, self._t_sync = loop.time(), self.view.last_t + assumed_down
                    # one sim second of grace: a vehicle that sends ticks has sent one by then
                    next_t = math.ceil(self._t_sync) + 1.0
                continue
            except asyncio.TimeoutError:
                self._check_silence()
                if not self.ticks.heard["vehicle"] and now is None:  # nothing yet: greet again (the shim may have started
                    self.ep.send(self._heartbeat())  # after us, or we were restarted and it must relearn us)
            if self.ticks.heard["vehicle"]:
                continue
            now = self.sim_now(loop)
            if now is not None and next_t is not None and now >= next_t - 1e-6:
                self.step(float(next_t))
                next_t += 1.0

    def write_log(self) -> "Path | None":
        """Write the commands sent (JSONL) atomically."""
        if self.opts.log is None:
            return None
        from daa_sil.files import atomic_write_text, to_jsonable

        text = "".join(json.dumps(to_jsonable(r), sort_keys=True) + "\n" for r in self.sent)
        return atomic_write_text(self.opts.log, text)
