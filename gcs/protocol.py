"""The GCS's MAVLink protocol, sans-IO: datagrams in; sends, steps and console lines out.

:class:`GcsProtocol` never reads a clock or touches a socket. The node (:mod:`gcs.node`) hands it
each datagram with :meth:`GcsProtocol.receive` (sender, arrival time), calls :meth:`GcsProtocol.on_idle`
when its timer fires, sends what :meth:`GcsProtocol.take_sends` returns and shows what
:meth:`GcsProtocol.take_events` returns (:class:`Stepped`: a status line; :class:`Notice`: a warning).

Per step ``k`` at sim time ``t_k`` (``docs/architecture.md`` step 1):

* **ticks** (lockstep; realtime behind a vehicle that sends them): on ``SIM_TICK(k, t_k)`` (forwarded
  by the shim after it released every packet due at ``t_k``) the pilot runs on what the GCS has
  taken in, the GCS sends its command(s) and a HEARTBEAT (one datagram), then ``SIM_TICK_ACK(k)``
  alone in its datagram. A repeated tick is re-acknowledged without stepping again. The tick
  protocol's state is a :class:`daa_sil.sil.lockstep.TickPeer`.
* **free-running** (realtime, a vehicle that sends no ticks): the GCS's own clock, synchronised on
  the first telemetry message (``t = time_boot_ms + assumed downlink delay``) and advanced with the
  wall clock x ``speed``, stepping at every whole sim second (off by the difference between the
  first packet's delay and the assumed one: no lockstep parity).

Ticks that stop after they came (``SILENT_AFTER_S["gcs"]``, :mod:`daa_sil.sil.silence`) are reported.
Hostile input: only the vehicle side's address and system id are accepted (the
:class:`daa_sil.sil.intake.Intake`); every message is handled under its guard; telemetry the pilot
would see is taken only if physical, not older than what the pilot sees and, when ticks drive the
GCS, not stamped after the newest tick (:class:`gcs.view.View`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

from daa_sil.config.settings import VEHICLE_SYSID as VEHICLE_SYSTEM
from daa_sil.geometry.frames import geodetic_to_enu
from daa_sil.link.codec import MavCodec
from daa_sil.link.codec import mavlink as M
from daa_sil.sil.intake import Address, Intake, Received, format_udp_address
from daa_sil.sil.lockstep import TickPeer

from .pilot import CommandSent, ScheduledSetting, SettingSent
from .view import READ_IDS as VIEW_READS, View

#: every message id the GCS reads: the telemetry its view takes in, and the lockstep tick; its codec
#: verifies the rest of the vehicle's stream and counts it as ``unread`` without unpacking it
READ_IDS = VIEW_READS | {M.MAVLINK_MSG_ID_SIM_TICK}
GCS_SYSID, GCS_COMPID = 255, 190
VEHICLE_SYSID = VEHICLE_SYSTEM.default
#: wall seconds between the idle checks of a lockstep GCS (greeting, silence)
LOCKSTEP_IDLE_S = 0.1
#: free-running: longest wait between checks (s), and before the clock is synchronised
FREE_IDLE_MAX_S, FREE_IDLE_UNSYNCED_S = 0.5, 0.2


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
    #: settings to send (:class:`gcs.pilot.ScheduledSetting`: sim time s, NAME, value; NAME ``MODE`` sends
    #: DO_SET_MODE with the mode number as value)
    settings: "tuple[ScheduledSetting, ...]" = ()
    #: ``--config``: a :class:`daa_sil.config.run_config.RunConfig` whose ``daa`` changes shape the
    #: pilot's display and whose ``pilot`` changes the pilot model (None = the scenario alone)
    config: "object | None" = None


class Send(NamedTuple):
    """One datagram to ``addr``: ``messages`` packets, counted in the socket's ``sent`` unless not ``counted``."""

    addr: Address
    data: bytes
    messages: int
    counted: bool = True


class Stepped(NamedTuple):
    """The GCS ran its step at ``t`` (sim s) and sent ``n_cmd`` commands and settings (a status line)."""

    t: float
    n_cmd: int


class Notice(NamedTuple):
    """A warning line (``daa-gcs:`` in front)."""

    text: str


class GcsProtocol:
    """The GCS (see the module docstring). ``pilot``: a :class:`gcs.pilot.ModelPilot` or ``ScriptedPilot``;
    ``intake``: the receiving rules of its socket (the vehicle side only); ``assumed_down_s``: the
    downlink delay assumed when synchronising a free-running clock (s); ``wall_offset``: UNIX time minus
    the caller's clock, for the command log's wall times."""

    def __init__(self, sc, opts: GcsOptions, codec: MavCodec, intake: Intake, pilot, *,
                 assumed_down_s: float = 0.0, wall_offset: float = 0.0):
        self.sc, self.opts, self.codec, self.intake, self.pilot = sc, opts, codec, intake, pilot
        self.lockstep = opts.clock == "lockstep"
        self.assumed_down_s, self.wall_offset = float(assumed_down_s), float(wall_offset)
        self.pending_settings = sorted((ScheduledSetting(*s) for s in opts.settings), key=lambda s: s.t)
        self.view = View()
        self.origin = sc.origin if sc is not None else None
        self.order = [i.id for i in sc.intruders] if sc is not None else []
        self.seq = 0
        self.sent: "list[CommandSent | SettingSent]" = []
        self.ticks = TickPeer("gcs", codec)  #: the tick protocol: ticks seen, skipped, acked (done), silence
        self.steps = 0
        self._wall0: "float | None" = None  # free-running: the wall time (s) of t_sync
        self._t_sync = 0.0
        self.next_t: "float | None" = None  # free-running: the next step's sim time (s)
        self._sends: "list[Send]" = []
        self._events: list = []

    # -- what goes out ---------------------------------------------------------------------------
    def take_sends(self) -> "list[Send]":
        out, self._sends = self._sends, []
        return out

    def take_events(self) -> list:
        """:class:`Stepped` and :class:`Notice` events, in order (the list is emptied)."""
        out, self._events = self._events, []
        return out

    @property
    def peer(self) -> "Address | None":
        """The vehicle side (``--vehicle``): fixed, or with ``udpin:`` the first address that sent."""
        return self.intake.peer

    def peer_text(self) -> str:
        return format_udp_address(self.peer) if self.peer is not None else self.opts.vehicle

    def _send(self, msgs: list) -> None:
        if self.peer is None:
            self.intake.counters.send_no_peer += 1
            return
        self._sends.append(Send(self.peer, self.codec.encode_many(msgs), len(msgs)))

    def _warn(self, text: str) -> None:
        self._events.append(Notice(text))

    def heartbeat(self):
        return M.MAVLink_heartbeat_message(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, M.MAV_STATE_ACTIVE, 3)

    def greet(self) -> None:
        """A HEARTBEAT to the vehicle side (a shim learns the GCS's address from it)."""
        self._send([self.heartbeat()])

    # -- receiving -------------------------------------------------------------------------------
    def receive(self, data: bytes, addr: Address, now: float) -> None:
        """One datagram from ``addr`` at wall ``now`` (s): a tick steps the pilot, the rest is telemetry."""
        for r in self.intake.receive(data, addr, now):
            self.intake.counters.received += 1
            tick = r.msg.get_type() == "SIM_TICK"
            self.intake.guard.run(self._on_tick if tick else self.handle, r)
            if not tick and not self.lockstep:
                self._sync(r.t)

    def handle(self, r: Received) -> None:
        """Take in one telemetry message (:meth:`gcs.view.View.take`); run it under the guard."""
        ticks = self.ticks  # no genuine telemetry is newer than the newest tick
        self.view.take(r.msg, self._enu, origin_known=self.origin is not None,
                       newest_tick=ticks.newest_t if ticks.heard["vehicle"] else None)

    def _enu(self, lat_e7: int, lon_e7: int, alt_mm: int) -> tuple:
        o = self.origin
        lat0, lon0, alt0 = (o.lat_deg, o.lon_deg, o.alt_m) if o is not None else (lat_e7 / 1e7, lon_e7 / 1e7, 0.0)
        x, y, z = geodetic_to_enu(lat_e7 / 1e7, lon_e7 / 1e7, alt_mm / 1000.0, lat0, lon0, alt0)
        return float(x), float(y), float(z)

    def _on_tick(self, r: Received) -> None:
        """``SIM_TICK(k, t_k)``: run step ``t_k`` if ``k`` is new (a repeated tick is only re-acked), then ack."""
        k, t = int(r.msg.tick), r.msg.time_ms / 1000.0
        step, back = self.ticks.on_tick(k, t, r.t)
        if back is not None:
            self._warn(f"ticks from {self.peer_text()} are back at t = {t:g} s (silent for {back:.1f} s)")
        n = self.step(t, r.t) if step else 0
        if self.peer is not None:
            self._sends.append(Send(self.peer, self.ticks.ack(k, r.msg.time_ms, min(n, 65535)), 1, counted=False))

    # -- the pilot's step ------------------------------------------------------------------------
    def step(self, t: float, now: float) -> int:
        """Run the pilot at ``t`` (s; wall ``now``) and send its commands plus a HEARTBEAT; returns messages sent."""
        wall = round(now + self.wall_offset, 3)
        msgs = [self.heartbeat()] + self._settings_due(t, wall)
        for o in self.pilot.orders(t, self.view, self.order):
            self.seq += 1
            msgs.append(M.MAVLink_pilot_maneuver_message(int(round(t * 1000)), self.seq, VEHICLE_SYSID, 1,
                                                         o.track_deg, o.vs_mps, o.gs_mps))
            self.sent.append(CommandSent(t, self.seq, wall, o))
        self._send(msgs)
        self.steps += 1
        if self.opts.display:
            self._events.append(Stepped(t, len(msgs) - 1))
        return len(msgs)

    def _settings_due(self, t: float, wall: float) -> list:
        """PARAM_SET / DO_SET_MODE for the settings due at ``t``, after a SYSTEM_TIME that stamps their send
        time (the vehicle logs it with the arrival time)."""
        out = []
        while self.pending_settings and self.pending_settings[0].t <= t + 1e-9:
            _, name, value = self.pending_settings.pop(0)
            if name == "MODE":
                out.append(M.MAVLink_command_long_message(VEHICLE_SYSID, 1, M.MAV_CMD_DO_SET_MODE, 0,
                                                          M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, float(value),
                                                          0, 0, 0, 0, 0))
            else:
                out.append(M.MAVLink_param_set_message(VEHICLE_SYSID, 1, name.encode("ascii"), float(value),
                                                       M.MAV_PARAM_TYPE_REAL32))
            self.sent.append(SettingSent(t, "mode" if name == "MODE" else "param", name, float(value), wall))
        if out:
            from daa_sil.link.plane import system_time  # lazy: start-up time

            out.insert(0, system_time(t))
        return out

    # -- timers ----------------------------------------------------------------------------------
    def _sync(self, now: float) -> None:
        """Free-running: start the own clock on the first telemetry (one sim second of grace: a vehicle that
        sends ticks has sent one by then)."""
        if self._wall0 is None and math.isfinite(self.view.last_t):
            self._wall0, self._t_sync = now, self.view.last_t + self.assumed_down_s
            self.next_t = math.ceil(self._t_sync) + 1.0

    def sim_now(self, now: float) -> "float | None":
        """Free-running sim time (s) at wall ``now``; None before the clock is synchronised."""
        if self._wall0 is None:
            return None
        return self._t_sync + (now - self._wall0) * self.opts.speed

    def idle_timeout(self, now: float) -> float:
        """Wall seconds until :meth:`on_idle` is due (the node's timer)."""
        if self.lockstep:
            return LOCKSTEP_IDLE_S
        sim = self.sim_now(now) if not self.ticks.heard["vehicle"] else None
        timeout = FREE_IDLE_UNSYNCED_S if sim is None or self.next_t is None else max(
            0.0, (self.next_t - sim) / self.opts.speed)
        return min(timeout, FREE_IDLE_MAX_S)

    def on_idle(self, now: float) -> None:
        """The node's timer at wall ``now`` (s): report silent ticks; greet until the first tick (a shim may have
        started after us, or we were restarted and it must relearn us); free-running, step when due."""
        self.check_silence(now)
        if self.lockstep:
            if self.ticks.sent < 0:
                self.greet()
            return
        if self.ticks.heard["vehicle"]:
            return
        sim = self.sim_now(now)
        if sim is None:
            self.greet()
        elif self.next_t is not None and sim >= self.next_t - 1e-6:
            self.step(float(self.next_t), now)
            self.next_t += 1.0

    def check_silence(self, now: float) -> None:
        """Report (once until they come back) ticks that stopped for the role's SILENT_AFTER_S."""
        for _, quiet in self.ticks.check_silence(now):
            self._warn(f"warning: no SIM_TICK from {self.peer_text()} for {quiet:.1f} s (last: tick "
                       f"{self.ticks.sent}): has the vehicle (or the shim) stopped?")
