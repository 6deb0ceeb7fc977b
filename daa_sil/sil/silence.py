"""One silence watch for every SIL process: a party that talked and then stopped is reported once,
and again when it comes back.

Each role watches the parties it hears from and has one threshold (wall seconds), defined here:
the shim watches the vehicle and the GCS (any datagram), the vehicle watches the shim and the GCS
(answers to its ticks: echoes, acks), the GCS watches the vehicle side (its ticks).
"""

from __future__ import annotations

#: wall seconds of silence before a party is reported, per watching role
SILENT_AFTER_S = {"shim": 5.0, "vehicle": 3.0, "gcs": 3.0}


class Silence:
    """When one party was last heard (wall s, the caller's clock) and whether it is reported silent.

    ``heard(now)`` notes a sign of life and returns how long the party had been reported silent
    (None if it was not); ``check(now)`` returns the seconds it has been quiet the moment it
    becomes silent (once, until it is heard again), else None.
    """

    def __init__(self, after_s: float):
        self.after_s = float(after_s)
        self.last: "float | None" = None  #: when it was last heard (None: never)
        self.silent = False

    def heard(self, now: float) -> "float | None":
        """A sign of life at ``now`` (s); the silence it ends (s), or None."""
        back = now - self.last if self.silent and self.last is not None else None
        self.silent = False
        self.last = now
        return back

    def check(self, now: float, after_s: "float | None" = None) -> "float | None":
        """Quiet seconds if the party becomes silent at ``now`` (threshold ``after_s``, default the
        role's), else None; a party never heard is never silent."""
        if self.last is None or self.silent:
            return None
        quiet = now - self.last
        if quiet < (self.after_s if after_s is None else after_s):
            return None
        self.silent = True
        return quiet
