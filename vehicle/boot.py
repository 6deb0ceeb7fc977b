"""The vehicle before its simulation is ready, sans-IO: what it says while it boots, as an autopilot does.

A cold first start compiles the DAA kernels and builds the wait maps (tens of seconds). An autopilot
shows itself at once and says what it is doing, so the vehicle binds its sockets first and, while it
prepares (:mod:`vehicle.prepare`, beside the link), already:

* sends a HEARTBEAT every second in ``MAV_STATE_BOOT`` (mode GUIDED: the pilot's, the agent has not
  started) to every ground station it can reach;
* answers reads (parameters, AUTOPILOT_VERSION, TIMESYNC, PING, rates) and applies parameter writes to
  the policy the agent will start with (:class:`BootPlant` is the plant the protocol core uses until
  then: the scenario's policy, resolved as the simulation will resolve it);
* reports the preparation's progress in STATUSTEXT (:func:`progress_text`);
* refuses pilot commands and traffic (``MAV_RESULT_TEMPORARILY_REJECTED`` and a STATUSTEXT): nothing
  flies yet.

The simulation clock starts when the vehicle is ready (sim time 0 is the first step after it);
``daa-vehicle --wait-gcs`` then waits, in ``MAV_STATE_STANDBY``, for the first ground station on the
pilot's link.
"""

from __future__ import annotations

from daa_sil.config.settings import STEP
from daa_sil.link.codec import mavlink as M

from . import identity as ident
from . import telemetry as T
from .core import resolve_policy

#: STATUSTEXT prefix of the boot's progress lines
PREFIX = "boot: "
#: while booting, the latest progress line goes out again with every this many heartbeats (1 a wall second),
#: for a ground station that came in after it was said
BOOT_TEXT_EVERY = 5


def progress_text(text: str) -> str:
    """A preparation step as a STATUSTEXT (at most 50 characters)."""
    return (PREFIX + text)[:50]


def boot_messages(plant, standby: bool, text: str, beat: int) -> list:
    """The ``beat``-th boot datagram's messages: a HEARTBEAT in MAV_STATE_BOOT (STANDBY while waiting for a
    GCS), and every :data:`BOOT_TEXT_EVERY` beats the latest progress ``text`` again."""
    state = M.MAV_STATE_STANDBY if standby else M.MAV_STATE_BOOT
    msgs = [T.heartbeat(plant.last_authority, bool(plant.policy.enabled), state)]
    if text and beat % BOOT_TEXT_EVERY == 0:
        msgs.append(T.statustext(progress_text(text), M.MAV_SEVERITY_INFO))
    return msgs


class BootPlant:
    """The plant (:class:`vehicle.services.Plant`) of a vehicle that is not ready yet: the scenario ``sc``
    and the policy the agent will start with (``config``: the run configuration, as
    :func:`vehicle.core.resolve_policy` reads it); no simulation."""

    booting = True

    def __init__(self, sc, config=None, dt: float = STEP.default, flags=None):
        self.sc, self.dt = sc, float(dt)
        self.policy = resolve_policy(sc, None, config, flags)
        self.n_steps = sc.n_steps
        self.last_authority = "pilot"
        self.last_decision = "none"
        self.written = False  #: a parameter was set while booting (the simulation starts with it)

    def set_policy(self, policy) -> None:
        self.policy = policy
        self.written = True

    def mode(self) -> int:
        return ident.mode_of(self.last_authority, bool(self.policy.enabled))

    def note_gcs_data(self, t: float) -> None:
        """Link liveness is the simulation's; nothing to note before it starts."""
