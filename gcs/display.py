"""One line per sim second of what the remote pilot sees (rich colours on a TTY, plain otherwise).

``t=  42s  seen@  38s own trk   0.0 alt   1000m gs   55  nearest 4660 r   6123m dh    +0m  alert 2
bands mid  GUIDED daa/blend  sent #3 maneuver2 trk 30``: the GCS's sim time, the (delayed) time of
the newest ownship state it has, the ownship's track / altitude / ground speed, the nearest
intruder's range and height difference, the **onboard** DAIDALUS alert level (DAA_ALERT, 0-3) of
that same vehicle time -- so it is the vehicle's alert delayed by the downlink, with ``@T`` added
if it is of another vehicle time T --, the highest region of the track bands (DAA_BANDS), the
vehicle's flight mode (HEARTBEAT), the agent's authority / decision (ALLOCATION_DECISION) and the
last command sent (or setting).

The agent may keep control below the corrective alert (2): a wait or blend goes on until the
ownship has reached its command, and control returns to the pilot only onto a safe course. The
line then says ``(alert < 2: manoeuvre in progress or pilot's course unsafe)``, so that ``alert 0``
next to ``daa/blend`` is not taken for a disagreement.
"""

from __future__ import annotations

import math
import sys
import time

from daa_sil.daa.config import REGION_NAMES

from .pilot import SettingSent

_console = None
#: a plain (not a TTY) status line is flushed when this many wall seconds passed since the last flush: a
#: realtime run (one line a second) flushes each line as before, a lockstep run (hundreds of lines a
#: second, into the run's log through a pipe the driver reads) a batch at a time; everything is flushed
#: before the GCS writes to stderr and when it exits
FLUSH_EVERY_S = 0.2
_last_flush = -math.inf


def format_line(node, t: float, n_cmd: int) -> str:
    """``t  own(track, alt, gs)  nearest intruder(range, dh)  authority/decision  commands`` as text;
    ``node``: the GCS's :class:`gcs.protocol.GcsProtocol` (its view and what it sent)."""
    v = node.view
    parts = [f"t={t:5.0f}s"]
    if v.own is not None:
        _, x, y, z, gs, trk, vs = v.own
        parts.append(f"seen@{v.own[0]:5.0f}s own trk {math.degrees(trk) % 360:5.1f} alt {z:6.0f}m gs {gs:4.0f}")
        if v.intruders:
            rng = {i: math.hypot(s[0] - x, s[1] - y) for i, s in v.intruders.items()}
            i = min(rng, key=rng.get)
            parts.append(f"nearest {i} r {rng[i]:6.0f}m dh {v.intruders[i][2] - z:+5.0f}m")
    else:
        parts.append("no telemetry yet")
    level = int(v.alert[1]) if math.isfinite(v.alert[0]) else None
    alert = "alert ?" if level is None else f"alert {level}"
    if level is not None and (v.own is None or v.alert[0] != v.own[0]):
        alert += f"@{v.alert[0]:.0f}s"
    region = REGION_NAMES[v.alert_regions] if 0 <= v.alert_regions < len(REGION_NAMES) else "?"
    parts.append(f"{alert} bands {region}  {v.mode} {v.authority}/{v.decision}")
    if v.authority not in ("pilot", "?") and level is not None and level < 2:
        parts.append("(alert < 2: manoeuvre in progress or pilot's course unsafe)")
    if n_cmd and node.sent:
        c = node.sent[-1]
        if isinstance(c, SettingSent):
            parts.append(f"set {c.name} {c.value:g}")
        else:
            parts.append(f"sent #{c.seq} {c.order.kind} trk {c.order.track_deg:.0f}")
    return "  ".join(parts)


def render_line(node, t: float, n_cmd: int) -> None:
    """Print one status line (rich if stdout is a TTY; otherwise flushed at most every :data:`FLUSH_EVERY_S`)."""
    global _console
    line = format_line(node, t, n_cmd)
    if sys.stdout.isatty():
        if _console is None:
            from rich.console import Console  # lazy: start-up time

            _console = Console()
        style = {"daa": "bold red", "waiting": "yellow", "pilot": "green"}.get(node.view.authority, "")
        _console.print(line, style=style, highlight=False)
    else:
        global _last_flush
        if _last_flush == -math.inf and getattr(sys.stdout, "write_through", False):
            # a child of daa-sil run (PYTHONUNBUFFERED): keep the lines until a flush instead of a write each
            sys.stdout.reconfigure(write_through=False)
        now = time.monotonic()
        flush = now - _last_flush >= FLUSH_EVERY_S
        print(line, flush=flush)
        if flush:
            _last_flush = now
