"""A guard around the handling of each received message: an exception is a malformed message, not a crash.

Network input is hostile. The codec drops what is not valid MAVLink (:mod:`daa_sil.link.codec`), but
a packet that decodes can still carry values its handler does not expect (a NaN where an integer is
meant, an id out of range, ...). Handlers check what they read; this guard is what makes a missed
case harmless. The vehicle, the GCS and the shim run each message's handling (the shim: each
datagram's, the unit it relays) under :meth:`MessageGuard.call`:

* an exception (``Exception``; never a cancellation, Ctrl-C or exit) counts the message as
  **malformed**, by type, and the caller goes on with the next message of the same datagram;
* the first malformed message of each type (up to ``max_named`` types) is reported at once, one line
  naming its type, sender and the exception; while more come, one summary line at most every
  ``every_s`` seconds with the counts (the style of :class:`daa_sil.sil.endpoint.DropReporter`);
* ``DAA_SIL_DEBUG=1`` adds the traceback (for whoever fixes the handler).

Lines go to ``emit`` (default stderr) as ``"{who}: warning: ..."``.
"""

from __future__ import annotations

import os
import sys
import time
import traceback
from collections import Counter
from typing import Callable


def stderr_line(text: str) -> None:
    """``text`` as one line on stderr, after whatever this process buffered on stdout (the GCS's status
    lines are flushed in batches: a warning must not overtake them in a log where both streams meet)."""
    try:
        sys.stdout.flush()
    except (OSError, ValueError, AttributeError):  # closed or replaced: nothing to keep in order
        pass
    print(text, file=sys.stderr, flush=True)


class MessageGuard:
    """Count and report messages whose handling raised (see the module docstring)."""

    def __init__(self, who: str, *, emit: "Callable[[str], None] | None" = None, every_s: float = 10.0,
                 clock: "Callable[[], float]" = time.monotonic, max_named: int = 8):
        self.who = who
        self.emit = emit or stderr_line
        self.every_s, self.clock, self.max_named = float(every_s), clock, int(max_named)
        self.by_type: Counter = Counter()  #: message type -> malformed messages
        self.total = 0
        self.lines = 0
        self._since = 0
        self._next: "float | None" = None

    def call(self, fn: Callable, *args, what: str = "message", source=None) -> bool:
        """``fn(*args)``; True if it returned, False if it raised (then counted and maybe reported).

        ``what``: the message type (e.g. ``"COMMAND_LONG"``); ``source``: the sender's ``(host, port)``.
        """
        try:
            fn(*args)
            return True
        except Exception as exc:  # noqa: BLE001 -- the point: no handler may take the process down
            self.note(what, source, exc)
            return False

    def run(self, fn: Callable, r) -> bool:
        """:meth:`call` for one :class:`daa_sil.sil.endpoint.Received` message ``r``: ``fn(r)``."""
        return self.call(fn, r, what=r.msg.get_type(), source=r.addr)

    def note(self, what: str, source, exc: BaseException) -> None:
        """Count one malformed ``what`` from ``source``; maybe emit a line."""
        new = what not in self.by_type
        self.by_type[what] += 1
        self.total += 1
        self._since += 1
        now = self.clock()
        if new and len(self.by_type) <= self.max_named:
            src = f" from {_addr_text(source)}" if source is not None else ""
            self._say(f"malformed {what}{src} dropped ({type(exc).__name__}: {_one_line(exc)}); the other "
                      f"messages of its datagram are handled")
            if os.environ.get("DAA_SIL_DEBUG"):
                self.emit("".join(traceback.format_exception(exc)).rstrip())
            self._since = 0
            if self._next is None:
                self._next = now + self.every_s
        elif self._next is None or now >= self._next:
            self._say(f"still dropping malformed messages: {self._since} in the last {self.every_s:g} s, "
                      f"{self.total} in all ({self._top()})")
            self._since = 0
            self._next = now + self.every_s

    def summary(self) -> "str | None":
        """One line with the totals (None if nothing was malformed)."""
        if not self.total:
            return None
        return f"malformed messages dropped: {self.total} ({self._top()})"

    def _top(self) -> str:
        top = ", ".join(f"{t}: {n}" for t, n in self.by_type.most_common(3))
        more = f" and {len(self.by_type) - 3} more types" if len(self.by_type) > 3 else ""
        return top + more

    def _say(self, text: str) -> None:
        self.lines += 1
        self.emit(f"{self.who}: warning: {text}")


def _one_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return (text[0] if text else "")[:200]


def _addr_text(addr) -> str:
    try:
        host, port = addr[0], addr[1]
    except (TypeError, IndexError, KeyError):
        return str(addr)
    return f"udp:[{host}]:{port}" if ":" in str(host) else f"udp:{host}:{port}"
