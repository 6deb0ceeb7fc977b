"""What the vehicle does at a step boundary with what ground stations asked of it, sans-IO: settings
(parameters, modes), the pilot's commands through the command gate, injected traffic, and the
announcements of each (the protocol core, :mod:`vehicle.protocol`, queues them and calls in here).

* a **setting** (PARAM_SET, SET_MODE, DO_SET_MODE) from any output goes to
  :class:`vehicle.services.GcsServices` (which refuses a read-only output's); its answer waits for the
  peer's reply budget; an accepted one is announced to the other outputs' ground stations;
* a **pilot command** (PILOT_MANEUVER, SET_POSITION_TARGET_GLOBAL_INT, DO_REPOSITION) from the pilot's
  link goes through the :class:`vehicle.commands.CommandGate` into the simulation whatever the authority:
  the agent judges it at its next step (SM(u), Algorithm 1). From an observer it is refused (DENIED);
  while the vehicle boots, TEMPORARILY_REJECTED;
* **traffic** (an ADSB_VEHICLE sent to the vehicle, :mod:`vehicle.traffic`) from a writable output
  becomes a new intruder; from a read-only one, or while booting, it is refused with a STATUSTEXT.
  Each one is logged like a setting (kind ``traffic``).
"""

from __future__ import annotations

import math

from daa_sil.link.codec import mavlink as M
from daa_sil.sil.intake import Received
from daa_sil.sil.outputs import PILOT_LINK

from . import telemetry as T
from .commands import CommandGate, reposition_command, setpoint_command
from .ports import OutputLink, Outbox
from .services import SYSID, GcsServices, SettingEvent
from .traffic import intruder_from_adsb

VEHICLE_SYSID = SYSID  #: (the setting daa_sil.config.settings.VEHICLE_SYSID)
PILOT_MANEUVER_ID = M.MAVLINK_MSG_ID_PILOT_MANEUVER
#: setting writes printed per step (a flood of PARAM_SET is summed up in one line instead)
ANNOUNCED_PER_STEP = 20


def is_pilot_command(msg) -> bool:
    """PILOT_MANEUVER, SET_POSITION_TARGET_GLOBAL_INT, or a COMMAND_INT / COMMAND_LONG DO_REPOSITION."""
    mtype = msg.get_type()
    return mtype in ("PILOT_MANEUVER", "SET_POSITION_TARGET_GLOBAL_INT") or (
        mtype in ("COMMAND_INT", "COMMAND_LONG") and int(msg.command) == M.MAV_CMD_DO_REPOSITION)


def is_traffic(msg) -> bool:
    """An ADSB_VEHICLE sent to the vehicle: traffic to inject (:mod:`vehicle.traffic`)."""
    return msg.get_type() == "ADSB_VEHICLE"


class Orders:
    """The step boundary's handlers (see the module docstring). ``plant``: the simulation, or the
    :class:`vehicle.boot.BootPlant` while booting (the protocol swaps it); ``out``: where sends and lines go;
    ``stats``: the node's :class:`vehicle.node_options.VehicleStats`."""

    def __init__(self, plant, services: GcsServices, out: Outbox, stats):
        self.plant, self.services, self.out, self.stats = plant, services, out, stats
        self.gate = CommandGate()
        self.announced, self.unannounced = 0, 0  # setting lines printed / not printed this step

    def new_step(self, t: float) -> None:
        if self.unannounced:
            self.out.say(f"t={t:5.0f}s {self.unannounced} more setting writes (not printed)")
        self.announced, self.unannounced = 0, 0

    # -- settings ----------------------------------------------------------------------------------
    def setting(self, r: Received, out: OutputLink, outputs: "list[OutputLink]", now: float, t: float,
                t_sent: "float | None") -> None:
        """A setting, an observer's command or traffic from ``out`` (received at sim ``now``, applied at ``t``)."""
        msg = r.msg
        peer = out.peer_at(r.addr)
        if is_traffic(msg):
            return self.traffic(r, out, outputs, now, t, t_sent)
        if is_pilot_command(msg):  # a command must cross the delayed link: only the first --out flies
            self.stats.commands_from_observers_ignored += 1
            if msg.get_type().startswith("COMMAND") and peer is not None:
                peer.queue_reply([M.MAVLink_command_ack_message(msg.command, M.MAV_RESULT_DENIED, 0, 0,
                                                                msg.get_srcSystem(), msg.get_srcComponent())])
                self.stats.gcs_requests_answered += 1
            return
        n0 = len(self.services.events)
        replies = self.services.write(msg, out.name, now, t, t_sent)
        if replies and peer is not None:
            peer.queue_reply(replies)
            self.stats.gcs_requests_answered += 1
        for ev in self.services.events[n0:]:
            self.announce(ev, outputs)
        if self.services.events_unlogged:
            self.out.warn_once("events", f"more than {len(self.services.events)} setting writes: the rest are "
                                         f"applied and answered but not logged")

    def traffic(self, r: Received, out: OutputLink, outputs, now: float, t: float, t_sent) -> None:
        """An ADSB_VEHICLE sent to the vehicle: inject it (see the module docstring) or say why not."""
        msg = r.msg
        plant = self.plant
        icao = int(msg.ICAO_address)
        if out.name not in self.services.writable:
            status, reason = "denied_readonly", f"traffic {icao}: {out.name} is read-only"
        elif plant.booting:
            status, reason = "temporarily_rejected", f"traffic {icao}: the vehicle is booting"
        else:
            got = intruder_from_adsb(msg, plant.sc.origin, plant.own_position(), plant.icao, len(plant.icao))
            if isinstance(got, str):
                status, reason = "denied", got
            else:
                plant.inject_intruder(got)
                status, reason = "accepted", f"traffic {got.callsign} ({icao}) injected"
        ev = self.services.log_event(kind="traffic", name=str(icao), old=math.nan, new=float(icao), status=status,
                                     link=out.name, source=(msg.get_srcSystem(), msg.get_srcComponent()),
                                     t_received=now, t_applied=t, t_sent=t_sent, reason=reason)
        peer = out.peer_at(r.addr)
        if peer is not None:
            sev = M.MAV_SEVERITY_INFO if status == "accepted" else M.MAV_SEVERITY_WARNING
            peer.queue_reply([T.statustext(reason[:50], sev)])
        self.announce(ev, outputs)

    def announce(self, ev: SettingEvent, outputs: "list[OutputLink]") -> None:
        """A write: one console line, and an accepted one as a STATUSTEXT to the other outputs' stations too."""
        sent = f", sent t={ev.t_sent:g}s" if ev.t_sent is not None else ""
        if self.announced < ANNOUNCED_PER_STEP:
            self.announced += 1
            self.out.say(f"t={ev.t_applied:5.0f}s {ev.kind} {ev.name} {ev.status}: {ev.reason} (from {ev.link}, "
                         f"received t={ev.t_received:.1f}s{sent})")
        else:
            self.unannounced += 1
        if ev.status == "accepted":
            for o in outputs:
                if o.name != ev.link and o.name != PILOT_LINK:
                    for peer in o.peers.values():
                        peer.queue_reply([T.statustext(ev.reason[:50])])

    # -- pilot commands ----------------------------------------------------------------------------
    def pilot_command(self, r: Received, port: int, now: float, t: float) -> None:
        """A command from the pilot's link (received at sim ``now``): through the gate into the simulation, at
        step ``t``, whatever the authority (the agent judges it), with its acknowledgement."""
        msg = r.msg
        is_cmd = msg.get_type().startswith("COMMAND")
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        if is_cmd and msg.target_system not in (0, VEHICLE_SYSID):
            return
        if self.plant.booting:
            self.stats.commands_while_booting += 1
            if is_cmd:
                self.out.send(port, r.addr, [
                    M.MAVLink_command_ack_message(msg.command, M.MAV_RESULT_TEMPORARILY_REJECTED, 0, 0, *src),
                    T.statustext("command refused: the vehicle is booting")])
                self.stats.gcs_requests_answered += 1
            return
        if is_cmd:
            cmd = reposition_command(msg, self.plant.own_position(), self.plant.sc.origin, now, msg.get_seq())
        else:
            cmd = setpoint_command(msg, VEHICLE_SYSID)
        if cmd is None or isinstance(cmd, str):
            self.gate.counters.invalid += 1
            if is_cmd:
                self.out.send(port, r.addr, [M.MAVLink_command_ack_message(msg.command, M.MAV_RESULT_DENIED, 0, 0, *src),
                                             T.statustext(str(cmd)[:50] if cmd else "DO_REPOSITION: invalid")])
                self.stats.gcs_requests_answered += 1
            return
        ok = self.gate.offer(cmd, t)
        if ok:
            self.plant.add_command(cmd)
        if cmd.kind == "PILOT_MANEUVER" and ok:  # our dialect acknowledges with its cmd_seq
            self.out.send(port, r.addr, [T.command_ack(PILOT_MANEUVER_ID, M.MAV_RESULT_ACCEPTED, cmd.seq, *src)])
        elif is_cmd:
            self.out.send(port, r.addr, [M.MAVLink_command_ack_message(
                msg.command, M.MAV_RESULT_ACCEPTED if ok else M.MAV_RESULT_DENIED, 0, 0, *src)])
            self.stats.gcs_requests_answered += 1
        # SET_POSITION_TARGET_GLOBAL_INT: no COMMAND_ACK (not a command); POSITION_TARGET_GLOBAL_INT is the feedback
