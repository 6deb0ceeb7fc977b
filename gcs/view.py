"""What the remote pilot sees: the newest telemetry the GCS took in (:class:`View`), and the rules for
taking a message in (hostile input is counted in ``View.rejected``, never shown to the pilot)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, NamedTuple

from daa_sil.agent.decision import AUTHORITY_NAMES, DECISION_NAMES  # the wire codes are the agent's (link/messages.py)
from daa_sil.geometry.kinematics import state_in_bounds
from daa_sil.link.codec import mavlink as M

#: DAIDALUS alert levels the DAA_ALERT value may take (0 none ... 3 warning)
ALERT_LEVELS = range(4)
#: a telemetry stamp may be at most this far (s) after the newest SIM_TICK: one step
TICK_SLACK_S = 1.0


@dataclass
class View:
    """The newest telemetry the GCS has (vehicle sim times in s)."""

    own: "tuple | None" = None  #: (t, x, y, z, gs, trk, vs) ENU
    intruders: dict = field(default_factory=dict)  #: icao -> (x, y, z, gs, trk, vs)
    callsigns: dict = field(default_factory=dict)
    authority: str = "?"
    decision: str = "?"
    wait_s: float = math.nan
    alert_regions: int = 0
    alert: tuple = (math.nan, 0)  #: (vehicle sim time, DAIDALUS alert level 0-3) from DAA_ALERT
    last_t: float = -math.inf
    #: telemetry messages dropped: not physical (non-finite, beyond STATE_BOUNDS, latitude / longitude /
    #: heading / alert level out of range), older than the newest seen, or stamped after the newest tick
    rejected: int = 0
    acks: int = 0
    statustext: list = field(default_factory=list)
    mode: str = "?"  #: the vehicle's flight mode name (HEARTBEAT custom_mode, ArduPlane numbering)
    params: dict = field(default_factory=dict)  #: parameter name -> value, from PARAM_VALUE
    fresh: bool = True  #: the last position message was taken (ADS-B in its datagram follows it)

    def take(self, m, enu: Callable, origin_known: bool = True, newest_tick: "float | None" = None) -> None:
        """Take in message ``m`` from the vehicle; ``enu(lat_e7, lon_e7, alt_mm) -> (x, y, z)`` m;
        ``newest_tick``: sim time of the newest SIM_TICK (s), None when no tick drives the GCS. A type
        outside :data:`READ_TYPES` changes nothing."""
        handler = _HANDLERS.get(m.get_type())
        if handler is not None:
            handler(self, m, _Given(enu, origin_known, newest_tick))

    def _local_position(self, m, g: "_Given") -> None:
        tm = m.time_boot_ms / 1000.0
        n, e, d, vn, ve, vd = (float(m.x), float(m.y), float(m.z), float(m.vx), float(m.vy), float(m.vz))
        self.fresh = state_in_bounds(e, n, -d, ve, vn, -vd) and not tm < self.last_t and not g.future(tm)
        if not self.fresh:
            self.rejected += 1
            return
        self.own = (tm, e, n, -d, math.hypot(vn, ve), math.atan2(ve, vn) % (2 * math.pi), -vd)
        self.last_t = tm

    def _adsb(self, m, g: "_Given") -> None:
        if not self.fresh:  # rides in a datagram whose position was rejected
            self.rejected += 1
            return
        if not m.flags & M.ADSB_FLAGS_VALID_COORDS:
            return
        gs, trk, vs = m.hor_velocity / 100.0, math.radians(m.heading / 100.0), m.ver_velocity / 100.0
        ok = lat_lon_ok(m.lat, m.lon) and 0 <= m.heading <= 36000
        x, y, z = g.enu(m.lat, m.lon, m.altitude) if ok else (math.nan,) * 3
        if not (ok and state_in_bounds(x, y, z, gs * math.sin(trk), gs * math.cos(trk), vs)):
            self.rejected += 1
            return
        self.intruders[int(m.ICAO_address)] = (x, y, z, gs, trk, vs)
        self.callsigns[int(m.ICAO_address)] = m.callsign

    def _alert(self, m, g: "_Given") -> None:
        if m.name != "DAA_ALERT":
            return
        ta = m.time_boot_ms / 1000.0
        if ta < self.alert[0] or int(m.value) not in ALERT_LEVELS or g.future(ta):
            self.rejected += 1  # older than the level shown, not an alert level, or from the future
            return
        self.alert = (ta, int(m.value))

    def _global_position(self, m, g: "_Given") -> None:
        if not (g.origin_known and self.own is None):
            return
        vn, ve, vs = m.vx / 100.0, m.vy / 100.0, -m.vz / 100.0
        ok = lat_lon_ok(m.lat, m.lon) and not g.future(m.time_boot_ms / 1000.0)
        x, y, z = g.enu(m.lat, m.lon, m.alt) if ok else (math.nan,) * 3
        if not (ok and state_in_bounds(x, y, z, ve, vn, vs)):
            self.rejected += 1
            return
        self.own = (m.time_boot_ms / 1000.0, x, y, z, math.hypot(vn, ve), math.atan2(ve, vn) % (2 * math.pi), vs)

    def _decision(self, m, g: "_Given") -> None:
        self.authority = AUTHORITY_NAMES[m.authority] if m.authority < len(AUTHORITY_NAMES) else "?"
        self.decision = DECISION_NAMES[m.decision] if m.decision < len(DECISION_NAMES) else "?"
        self.wait_s = m.wait_s

    def _bands(self, m, g: "_Given") -> None:
        if m.part == 0:
            regions = m.region[:min(m.count, len(m.region))]
            self.alert_regions = max([int(x) for x in regions if int(x) in (1, 2, 3)] or [0])

    def _ack(self, m, g: "_Given") -> None:
        self.acks += 1

    def _heartbeat(self, m, g: "_Given") -> None:
        if m.get_srcComponent() == 1:
            from daa_sil.link.plane import mode_name  # lazy: start-up time

            self.mode = mode_name(m.custom_mode)

    def _param(self, m, g: "_Given") -> None:
        self.params[str(m.param_id)] = float(m.param_value)

    def _statustext(self, m, g: "_Given") -> None:
        self.statustext = (self.statustext + [m.text])[-5:]


class _Given(NamedTuple):
    """What :meth:`View.take` is given besides the message."""

    enu: Callable
    origin_known: bool
    newest_tick: "float | None"

    def future(self, t_s: float) -> bool:
        """Lockstep / ticks: no genuine message is newer than the newest tick (plus one step)."""
        return self.newest_tick is not None and t_s > self.newest_tick + TICK_SLACK_S + 1e-9


#: the handler of each message type the view reads: the one list of the telemetry the GCS reads
_HANDLERS: "dict[str, Callable]" = {
    "LOCAL_POSITION_NED": View._local_position, "ADSB_VEHICLE": View._adsb, "NAMED_VALUE_INT": View._alert,
    "GLOBAL_POSITION_INT": View._global_position, "ALLOCATION_DECISION": View._decision, "DAA_BANDS": View._bands,
    "COMMAND_ACK": View._ack, "HEARTBEAT": View._heartbeat, "PARAM_VALUE": View._param,
    "STATUSTEXT": View._statustext,
}
#: the message types :meth:`View.take` reads, and their ids
READ_TYPES = frozenset(_HANDLERS)
READ_IDS = frozenset(getattr(M, f"MAVLINK_MSG_ID_{name}") for name in READ_TYPES)


def lat_lon_ok(lat_e7: int, lon_e7: int) -> bool:
    """degE7 latitude / longitude within [-90, 90] / [-180, 180] deg."""
    return abs(lat_e7) <= 900_000_000 and abs(lon_e7) <= 1_800_000_000
