"""Per-link telemetry rates in sim time: defaults like ArduPilot SITL's, SET_MESSAGE_INTERVAL and
REQUEST_DATA_STREAM (sans-IO; the node keeps one :class:`StreamRates` per link, peer and tap).

Sim time advances in steps of ``dt`` (1 s), and a message carries the state of a step, so no
message can usefully go out faster than once per step. Hence:

* defaults: every message once per step (ArduPlane's SITL defaults are 1 Hz for each stream group;
  its 5 Hz ADS-B default is above the sim rate, so once per step too); HEARTBEAT fixed at 1 Hz;
  HOME_POSITION once at the first step and on request (as ArduPilot: sent when home is set);
* ``SET_MESSAGE_INTERVAL`` with an interval shorter than ``dt`` is **accepted**, as ArduPilot SITL
  accepts it and streams as fast as it can: here that is once per step, and a STATUSTEXT says so
  (a GCS that gets DENIED reports an error); GET_MESSAGE_INTERVAL then reports the interval used
  (``dt``). An interval >= ``dt`` is honoured in sim time (the message goes out at the first step at
  or after the due time); -1 stops it, 0 restores the default; longer than MESSAGE_INTERVAL's int32
  can report (2,147 s) is DENIED. HEARTBEAT stays at 1 Hz: a faster request is accepted (it is
  once per step already), a slower one or -1 DENIED;
* ``REQUEST_DATA_STREAM`` (no ACK exists) above ``1 / dt`` is clamped to once per step and a
  STATUSTEXT says so; rate 0 or ``start_stop`` 0 stops the group. Groups as ArduPilot's:
  EXTENDED_STATUS (SYS_STATUS, GPS_RAW_INT, POSITION_TARGET_GLOBAL_INT, EXTENDED_SYS_STATE),
  POSITION (GLOBAL_POSITION_INT, LOCAL_POSITION_NED), EXTRA1 (ATTITUDE), EXTRA2 (VFR_HUD), EXTRA3
  (SYSTEM_TIME); ALL = all of them. ADS-B and the DAA messages are set per message only.

Everything is decided on sim time, so a lockstep run stays deterministic.
"""

from __future__ import annotations

import math

from daa_sil.config.settings import STEP
from daa_sil.link.codec import mavlink as M

HEARTBEAT = M.MAVLINK_MSG_ID_HEARTBEAT
#: longest interval MESSAGE_INTERVAL can report (its ``interval_us`` is an int32), us
MAX_INTERVAL_US = 2**31 - 1
HOME_POSITION = M.MAVLINK_MSG_ID_HOME_POSITION
#: every message the vehicle streams, in the order they go out in a step's datagram
STREAMED = (HEARTBEAT, M.MAVLINK_MSG_ID_SYSTEM_TIME, M.MAVLINK_MSG_ID_SYS_STATUS, M.MAVLINK_MSG_ID_GPS_RAW_INT,
            M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, M.MAVLINK_MSG_ID_LOCAL_POSITION_NED, M.MAVLINK_MSG_ID_ATTITUDE,
            M.MAVLINK_MSG_ID_VFR_HUD, M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE,
            M.MAVLINK_MSG_ID_POSITION_TARGET_GLOBAL_INT, HOME_POSITION, M.MAVLINK_MSG_ID_ADSB_VEHICLE,
            M.MAVLINK_MSG_ID_NAMED_VALUE_INT, M.MAVLINK_MSG_ID_DAA_BANDS, M.MAVLINK_MSG_ID_ALLOCATION_DECISION)
#: default interval per message, s (None = not streamed: on request only)
DEFAULT_INTERVAL_S = {m: 1.0 for m in STREAMED}
DEFAULT_INTERVAL_S[HOME_POSITION] = None

#: REQUEST_DATA_STREAM groups (ArduPilot's assignment of the messages we have)
DATA_STREAM_GROUPS = {
    M.MAV_DATA_STREAM_EXTENDED_STATUS: (M.MAVLINK_MSG_ID_SYS_STATUS, M.MAVLINK_MSG_ID_GPS_RAW_INT,
                                        M.MAVLINK_MSG_ID_POSITION_TARGET_GLOBAL_INT,
                                        M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE),
    M.MAV_DATA_STREAM_POSITION: (M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, M.MAVLINK_MSG_ID_LOCAL_POSITION_NED),
    M.MAV_DATA_STREAM_EXTRA1: (M.MAVLINK_MSG_ID_ATTITUDE,),
    M.MAV_DATA_STREAM_EXTRA2: (M.MAVLINK_MSG_ID_VFR_HUD,),
    M.MAV_DATA_STREAM_EXTRA3: (M.MAVLINK_MSG_ID_SYSTEM_TIME,),
}
DATA_STREAM_GROUPS[M.MAV_DATA_STREAM_ALL] = tuple(m for g in list(DATA_STREAM_GROUPS.values()) for m in g)


def msg_name(msg_id: int) -> str:
    cls = M.mavlink_map.get(int(msg_id))
    return cls.msgname if cls is not None else f"message {int(msg_id)}"


class StreamRates:
    """Which messages are due at each step for one link (intervals in sim seconds)."""

    def __init__(self, dt: float = STEP.default):
        self.dt = float(dt)
        self.interval: dict[int, "float | None"] = dict(DEFAULT_INTERVAL_S)
        self._next: dict[int, float] = {m: 0.0 for m in STREAMED}
        self.once: set[int] = {HOME_POSITION}  #: one-shot messages for the next step
        self._clamp_told: set[int] = set()

    def due(self, t: float) -> set[int]:
        """Message ids to send at step ``t`` (s); advances their next due time."""
        out = set(self.once)
        self.once.clear()
        eps = 1e-9
        for m, iv in self.interval.items():
            if iv is None:
                continue
            if t + eps >= self._next[m]:
                out.add(m)
                # next due one interval after this step (never before the next step)
                self._next[m] = t + max(iv, self.dt)
        return out

    def interval_us(self, msg_id: int) -> int:
        """MESSAGE_INTERVAL value: the interval used (> 0 us; never below one step), -1 stopped, 0 not
        produced by this vehicle."""
        if int(msg_id) not in DEFAULT_INTERVAL_S:
            return 0
        iv = self.interval[int(msg_id)]
        return -1 if iv is None else int(round(max(iv, self.dt) * 1e6))

    def set_interval(self, msg_id: int, interval_us: float, t_now: float) -> "tuple[int, str]":
        """SET_MESSAGE_INTERVAL: ``(MAV_RESULT, note)``; applied from the next step. The note (for a
        STATUSTEXT; '' if none) says why a request was refused, or that an accepted one is faster than
        the sim step and goes out once per step."""
        m = int(msg_id)
        if m not in DEFAULT_INTERVAL_S:
            return M.MAV_RESULT_UNSUPPORTED, f"{msg_name(m)} is not produced by this vehicle"
        if not math.isfinite(interval_us) or (interval_us < 0 and interval_us != -1):
            return M.MAV_RESULT_DENIED, f"interval {interval_us!r} us invalid (-1 stop, 0 default, > 0 us)"
        if interval_us > MAX_INTERVAL_US:
            return M.MAV_RESULT_DENIED, f"interval {interval_us:g} us too long (at most {MAX_INTERVAL_US / 1e6:.0f} s)"
        if m == HEARTBEAT and (interval_us == -1 or interval_us > 1e6 + 1):
            return M.MAV_RESULT_DENIED, "HEARTBEAT is fixed at 1 Hz"
        note = ""
        if interval_us == -1:
            self.interval[m] = None
        elif interval_us == 0:
            self.interval[m] = DEFAULT_INTERVAL_S[m]
        else:
            s = interval_us / 1e6
            if s < self.dt - 1e-9:
                note = f"{msg_name(m)} once per step ({self.dt:g} s)"  # <= 50 characters: one STATUSTEXT
            self.interval[m] = s
        self._next[m] = t_now
        return M.MAV_RESULT_ACCEPTED, note

    def request_data_stream(self, stream_id: int, rate_hz: float, start: bool, t_now: float) -> str:
        """REQUEST_DATA_STREAM; returns a note for a STATUSTEXT ('' if none). Unknown groups: no-op."""
        ids = DATA_STREAM_GROUPS.get(int(stream_id), ())
        if not ids:
            return ""
        note = ""
        if not start or rate_hz <= 0:
            iv = None
        else:
            iv = max(1.0 / float(rate_hz), self.dt)
            if 1.0 / float(rate_hz) < self.dt - 1e-9 and int(stream_id) not in self._clamp_told:
                self._clamp_told.add(int(stream_id))
                note = f"stream {int(stream_id)} {float(rate_hz):g} Hz above the sim rate: {1 / self.dt:g} Hz"
        for m in ids:
            self.interval[m] = iv
            self._next[m] = t_now
        return note

    def request_once(self, msg_id: int) -> bool:
        """REQUEST_MESSAGE: send ``msg_id`` at the next publish; False if this vehicle cannot produce it."""
        if int(msg_id) not in DEFAULT_INTERVAL_S:
            return False
        self.once.add(int(msg_id))
        return True
