"""Pilot command gate: absolute, idempotent setpoints under multi-second delay.

Each pilot command carries its send time (sim s) and a sequence number. The gate applies each
command at most once and never an older one after a newer one: a command is accepted only if
its ``(t_sent, seq)`` is strictly newer than the last accepted one *from the same source*
(sources: the MAVLink ``(sysid, compid)``). Duplicates (same seq re-delivered by the link or the
shim's ``dup``), replays and reordered stale commands are counted and dropped.
Commands stamped in the future (beyond ``max_future_s``) are forged or from an unsynchronised
clock: counted and dropped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field


@dataclass(frozen=True)
class PilotCommand:
    """One accepted pilot command. ``nan`` fields mean keep current. Angles deg, speeds m/s."""

    t_sent: float  #: sim time the pilot sent it, s
    seq: int  #: command sequence number (>= 1)
    track_deg: float
    vs_mps: float
    gs_mps: float
    source: tuple = (255, 190)
    kind: str = "PILOT_MANEUVER"


@dataclass
class GateCounters:
    accepted: int = 0
    duplicate: int = 0
    older: int = 0
    future: int = 0
    invalid: int = 0


@dataclass
class CommandGate:
    """Accept each pilot command at most once, in order of ``(t_sent, seq)`` per source."""

    max_future_s: float = 2.0
    counters: GateCounters = field(default_factory=GateCounters)
    _last: dict = field(default_factory=dict)

    def offer(self, cmd: PilotCommand, t_now: float) -> bool:
        """True if ``cmd`` is new and valid at vehicle sim time ``t_now`` (s); else counted and dropped."""
        c = self.counters
        vals = (cmd.track_deg, cmd.vs_mps, cmd.gs_mps)
        if (not math.isfinite(cmd.t_sent) or cmd.t_sent < 0 or cmd.seq < 0
                or all(math.isnan(v) for v in vals) or any(math.isinf(v) for v in vals)
                or (math.isfinite(cmd.track_deg) and not 0.0 <= cmd.track_deg <= 360.0)
                or (math.isfinite(cmd.gs_mps) and not 0.0 < cmd.gs_mps <= 400.0)
                or (math.isfinite(cmd.vs_mps) and abs(cmd.vs_mps) > 60.0)):
            c.invalid += 1
            return False
        if cmd.t_sent > t_now + self.max_future_s:
            c.future += 1
            return False
        key = (cmd.t_sent, cmd.seq)
        last = self._last.get(cmd.source)
        if last is not None:
            if key == last:
                c.duplicate += 1
                return False
            if key < last:
                c.older += 1
                return False
        self._last[cmd.source] = key
        c.accepted += 1
        return True
