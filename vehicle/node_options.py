"""Options and counters of the vehicle node (:class:`vehicle.node.VehicleNode`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from daa_sil.config.settings import GCS_PORT, udp


@dataclass
class VehicleOptions:
    """Runtime options of the vehicle node (addresses ``udp:HOST:PORT``; timeouts in wall s)."""

    out: str = udp(GCS_PORT)
    #: further outputs (``--out`` after the first): observers, ``CONN[,rw]`` (:mod:`daa_sil.sil.outputs`)
    also_out: tuple = ()
    listen: str = "udp:127.0.0.1:0"
    tap: "str | None" = None
    clock: str = "realtime"
    speed: float = 1.0
    key: "bytes | None" = None
    steplog: "Path | None" = None
    tick_timeout_s: float = 10.0
    tick_retry_s: float = 2.0
    #: wall seconds to wait for the answer to tick 0 (the partner may still be starting); None = tick_timeout_s
    start_timeout_s: "float | None" = None
    #: ``udp:127.0.0.1:PORT``: publish each step's step-log row there (:mod:`daa_sil.sil.live`)
    live: "str | None" = None
    #: ``--waitmap``: map preset, grid spec or family directory (None = the default map)
    waitmap: "str | None" = None
    #: ``--config``: a :class:`daa_sil.config.run_config.RunConfig` (None = the scenario alone)
    config: "object | None" = None
    #: the per-group settings of the command line (``--wt``, ...: an Overrides; None = none)
    settings: "object | None" = None
    #: let the (undelayed) tap set parameters and modes; by default it may only read
    tap_writable: bool = False
    #: realtime: "auto" (start at once, wait for tick answers only from a partner that gives them) or
    #: "wait" (start the clock once tick 0 is acknowledged; error after tick_timeout_s)
    tick_sync: str = "auto"
    #: called once with the wall (``time.monotonic``) instant of step 0's deadline when the clock starts
    on_clock_start: "object | None" = None
    #: stop after the scenario's last step (``daa-sil run``); False: fly on until stopped (``daa-vehicle``'s
    #: default: the ownship on its last command or its plan, the intruders straight on)
    exit_at_end: bool = True
    #: once ready, wait (MAV_STATE_STANDBY) for the first message from a ground station on the pilot's link
    #: before the clock starts
    wait_gcs: bool = False


@dataclass
class VehicleStats:
    steps: int = 0
    ticks_sent: int = 0
    tick_retries: int = 0
    gcs_requests_answered: int = 0
    #: pilot commands from an observer output (the tap, a further --out): never flown
    commands_from_observers_ignored: int = 0
    #: pilot commands that arrived while the vehicle was booting (refused: nothing flies yet)
    commands_while_booting: int = 0
    foreign_messages_ignored: int = 0
    #: messages from an address that is no output of the socket they came in on, dropped
    other_address_ignored: int = 0
    authority_changes: int = 0
    #: realtime: how late each step's telemetry went out after its due wall time ``W_k``, ms
    late_mean_ms: float = 0.0
    late_max_ms: float = 0.0
    late_p99_ms: float = 0.0
    #: ticks the shim echoed back (it is alive, and the uplink due at that tick was sent)
    tick_echoes: int = 0
    #: realtime: who confirms ticks: "shim" (echoes), "gcs" (acks, no shim between) or "none"
    sync_partner: str = "none"
    #: realtime: steps that ran before their tick was confirmed (0 = each step saw what lockstep sees)
    steps_unconfirmed: int = 0
    #: realtime: ticks the GCS acknowledged only after the next tick had gone out
    acks_late: int = 0
    #: warnings printed because the shim or the GCS stopped answering ticks
    silence_warnings: int = 0
    #: messages dropped because the queue they wait in (reads, settings, commands) was past its byte budget
    dropped_queue: int = 0
    extra: dict = field(default_factory=dict)
