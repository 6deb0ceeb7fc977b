"""The delay shim's configuration and its random streams.

:class:`ShimConfig` (delays, loss, duplication, reordering, outages, clock), the per-direction
seeds and the delay processes shared with fast-time (docs/sil.md, "Delay parity with fast-time").
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from daa_sil.config.settings import SHIM_GCS_PORT, SHIM_VEHICLE_PORT, udp
from daa_sil.errors import UsageError
from daa_sil.link.codec import mavlink
from daa_sil.link.delayline import check_outages
from daa_sil.models.latency import DEFAULT_EPOCH_S, DelayModel
from daa_sil.models.link_rule import LinkLegs
from daa_sil.models.delay_process import as_seed_sequence, child_seed, link_delay_processes
from daa_sil.models.streams import STREAM_DOWN, STREAM_UP
from daa_sil.sil.endpoint import parse_udp_address

CLOCKS = ("realtime", "lockstep")
#: bytes each delay line may hold in flight (a lockstep step carries 1-3 kB each way: this is hours of it)
LINE_BYTES = 16 * 1024 * 1024
#: bytes of GCS datagrams held before the mode is decided (realtime) or while a step awaits its ack (lockstep)
HELD_BYTES = 8 * 1024 * 1024
TIMINGS = ("precise", "poll")
#: MAVLink ids of the lockstep clock's tick and its acknowledgement
TICK_ID = mavlink.MAVLINK_MSG_ID_SIM_TICK
ACK_ID = mavlink.MAVLINK_MSG_ID_SIM_TICK_ACK


def direction_seeds(seed: "int | np.random.SeedSequence | None") -> dict:
    """``{"down": SeedSequence, "up": SeedSequence}``: the roots of each DelayLine's impairment draws."""
    ss = as_seed_sequence(seed)
    return {"down": child_seed(ss, 0), "up": child_seed(ss, 1)}


def delay_stream_seeds(seed: "int | np.random.SeedSequence | None") -> dict:
    """``{"down": ..., "up": ...}`` delay-process seeds: the fast-time streams of encounter ``seed``.

    Equal to ``encounter_streams(seed)[STREAM_DOWN]`` / ``[STREAM_UP]`` for an int seed (the
    children ``(2,)`` / ``(1,)`` of ``SeedSequence(seed)``; for a SeedSequence, its children).
    """
    ss = as_seed_sequence(seed)
    return {"down": child_seed(ss, STREAM_DOWN), "up": child_seed(ss, STREAM_UP)}


def shim_delay_processes(config: "ShimConfig", seed: "int | np.random.SeedSequence | None" = None) -> dict:
    """``{"down": DelayProcess, "up": DelayProcess}`` of a shim (see the module docstring, Seeds).

    ``seed``: a resolved seed (default ``config.seed``; None there = fresh entropy).
    """
    seeds = delay_stream_seeds(config.seed if seed is None else seed)
    legs = LinkLegs(config.delay_up, config.delay_down, shared=config.round_trip,
                    rule="round-trip" if config.round_trip else "one-way")
    return link_delay_processes(legs, seeds["up"], seeds["down"], epoch_s=config.epoch_s)


def control_ids(data: bytes) -> "set[int]":
    """Message ids of the packets in a datagram by header walk only (no CRC check).

    Returns only SIM_TICK / SIM_TICK_ACK ids found, plus ``-1`` if the datagram also holds other
    packets (or bytes that are not a packet).
    """
    found: set[int] = set()
    i, n = 0, len(data)
    while i < n:
        b0 = data[i]
        if b0 == 0xFD and i + 10 <= n:
            ln, flags = data[i + 1], data[i + 2]
            mid = data[i + 7] | (data[i + 8] << 8) | (data[i + 9] << 16)
            size = 12 + ln + (13 if flags & 1 else 0)
        elif b0 == 0xFE and i + 6 <= n:
            ln, mid = data[i + 1], data[i + 5]
            size = 8 + ln
        else:
            found.add(-1)
            break
        found.add(mid if mid in (TICK_ID, ACK_ID) else -1)
        i += size
    return found


@dataclass
class ShimConfig:
    """Everything the shim needs. Delays are models of one-way delay in sim seconds.

    ``listen_vehicle`` / ``listen_gcs``: the shim's sockets (``udp:HOST:PORT``; port 0 = OS-chosen).
    ``vehicle`` / ``gcs``: peer addresses, or None to learn them from the first datagram.
    ``delay_down`` (vehicle -> GCS), ``delay_up`` (GCS -> vehicle); ``round_trip``: the two are the
    halves of one round trip (:func:`daa_sil.models.link_rule.link_legs`): the downlink reads the
    uplink's draws; ``epoch_s`` of the delay process (0 = per-datagram draws). ``loss``/``dup``/``reorder`` probabilities and ``outages``
    (``[(t_start, t_end), ...]`` sim s) apply to both directions. ``speed``: sim seconds per wall
    second in realtime mode. ``key``: signing key used to verify control messages in lockstep and the first datagram of a peer.
    ``timing`` (realtime only): ``"precise"`` (default) stamps every datagram with its kernel
    arrival time and wakes for each release with a timerfd (:mod:`daa_sil.sil.rtclock`);
    ``"poll"`` stamps on read and uses ``loop.call_at`` ``spin_s`` early, then polls the loop
    (still serving I/O) until the release instant (the selector's millisecond timeout rounding
    otherwise makes releases up to ~1 ms late; ``spin_s`` 0 = no polling). ``"precise"`` falls
    back to ``"poll"`` where timerfd / kernel stamps are unavailable (non-Linux).
    ``max_line_bytes``: bytes each delay line holds in flight; ``max_held_bytes``: bytes of GCS datagrams
    held (start-up, a lockstep step): past either, datagrams are dropped and counted (``dropped_queue``).
    """

    delay_down: DelayModel
    delay_up: DelayModel
    round_trip: bool = False
    listen_vehicle: str = udp(SHIM_VEHICLE_PORT)
    listen_gcs: str = udp(SHIM_GCS_PORT)
    vehicle: "str | None" = None
    gcs: "str | None" = None
    epoch_s: float = DEFAULT_EPOCH_S
    loss: float = 0.0
    dup: float = 0.0
    reorder: float = 0.0
    fifo: bool = True
    outages: Sequence[Sequence[float]] = ()
    seed: "int | None" = 0
    clock: str = "realtime"
    speed: float = 1.0
    key: "bytes | None" = None
    stats_json: "str | None" = None
    max_log: int = 100_000
    spin_s: float = 0.002
    timing: str = "precise"
    max_line_bytes: int = LINE_BYTES
    max_held_bytes: int = HELD_BYTES

    def validate(self) -> None:
        """Raise a one-line UsageError for any bad value."""
        if self.clock not in CLOCKS:
            raise UsageError(f"clock must be one of {', '.join(CLOCKS)}, got {self.clock!r}")
        if not (math.isfinite(self.speed) and 0.01 <= self.speed <= 1000):
            raise UsageError(f"speed must be within [0.01, 1000], got {self.speed!r}")
        if self.timing not in TIMINGS:
            raise UsageError(f"timing must be one of {', '.join(TIMINGS)}, got {self.timing!r}")
        if not (math.isfinite(self.spin_s) and 0 <= self.spin_s <= 0.05):
            raise UsageError(f"spin_s must be within [0, 0.05] s, got {self.spin_s!r}")
        for name in ("max_line_bytes", "max_held_bytes"):
            v = getattr(self, name)
            if not (isinstance(v, int) and 65_536 <= v <= 2**34):
                raise UsageError(f"{name} must be an integer within [65536, 2**34] bytes, got {v!r}")
        for name in ("delay_down", "delay_up"):
            if not isinstance(getattr(self, name), DelayModel):
                raise UsageError(f"{name} must be a delay model (see daa_sil.models.latency), got {getattr(self, name)!r}")
        if self.round_trip and self.delay_up != self.delay_down:
            raise UsageError("a round trip is one delay: delay_up and delay_down must be its two equal halves")
        parse_udp_address(self.listen_vehicle, "--listen-vehicle")
        parse_udp_address(self.listen_gcs, "--listen-gcs")
        for name in ("vehicle", "gcs"):
            if getattr(self, name) is not None:
                parse_udp_address(getattr(self, name), f"--{name}", allow_port_zero=False)
        check_outages(self.outages)
