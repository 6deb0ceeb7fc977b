"""What the vehicle answers to a ground station, as an ArduPlane would (no sockets, no clock).

:class:`GcsServices` takes one received message and returns the messages to send back. It is
split the way the timing needs it:

* **reads** (:meth:`GcsServices.is_read`, :meth:`GcsServices.read`): PARAM_REQUEST_LIST / _READ,
  TIMESYNC, PING, REQUEST_DATA_STREAM, MISSION_REQUEST_LIST, FILE_TRANSFER_PROTOCOL, and the
  COMMAND_LONG / COMMAND_INT that change nothing the simulation uses (REQUEST_MESSAGE,
  GET_HOME_POSITION, SET_ / GET_MESSAGE_INTERVAL, REQUEST_AUTOPILOT_CAPABILITIES, ARM / DISARM,
  unknown commands). Rates are per peer (the caller passes the peer's :class:`StreamRates`), so an
  observer asking for rates changes only its own stream. A PARAM_REQUEST_LIST is answered one
  :meth:`GcsServices.param_value` at a time by the caller (:mod:`vehicle.peers`: paced, one list in
  flight per peer). The protocol core answers reads as they arrive in realtime, at the step boundary
  in lockstep, within each peer's reply budget.
* **writes** (:meth:`GcsServices.write`): PARAM_SET, SET_MODE and DO_SET_MODE. A PARAM_SET changes
  the agent's policy, so the protocol applies writes only at a step boundary (the change holds from
  the step after arrival) and only from a link in ``writable``: the GCS link (through the shim,
  delayed like pilot commands), and observers marked writable (``--tap-writable``, ``--out
  CONN,rw``; :mod:`daa_sil.sil.outputs`). Mode requests change nothing the agent
  decides (:mod:`vehicle.identity`) but are answered and logged the same way. Each write is kept
  as a :class:`SettingEvent` for the step log (the first :data:`MAX_EVENTS`; the rest are counted).

Pilot commands (PILOT_MANEUVER, SET_POSITION_TARGET_GLOBAL_INT, COMMAND_INT DO_REPOSITION) are
the protocol core's (:mod:`vehicle.protocol`; they go through :class:`vehicle.commands.CommandGate`).
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Protocol

from daa_sil.config.settings import STEP, VEHICLE_SYSID
from daa_sil.link.codec import mavlink as M
from daa_sil.link.messages import wire_int

from . import identity as ident
from . import telemetry as T
from .params import ParamTable
from .streams import StreamRates, msg_name

if TYPE_CHECKING:
    from daa_sil.config.policy import AllocationPolicy

SYSID, COMPID = VEHICLE_SYSID.default, 1
CMD_ACK_FOR_SET_MODE = M.MAVLINK_MSG_ID_SET_MODE  #: ArduPilot acks the SET_MODE message with command = 11
FORCE_DISARM_MAGIC = 21196
FTP_OP_NACK, FTP_ERR_UNKNOWN_COMMAND = 129, 7
MAX_MSG_ID = 2**24 - 1  #: MAVLink 2 message ids are 24-bit
#: setting writes kept for the step log (a flood of PARAM_SET must not grow the vehicle's memory)
MAX_EVENTS = 10_000

_READ_COMMANDS = {M.MAV_CMD_REQUEST_MESSAGE, M.MAV_CMD_GET_HOME_POSITION, M.MAV_CMD_SET_MESSAGE_INTERVAL,
                  M.MAV_CMD_GET_MESSAGE_INTERVAL, M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES,
                  M.MAV_CMD_COMPONENT_ARM_DISARM}
_WRITE_COMMANDS = {M.MAV_CMD_DO_SET_MODE}
#: pilot commands that come as COMMAND_INT / COMMAND_LONG (handled by the node with the gate)
PILOT_COMMANDS = {M.MAV_CMD_DO_REPOSITION}
#: message types that only read (COMMAND_LONG / COMMAND_INT aside: those depend on their command)
READ_TYPES = {"PARAM_REQUEST_LIST", "PARAM_REQUEST_READ", "TIMESYNC", "PING", "REQUEST_DATA_STREAM",
               "MISSION_REQUEST_LIST", "FILE_TRANSFER_PROTOCOL"}
_WRITE_TYPES = {"PARAM_SET", "SET_MODE"}
#: a refused PARAM_SET's PARAM_ERROR code, by the refusal's status
PARAM_ERRORS = {"unknown": M.MAV_PARAM_ERROR_DOES_NOT_EXIST, "out_of_range": M.MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE,
                "not_integer": M.MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE, "read_only": M.MAV_PARAM_ERROR_READ_ONLY,
                "denied_readonly": M.MAV_PARAM_ERROR_PERMISSION_DENIED}


@dataclass
class SettingEvent:
    """One parameter or mode write as the step log keeps it (times are vehicle sim time, s)."""

    kind: str  #: "param", "mode" or "traffic" (an injected intruder: ``name`` its ICAO address)
    name: str
    old: float
    new: float
    status: str  #: accepted / unchanged / read_only / out_of_range / not_integer / unknown / denied_readonly / denied
    link: str  #: the output it came from: "gcs", "tap", "out2", ...
    source: tuple
    t_received: float
    t_applied: float
    t_sent: "float | None" = None  #: the sender's SYSTEM_TIME stamp in the same datagram, if any
    reason: str = ""

    def as_dict(self) -> dict:
        d = dict(self.__dict__)
        d["source"] = list(self.source)
        for k in ("old", "new"):
            d[k] = None if not math.isfinite(d[k]) else d[k]
        return d


def _targets_us(msg) -> bool:
    ts = getattr(msg, "target_system", 0)
    tc = getattr(msg, "target_component", 0)
    return ts in (0, SYSID) and tc in (0, COMPID)


def _text(s: str, severity: int = M.MAV_SEVERITY_INFO):
    return T.statustext(s[:50], severity)


def _ack(msg, command: int, result: int):
    return M.MAVLink_command_ack_message(int(command) & 0xFFFF, result, 0, 0, msg.get_srcSystem(), msg.get_srcComponent())


class Plant(Protocol):
    """What the services read from and write to the simulation (:class:`vehicle.core.VehicleCore` is one):
    the agent's policy, replaced by a PARAM_SET, and the flight mode the vehicle shows."""

    @property
    def policy(self) -> AllocationPolicy: ...

    def set_policy(self, policy: AllocationPolicy) -> None: ...

    def mode(self) -> int: ...


@dataclass
class GcsServices:
    """Parameter, mode, rate and request handling for one vehicle (see the module docstring).

    ``plant``: the simulation (its policy and mode); ``dt``: the step (sim s); ``writable``: the links
    (outputs) whose parameter and mode writes are applied, the others being read-only observers.
    Times come with each call: ``now`` the vehicle's sim time (s) of a read; ``t_applied`` the step a
    write holds from.
    """

    params: ParamTable
    plant: Plant
    dt: float = STEP.default
    writable: frozenset = frozenset({"gcs"})
    events: "list[SettingEvent]" = field(default_factory=list)
    answered: int = 0
    #: setting writes beyond :data:`MAX_EVENTS`: applied and answered, but not kept for the step log
    events_unlogged: int = 0

    # -- classification ------------------------------------------------------------------------------
    @staticmethod
    def is_read(msg) -> bool:
        t = msg.get_type()
        if t in ("COMMAND_LONG", "COMMAND_INT"):
            return int(msg.command) not in _WRITE_COMMANDS and int(msg.command) not in PILOT_COMMANDS
        return t in READ_TYPES

    @staticmethod
    def is_write(msg) -> bool:
        t = msg.get_type()
        if t in ("COMMAND_LONG", "COMMAND_INT"):
            return int(msg.command) in _WRITE_COMMANDS
        return t in _WRITE_TYPES

    # -- reads ---------------------------------------------------------------------------------------
    @staticmethod
    def is_param_list(msg) -> bool:
        """A PARAM_REQUEST_LIST for this vehicle (answered one PARAM_VALUE at a time: :meth:`param_value`)."""
        return msg.get_type() == "PARAM_REQUEST_LIST" and _targets_us(msg)

    def param_value(self, i: int):
        """PARAM_VALUE of parameter ``i`` (0 .. ``len(self.params) - 1``) now."""
        s = self.params.specs[i]
        return T.param_value(s.name, self.params.value(s, self.plant.policy), s.ptype, len(self.params), i)

    def read(self, msg, rates: StreamRates, now: float, latest: "dict[int, list]") -> list:
        """Answer a read request (see :meth:`is_read`; a PARAM_REQUEST_LIST: :meth:`param_value` one by one)
        from a peer whose stream rates are ``rates``, at sim time ``now`` (s); ``latest``: the newest step's
        telemetry ``{msg_id: [messages]}`` (REQUEST_MESSAGE answers with it). Never raises on content."""
        t = msg.get_type()
        out: list = []
        if t == "PARAM_REQUEST_READ":
            if _targets_us(msg):
                found = self.params.find(msg.param_id, int(msg.param_index))
                if found is None:
                    out = [_text(f"PARAM_REQUEST_READ: unknown parameter {str(msg.param_id)!r}", M.MAV_SEVERITY_WARNING)]
                else:
                    i, s = found
                    out = [T.param_value(s.name, self.params.value(s, self.plant.policy), s.ptype, len(self.params), i)]
        elif t == "TIMESYNC":
            if int(msg.tc1) == 0:  # a request; tc1 != 0 is someone's reply
                out = [M.MAVLink_timesync_message(int(now * 1e9), int(msg.ts1))]
        elif t == "PING":
            if int(msg.target_system) == 0 and int(msg.target_component) == 0:  # a request
                out = [M.MAVLink_ping_message(int(msg.time_usec), int(msg.seq), msg.get_srcSystem(), msg.get_srcComponent())]
        elif t == "REQUEST_DATA_STREAM":
            if _targets_us(msg):
                note = rates.request_data_stream(msg.req_stream_id, float(msg.req_message_rate),
                                                                 bool(msg.start_stop), now)
                out = [_text(note)] if note else []
        elif t == "MISSION_REQUEST_LIST":
            if _targets_us(msg):
                out = [M.MAVLink_mission_count_message(msg.get_srcSystem(), msg.get_srcComponent(), 0,
                                                       getattr(msg, "mission_type", 0))]
        elif t == "FILE_TRANSFER_PROTOCOL":
            out = self._ftp_nak(msg)
        elif t in ("COMMAND_LONG", "COMMAND_INT"):
            out = self._command_read(msg, rates, now, latest)
        if out:
            self.answered += 1
        return out

    def _ftp_nak(self, msg) -> list:
        """No FTP here: NAK every request (UnknownCommand) so clients fall back to the parameter protocol."""
        if int(msg.target_system) not in (0, SYSID) or int(msg.target_component) not in (0, COMPID):
            return []
        p = bytes(msg.payload)
        if len(p) < 12:
            return []
        seq, session, opcode = struct.unpack_from("<HBB", p, 0)
        reply = struct.pack("<HBBBBBBI", (seq + 1) & 0xFFFF, session, FTP_OP_NACK, 1, opcode, 0, 0, 0)
        reply += bytes([FTP_ERR_UNKNOWN_COMMAND])
        reply += bytes(251 - len(reply))
        return [M.MAVLink_file_transfer_protocol_message(0, msg.get_srcSystem(), msg.get_srcComponent(), list(reply))]

    def _command_read(self, msg, rates: StreamRates, now: float, latest: dict) -> list:
        if not _targets_us(msg):
            return []
        c = int(msg.command)
        p1, p2 = float(msg.param1), float(msg.param2)
        if c in (M.MAV_CMD_REQUEST_MESSAGE, M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAV_CMD_GET_MESSAGE_INTERVAL):
            # a message id in a float: NaN, inf, a fraction or out of range is refused, never int()-ed
            hi = 0xFFFF if c == M.MAV_CMD_GET_MESSAGE_INTERVAL else MAX_MSG_ID  # MESSAGE_INTERVAL: uint16 id
            if wire_int(p1, 0, hi) is None:
                return [_ack(msg, c, M.MAV_RESULT_DENIED), _text(f"message id {p1!r} invalid", M.MAV_SEVERITY_WARNING)]
        if c == M.MAV_CMD_REQUEST_MESSAGE or c == M.MAV_CMD_GET_HOME_POSITION \
                or c == M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
            mid = (M.MAVLINK_MSG_ID_HOME_POSITION if c == M.MAV_CMD_GET_HOME_POSITION else
                   M.MAVLINK_MSG_ID_AUTOPILOT_VERSION if c == M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES else int(p1))
            msgs = self._one_shot(mid, rates, latest)
            if msgs is None:
                return [_ack(msg, c, M.MAV_RESULT_UNSUPPORTED),
                        _text(f"REQUEST_MESSAGE: {msg_name(mid)} is not produced here", M.MAV_SEVERITY_WARNING)]
            return [_ack(msg, c, M.MAV_RESULT_ACCEPTED)] + msgs
        if c == M.MAV_CMD_SET_MESSAGE_INTERVAL:
            result, note = rates.set_interval(int(p1), p2, now)
            sev = M.MAV_SEVERITY_INFO if result == M.MAV_RESULT_ACCEPTED else M.MAV_SEVERITY_WARNING
            return [_ack(msg, c, result)] + ([_text(note, sev)] if note else [])
        if c == M.MAV_CMD_GET_MESSAGE_INTERVAL:
            mid = int(p1)
            return [_ack(msg, c, M.MAV_RESULT_ACCEPTED), T.message_interval(mid, rates.interval_us(mid))]
        if c == M.MAV_CMD_COMPONENT_ARM_DISARM:
            if p1 == 1.0:
                return [_ack(msg, c, M.MAV_RESULT_ACCEPTED), _text("Arm: already armed (airborne)")]
            forced = p2 == FORCE_DISARM_MAGIC  # compared as floats: int(NaN) raised here (issue 20 §1)
            return [_ack(msg, c, M.MAV_RESULT_FAILED),
                    _text("Disarm refused: airborne" + (" (forced too)" if forced else ""), M.MAV_SEVERITY_WARNING)]
        return [_ack(msg, c, M.MAV_RESULT_UNSUPPORTED)]

    def _one_shot(self, mid: int, rates: StreamRates, latest: dict) -> "list | None":
        if mid == M.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            return [T.autopilot_version()]
        if mid in latest and latest[mid]:
            return list(latest[mid])
        if rates.request_once(mid):
            return []  # streamed, but no step yet: it goes out with the first step
        return None

    # -- writes --------------------------------------------------------------------------------------
    def write(self, msg, link: str, t_received: float, t_applied: float, t_sent: "float | None" = None) -> list:
        """Apply a PARAM_SET / SET_MODE / DO_SET_MODE from ``link`` now (call at a step boundary: it holds
        from the step at ``t_applied``, sim s); returns the replies."""
        t = msg.get_type()
        when = (t_received, t_applied, t_sent)
        if t == "PARAM_SET":
            return self._param_set(msg, link, *when)
        if t == "SET_MODE":
            if int(msg.target_system) not in (0, SYSID):
                return []
            return self._mode(msg, CMD_ACK_FOR_SET_MODE, int(msg.base_mode), int(msg.custom_mode), link, *when)
        if t in ("COMMAND_LONG", "COMMAND_INT") and int(msg.command) == M.MAV_CMD_DO_SET_MODE and _targets_us(msg):
            base, custom = wire_int(msg.param1, 0, 0xFF), wire_int(msg.param2, 0, 2**32 - 1)
            if base is None or custom is None:  # base_mode is a uint8, custom_mode a uint32
                return [_ack(msg, M.MAV_CMD_DO_SET_MODE, M.MAV_RESULT_DENIED),
                        _text(f"DO_SET_MODE: mode {float(msg.param1)!r}, {float(msg.param2)!r} invalid",
                              M.MAV_SEVERITY_WARNING)]
            return self._mode(msg, M.MAV_CMD_DO_SET_MODE, base, custom, link, *when)
        return []

    def log_event(self, **kw) -> SettingEvent:
        """Keep one write for the step log (the first :data:`MAX_EVENTS`; the rest are counted)."""
        ev = SettingEvent(**kw)
        if len(self.events) < MAX_EVENTS:
            self.events.append(ev)
        else:
            self.events_unlogged += 1
        return ev

    def _param_set(self, msg, link, t_received, t_applied, t_sent) -> list:
        if not _targets_us(msg):
            return []
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        pol = self.plant.policy
        res = self.params.set(msg.param_id, float(msg.param_value), pol)
        name = res.spec.name if res.spec is not None else str(msg.param_id).split("\0", 1)[0]
        status, reason = res.status, res.reason
        if link not in self.writable and res.spec is not None:
            status, reason = "denied_readonly", f"{name}: {link} is read-only"
        elif res.status == "accepted":
            self.plant.set_policy(res.policy)
        value = res.value if status in ("accepted", "unchanged") else res.old
        self.log_event(kind="param", name=name, old=res.old, new=value, status=status, link=link,
                  source=src, t_received=t_received, t_applied=t_applied, t_sent=t_sent, reason=reason)
        out = []
        error = PARAM_ERRORS.get(status)
        if error is not None:  # the refusal first: a client that reads PARAM_ERROR completes on it (MAVSDK)
            i = self.params.find(name)[0] if res.spec is not None else -1
            out.append(M.MAVLink_param_error_message(*src, name.encode("ascii", "replace")[:16], i, error))
        if res.spec is not None:
            i, _ = self.params.find(name)
            out.append(T.param_value(res.spec.name, value, res.spec.ptype, len(self.params), i))
        if status != "unchanged":
            sev = M.MAV_SEVERITY_INFO if status == "accepted" else M.MAV_SEVERITY_WARNING
            out.append(_text(reason, sev))
        self.answered += 1
        return out

    def _mode(self, msg, ack_cmd, base, custom, link, t_received, t_applied, t_sent) -> list:
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        current = int(self.plant.mode())
        result, reason = ident.mode_request(base, custom, current)
        status = {M.MAV_RESULT_ACCEPTED: "accepted", M.MAV_RESULT_TEMPORARILY_REJECTED: "temporarily_rejected"}.get(
            result, "denied")
        if link not in self.writable:
            result, status, reason = M.MAV_RESULT_DENIED, "denied_readonly", f"mode: {link} is read-only"
        self.log_event(kind="mode", name=ident.mode_name(custom), old=float(current), new=float(current), status=status,
                  link=link, source=src, t_received=t_received, t_applied=t_applied, t_sent=t_sent, reason=reason)
        self.answered += 1
        sev = M.MAV_SEVERITY_INFO if result == M.MAV_RESULT_ACCEPTED else M.MAV_SEVERITY_WARNING
        return [_ack(msg, ack_cmd, result), _text(reason, sev)]
