"""The authority (flight mode) STATUSTEXT, paced: at most one per :data:`MODE_TEXT_EVERY_S` of sim time,
always naming the latest mode (sans-IO).

The agent may hand control back and forth every step while a conflict is resolved; a ground station
that printed each change got a line a second. :class:`ModeAnnouncer` says a change at once when the
last text is at least the interval old, and otherwise waits: when the interval has passed, the next
publish says where the authority is *then* (from the last one said, so the texts read as a chain);
a flip and a flip back inside the interval says nothing. The heartbeat's mode is exact every step.
"""

from __future__ import annotations

#: sim seconds between two authority texts (at least)
MODE_TEXT_EVERY_S = 5.0
#: STATUSTEXT holds 50 characters
TEXT_MAX = 50


class ModeAnnouncer:
    """Which authority the ground stations were last told about, and when (sim s)."""

    def __init__(self, every_s: float = MODE_TEXT_EVERY_S, shown: str = "pilot"):
        self.every_s = float(every_s)
        self.shown = shown  #: the authority the last text named (the pilot's at the start)
        self.last_t: "float | None" = None
        self.held = 0  #: changes not said at once (said later or undone within the interval)

    def update(self, t: float, authority: str, decision: str, mode: str) -> "str | None":
        """The step at ``t`` (s) ends with ``authority`` (by ``decision``, shown as ArduPlane ``mode``): the
        text to send now, or None."""
        if authority == self.shown:
            return None
        if self.last_t is not None and t - self.last_t < self.every_s - 1e-9:
            self.held += 1
            return None
        text = f"t={t:.0f}s {mode} authority {self.shown}->{authority}"
        if len(text) + len(decision) + 3 <= TEXT_MAX:
            text += f" ({decision})"
        self.shown, self.last_t = authority, float(t)
        return text
