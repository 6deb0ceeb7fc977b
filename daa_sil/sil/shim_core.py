"""The delay shim's protocol, sans-IO: both delay lines, the tick clock, stamping and counters.

:class:`ShimCore` never reads a clock or touches a socket (in the style of h11's ``Connection``):
the caller hands it each datagram with :meth:`ShimCore.receive` and sends what it returns, a list
of :class:`Send` ``(dest, data)`` with ``dest`` ``"vehicle"`` or ``"gcs"``, in order. The socket
side (:class:`daa_sil.sil.shim.DelayShim`) keeps the addresses, the timers and the silence
watcher. *down* = vehicle -> GCS, *up* = GCS -> vehicle. Forwarded bytes are never modified.

Clocks
------
**Ticks** (lockstep always; realtime when the vehicle's first datagram is a ``SIM_TICK``; see
``docs/architecture.md``, "The step order"). The clock moves only on ticks:

1. A datagram from the vehicle holding a valid ``SIM_TICK(k, t_k)`` sets the clock to ``t_k``
   (never backwards: ``clock_backwards``), releases every packet due at or before ``t_k`` on both
   lines (each in release order), forwards the tick to the GCS at once and echoes it to the
   vehicle (``tick_echoes``): the echo says the shim is alive and every uplink packet due at
   ``t_k`` has been sent.
2. Other vehicle datagrams enter the down line stamped with the clock. GCS datagrams are stamped
   with the **oldest tick forwarded to the GCS that it has not acknowledged** (the last tick if it
   never acknowledges, or after it ignored ``MAX_GCS_LAG_TICKS``: ``gcs_unresponsive``), so a GCS
   that answers late keeps its step-k commands at step k (``gcs_lagged``). An uplink datagram due
   at a tick already processed is ``released_late``.
3. A GCS datagram holding a valid ``SIM_TICK_ACK(k)`` (cumulative) is forwarded to the vehicle at once.
4. Lockstep: a new tick that arrives while the GCS has not acknowledged the last tick forwarded to
   it is held (``ticks_held``) and processed when that ack arrives. So the GCS's step-(k-1)
   datagrams are queued before tick ``k`` releases anything, while the vehicle runs its step on
   the echo in parallel with the GCS (what either sends during tick ``k`` reaches the other at
   tick ``k + 1`` at the earliest). A repeated tick is forwarded again (a lost one is recovered).
5. Tick 0 processed before any GCS has spoken (its forward found no peer) is processed again when
   the GCS's first datagram comes in (``start_tick_forwarded``): what the vehicle's next retry of
   tick 0 would do, without waiting for it, except that it is not echoed a second time (the same
   signed bytes twice are a replay to the vehicle's codec). The GCS usually finishes starting after
   the vehicle.

**Free-running** (realtime, the vehicle sends no ticks): each datagram enters its line at the
sim time ``t`` given to :meth:`ShimCore.receive`; :meth:`ShimCore.next_release` says when the
caller should call :meth:`ShimCore.release`.

Until the vehicle's first datagram decides the mode (realtime), GCS datagrams are held
(``held_for_vehicle``, at most ``MAX_HELD`` datagrams and ``max_held_bytes`` bytes, then
``held_dropped``) and replayed after it. A vehicle that is still booting (a datagram of HEARTBEATs in
``MAV_STATE_BOOT`` or ``STANDBY`` and STATUSTEXTs: :mod:`vehicle.boot`) decides nothing: such datagrams
go to the GCS at once (``boot_relayed``); there is no sim clock yet to delay them by.

Every queue has a byte budget: each delay line ``max_line_bytes`` in flight, the start-up hold and a
lockstep step's held GCS datagrams ``max_held_bytes`` (:class:`daa_sil.sil.shim_config.ShimConfig`).
A datagram past one is dropped and counted in ``dropped_queue`` (and in the line's own
``dropped_queue``, or ``held_dropped`` / ``batch_dropped``); the socket side warns once.

Control messages are found by a header walk (:func:`daa_sil.sil.shim_config.control_ids`), then
fully decoded (CRC, and the signature with a key), so a forged or corrupt tick cannot move the clock
(``bad_control``; it is then plain data). Send ticks and acks alone in their datagram: a mixed one
is handled as control and its other messages skip the delay (``mixed_control``).

Fault draws (loss, duplication, reordering) are keyed on what a datagram is in the simulation, not
on how many came before (:meth:`daa_sil.link.delayline.DelayLine.fault_uniforms`), so traffic whose
amount depends on the wall clock (greetings before the first tick, repeated ticks) cannot shift them:

* before the first tick: ``(KEY_START, 0, n)``, ``n`` = the line's n-th start-up datagram;
* lockstep, GCS datagrams while a tick forwarded to it awaits its ack (its step): held until that
  ack (or the next tick) and keyed ``(KEY_BACK, t_ms, n)``, ``n`` counted back from the ack;
* otherwise ``(KEY_STEP, t_ms, n)``: the n-th datagram stamped ``t_ms`` (ms) on that line.

Free-running realtime keeps each line's sequential stream.
"""

from __future__ import annotations

from collections import deque
from typing import NamedTuple

from daa_sil.link.codec import MavCodec
from daa_sil.link.delayline import DelayLine
from daa_sil.models.delay_process import as_seed_sequence
from .shim_config import ACK_ID, TICK_ID, ShimConfig, control_ids, direction_seeds, shim_delay_processes

#: realtime: datagrams from the GCS held until the vehicle side's first datagram decides the mode; lockstep:
#: datagrams of one GCS step held until its ack (past this, dropped and counted: ``held_dropped``,
#: ``batch_dropped``)
MAX_HELD = 10_000
#: a GCS that has not acknowledged this many forwarded ticks is taken as gone (stamps fall back to the last tick)
MAX_GCS_LAG_TICKS = 8
#: first element of a fault-draw key (module docstring)
KEY_START, KEY_STEP, KEY_BACK = 0, 1, 2
#: per line, stamps whose datagram counts are kept (the oldest is forgotten past this)
MAX_COUNTED_STAMPS = 64
#: the protocol's counters (the socket side adds its own)
COUNTERS = ("rejected_claim", "ticks", "acks", "bad_control", "mixed_control", "clock_backwards", "tick_echoes",
            "held_for_vehicle", "held_dropped", "batch_dropped", "gcs_lagged", "gcs_unresponsive", "released_late",
            "ticks_held", "start_tick_forwarded", "dropped_queue", "boot_relayed")
#: MAV_STATE of a vehicle that is not flying its scenario yet (booting, or waiting for its GCS)
BOOT_STATES = (1, 3)  # MAV_STATE_BOOT, MAV_STATE_STANDBY
#: the side each line delivers to
DEST = {"down": "gcs", "up": "vehicle"}


class Send(NamedTuple):
    """One datagram to send: ``dest`` is ``"vehicle"`` or ``"gcs"``."""

    dest: str
    data: bytes


class ShimCore:
    """The shim's state machine: ``receive(side, data, t) -> [Send]``, ``next_release()``, ``release(t)``."""

    def __init__(self, config: ShimConfig):
        config.validate()
        self.config = config
        self.lockstep = config.clock == "lockstep"
        root = as_seed_sequence(config.seed)  # resolved once: seed None = fresh entropy shared by both
        seeds = direction_seeds(root)
        procs = shim_delay_processes(config, root)
        common = dict(fifo=config.fifo, loss=config.loss, dup=config.dup, reorder=config.reorder,
                      outages=config.outages, max_log=config.max_log, max_bytes=config.max_line_bytes)
        self.lines = {d: DelayLine(procs[d], seed=seeds[d], **common) for d in ("down", "up")}
        self.codec = MavCodec(0, 0, key=config.key, sign_outgoing=False)  # verifies control messages only
        #: sides whose peer is known (configured, or claimed by :meth:`claim`)
        self.known = {"vehicle": config.vehicle is not None, "gcs": config.gcs is not None}
        self.counters = {k: 0 for k in COUNTERS}
        self.sim_time = 0.0  #: the tick clock (s)
        self.last_tick: "int | None" = None
        #: releases driven by ticks (lockstep always; realtime once the vehicle's first datagram is a tick)
        self.tick_mode: "bool | None" = True if self.lockstep else None
        #: ticks processed by the last call: ``(k, t_k s, packets released)``
        self.processed: list[tuple[int, float, int]] = []
        self._out: list[Send] = []
        self._held: list[tuple[float, bytes]] = []  # mode undecided: GCS datagrams
        self._held_bytes = 0
        self._unacked: "deque[tuple[int, float]]" = deque()  # ticks forwarded to the GCS, not yet acked
        self._held_tick: "tuple | None" = None  # lockstep: the next tick, until the GCS acks its pending one
        self._start_tick: "tuple | None" = None  # tick 0, processed before any GCS had spoken
        self._gcs_acks = False  # the GCS acknowledges ticks (so its data can be stamped by them)
        self._start_count = {"down": 0, "up": 0}
        self._stamp_count: dict[str, dict[int, int]] = {"down": {}, "up": {}}
        self._gcs_batch: list[tuple[float, bytes]] = []
        self._batch_bytes = 0

    # -- input ---------------------------------------------------------------------------------
    def claim(self, side: str, data: bytes) -> bool:
        """May the first datagram from an unknown ``side`` make its sender that side's peer? Only a good
        MAVLink packet (with a key: validly signed) may; checked without changing any signing state."""
        if not self.codec.decode(data, commit=False):
            self.counters["rejected_claim"] += 1
            return False
        self.known[side] = True
        return True

    def receive(self, side: str, data: bytes, t: float = 0.0) -> list[Send]:
        """One datagram from ``side`` (its peer's); ``t``: its arrival on the free-running sim clock (s),
        not used while ticks drive the clock. Returns what to send now, in order."""
        self._out, self.processed = [], []
        if self.tick_mode is None:  # realtime: the vehicle side's first datagram decides the mode
            if side == "gcs":
                if len(self._held) < MAX_HELD and self._held_bytes + len(data) <= self.config.max_held_bytes:
                    self._held.append((t, data))
                    self._held_bytes += len(data)
                    self.counters["held_for_vehicle"] += 1
                else:
                    self.counters["held_dropped"] += 1
                    self.counters["dropped_queue"] += 1
                return self._out
            if self._booting(data):
                self.counters["boot_relayed"] += 1
                self._out.append(Send("gcs", data))
                return self._out
            self._decide_mode(data)
        if self.tick_mode:
            self._tick_datapath(side, data)
            if side == "gcs" and self._start_tick is not None and self.known["gcs"]:
                # the GCS spoke for the first time after tick 0: it gets tick 0 now, exactly as if the
                # vehicle's next retry of it had come in (instead of up to tick_retry_s later)
                start, self._start_tick = self._start_tick, None
                self.counters["start_tick_forwarded"] += 1
                # not echoed again: the vehicle had its echo, and a second copy of the same signed bytes is
                # a replay to its codec (dropped and counted as an attack)
                self._process_tick(*start, echo=False)
        else:
            self._push(self.lines["down" if side == "vehicle" else "up"], t, data)
        return self._out

    def _push(self, line: DelayLine, t: float, data: bytes, key: "tuple | None" = None) -> list:
        """``line.push`` counting a drop past the line's byte budget in ``dropped_queue``."""
        recs = line.push(t, data, key=key)
        if recs and recs[0].dropped == "queue":
            self.counters["dropped_queue"] += 1
        return recs

    def next_release(self) -> "float | None":
        """Free-running clock: sim time (s) of the earliest pending release; None if nothing is
        pending or ticks drive the releases."""
        if self.tick_mode is not False:
            return None
        due = [r for r in (self.lines["down"].next_release(), self.lines["up"].next_release()) if r is not None]
        return min(due) if due else None

    def release(self, t: float) -> list[Send]:
        """Free-running clock: every packet due at or before sim time ``t`` (s), down line first."""
        self._out, self.processed = [], []
        self._release("down", t)
        self._release("up", t)
        return self._out

    def _booting(self, data: bytes) -> bool:
        """Is this vehicle datagram only a booting vehicle's HEARTBEAT (BOOT / STANDBY) and STATUSTEXTs?"""
        if control_ids(data) != {-1}:
            return False
        msgs = self.codec.decode(data, commit=False)
        return bool(msgs) and all(
            (m.get_type() == "HEARTBEAT" and m.system_status in BOOT_STATES) or m.get_type() == "STATUSTEXT"
            for m in msgs)

    # -- tick clock ----------------------------------------------------------------------------
    def _decide_mode(self, first_vehicle_datagram: bytes) -> None:
        """Ticks if the vehicle's first datagram holds a valid SIM_TICK; then replay the held GCS data."""
        tick = False
        if TICK_ID in control_ids(first_vehicle_datagram):
            tick = any(m.get_msgId() == TICK_ID for m in self.codec.decode(first_vehicle_datagram, commit=False))
        self.tick_mode = tick
        held, self._held, self._held_bytes = self._held, [], 0
        for t, data in held:
            if tick:
                self._tick_datapath("gcs", data)
            else:
                self._push(self.lines["up"], t, data)

    def _tick_datapath(self, side: str, data: bytes) -> None:
        c = self.counters
        ids = control_ids(data)
        want = TICK_ID if side == "vehicle" else ACK_ID
        if want in ids:
            msg = self._decode_control(data, want)
            if msg is not None:
                if -1 in ids:
                    c["mixed_control"] += 1
                if side == "vehicle":
                    self._on_tick(msg, data)
                else:
                    self._on_ack(msg, data)
                return
            c["bad_control"] += 1
        if side == "vehicle":
            self._push(self.lines["down"], self.sim_time, data, key=self._fault_key("down", self.sim_time))
            return
        stamp = self._gcs_stamp()
        if self.lockstep and self._unacked:
            if len(self._gcs_batch) >= MAX_HELD or self._batch_bytes + len(data) > self.config.max_held_bytes:
                c["batch_dropped"] += 1  # a GCS flooding one step without acking it
                c["dropped_queue"] += 1
                return
            self._gcs_batch.append((stamp, data))  # the GCS's step: keyed back from its ack
            self._batch_bytes += len(data)
            return
        self._push_up(stamp, data, self._fault_key("up", stamp))

    def _decode_control(self, data: bytes, want: int):
        for m in self.codec.decode(data):
            if m.get_msgId() == want:
                return m
        return None

    def _push_up(self, stamp: float, data: bytes, key: tuple) -> None:
        recs = self._push(self.lines["up"], stamp, data, key)
        if stamp < self.sim_time and any(not r.dropped and r.t_out <= self.sim_time for r in recs):
            self.counters["released_late"] += 1  # lockstep would have released it at a tick already processed

    def _fault_key(self, direction: str, stamp: float) -> tuple:
        """Fault-draw key of the next datagram stamped ``stamp`` (s) on ``direction`` (module docstring)."""
        if self.last_tick is None:
            n = self._start_count[direction]
            self._start_count[direction] = n + 1
            return (KEY_START, 0, n)
        ms, counts = sim_ms(stamp), self._stamp_count[direction]
        n = counts.get(ms, 0)
        counts[ms] = n + 1
        if len(counts) > MAX_COUNTED_STAMPS:
            del counts[min(counts)]
        return (KEY_STEP, ms, n)

    def _flush_gcs_batch(self) -> None:
        """Lockstep: push the GCS datagrams held since the last tick forwarded to it, keyed back from now."""
        batch, self._gcs_batch, self._batch_bytes = self._gcs_batch, [], 0
        after: dict[int, int] = {}
        keys = []
        for stamp, _ in reversed(batch):
            ms = sim_ms(stamp)
            keys.append((KEY_BACK, ms, after.get(ms, 0)))
            after[ms] = after.get(ms, 0) + 1
        for (stamp, data), key in zip(batch, reversed(keys)):
            self._push_up(stamp, data, key)

    def _gcs_stamp(self) -> float:
        """Sim time a GCS datagram is sent at: the oldest tick it has not acknowledged (rule 2)."""
        if self._gcs_acks and self._unacked:
            t = self._unacked[0][1]
            if t < self.sim_time:
                self.counters["gcs_lagged"] += 1
            return t
        return self.sim_time

    def _on_tick(self, msg, data: bytes) -> None:
        self.counters["ticks"] += 1
        if self.lockstep and self._unacked and int(msg.tick) > self._unacked[-1][0]:
            self._held_tick = (msg, data)  # the newest copy (a retry replaces it)
            self.counters["ticks_held"] += 1
            return
        self._process_tick(msg, data)

    def _process_tick(self, msg, data: bytes, echo: bool = True) -> None:
        """Tick ``msg`` (its datagram ``data``): the clock, the releases, the forward to the GCS and (``echo``)
        the echo to the vehicle."""
        c = self.counters
        k = int(msg.tick)
        if self.last_tick is None or k > self.last_tick:  # a retried tick leaves the GCS's step batch whole, so
            self._flush_gcs_batch()  # its datagrams' fault keys do not depend on when the vehicle retried
        t_k = msg.time_ms / 1000.0
        if t_k < self.sim_time:
            c["clock_backwards"] += 1
        else:
            self.sim_time = t_k
        self.last_tick = k
        self._start_tick = (msg, data) if k == 0 and not self.known["gcs"] else None
        n = self._release("down", self.sim_time) + self._release("up", self.sim_time)
        self._out.append(Send("gcs", data))
        if self.known["gcs"] and (not self._unacked or self._unacked[-1][0] < k):
            self._unacked.append((k, t_k))
            if len(self._unacked) > MAX_GCS_LAG_TICKS:  # the GCS ignores ticks: gone, or not ack-capable
                self._unacked.clear()
                if self._gcs_acks:
                    c["gcs_unresponsive"] += 1
                self._gcs_acks = False
        if echo:
            self._out.append(Send("vehicle", data))
            c["tick_echoes"] += 1  # "shim alive, uplink due at t_k sent"
        self.processed.append((k, t_k, n))

    def _on_ack(self, msg, data: bytes) -> None:
        self.counters["acks"] += 1
        self._flush_gcs_batch()
        self._gcs_acks = True
        k = int(msg.tick)
        while self._unacked and self._unacked[0][0] <= k:
            self._unacked.popleft()
        self._out.append(Send("vehicle", data))
        if self._held_tick is not None and not self._unacked:  # lockstep: the held tick may go now
            held, self._held_tick = self._held_tick, None
            self._process_tick(*held)

    def _release(self, direction: str, t: float) -> int:
        items = self.lines[direction].pop_due(t)
        dest = DEST[direction]
        self._out.extend(Send(dest, data) for data in items)
        return len(items)


def sim_ms(t: float) -> int:
    """Sim time ``t`` (s) in whole milliseconds (>= 0), the unit of SIM_TICK times."""
    return max(0, int(round(t * 1000.0)))
