"""The delay shim's tick handling: in lockstep and realtime-ticks modes the shim's sim clock follows
the vehicle's SIM_TICK, releases what is due at each tick, forwards the tick to the GCS and echoes
it, and keeps the tick schedule statistics.

Lockstep pipelining: a new tick ``k`` that arrives while the GCS has not yet acknowledged the tick
it was forwarded last (``k - 1``) is **held** (``ticks_held``) and processed the moment that ack
arrives. So the GCS's step-(k-1) datagram is queued (stamped ``t_{k-1}``) before tick ``k``
releases anything, exactly as when the vehicle waited for the ack itself; but the vehicle can run
its step ``k - 1`` while the GCS runs its own, on the shim's echo. Neither needs the other's step
of the same tick: the shim releases packets only when it processes a tick, so what either side
sends during tick ``k`` reaches the other at tick ``k + 1`` at the earliest. (A vehicle whose tick
is held past its retry interval re-sends tick ``k - 1`` before tick ``k``: a repeated tick is
forwarded again, so a lost one is recovered, signed or not.)

Fault draws (loss, duplication, reordering) are keyed on what a datagram is in the simulation, not
on how many datagrams came before it (:meth:`daa_sil.link.delayline.DelayLine.fault_uniforms`), so
traffic whose amount depends on the wall clock -- the GCS's greetings before the first tick, a
repeated tick -- cannot shift the faults of the simulation's own datagrams:

* before the first tick: ``(KEY_START, 0, n)``, ``n`` = the line's n-th start-up datagram;
* lockstep, from the GCS while a tick forwarded to it awaits its ack (its step's datagrams): held
  until that ack (or the next tick) and keyed ``(KEY_BACK, t_ms, n)``, ``n`` counted back from the
  ack, so a greeting sent before the GCS saw its first tick but read after it comes first and does
  not move the keys of the step's datagrams; they enter the line before the next tick releases
  anything, as before;
* otherwise ``(KEY_STEP, t_ms, n)``: the n-th datagram stamped ``t_ms`` (ms) on that line.

Free-running realtime (no ticks) keeps the line's sequential stream."""

from __future__ import annotations

import asyncio

import numpy as np

from daa_sil.sil.shim_config import ACK_ID, TICK_ID, control_ids

#: a GCS that has not acknowledged this many forwarded ticks is taken as gone (stamps fall back to the last tick)
MAX_GCS_LAG_TICKS = 8
#: first element of a fault-draw key (module docstring)
KEY_START, KEY_STEP, KEY_BACK = 0, 1, 2
#: per line, stamps whose datagram counts are kept (the oldest is forgotten past this)
MAX_COUNTED_STAMPS = 64


class ShimTicks:
    """Part of :class:`daa_sil.sil.shim.DelayShim` (a mixin: it uses the shim's attributes)."""

    def _tick_datapath(self, side: str, data: bytes, t_rx: "float | None") -> None:
        """Lockstep rules (module docstring): control messages move the clock, data is stamped by ticks."""
        c = self.counters
        ids = control_ids(data)
        want = TICK_ID if side == "vehicle" else ACK_ID
        if want in ids:
            msg = self._decode_control(data, want)
            if msg is not None:
                if -1 in ids:
                    c["mixed_control"] += 1
                if side == "vehicle":
                    self._on_tick(msg, data, t_rx)
                else:
                    self._on_ack(msg, data)
                return
            c["bad_control"] += 1
        if side == "vehicle":
            self.lines["down"].push(self.sim_time, data, key=self._fault_key("down", self.sim_time))
            return
        stamp = self._gcs_stamp()
        if self.config.clock == "lockstep" and self._unacked:
            self._gcs_batch.append((stamp, data))  # the GCS's step: keyed back from its ack
            return
        self._push_up(stamp, data, self._fault_key("up", stamp))

    def _push_up(self, stamp: float, data: bytes, key: tuple) -> None:
        recs = self.lines["up"].push(stamp, data, key=key)
        if stamp < self.sim_time and any(not r.dropped and r.t_out <= self.sim_time for r in recs):
            self.counters["released_late"] += 1  # lockstep would have released it at a tick already processed

    def _fault_key(self, direction: str, stamp: float) -> tuple:
        """Fault-draw key of the next datagram stamped ``stamp`` (s) on ``direction`` (module docstring)."""
        if self.last_tick is None:
            n = self._start_count[direction]
            self._start_count[direction] = n + 1
            return (KEY_START, 0, n)
        ms, counts = _ms(stamp), self._stamp_count[direction]
        n = counts.get(ms, 0)
        counts[ms] = n + 1
        if len(counts) > MAX_COUNTED_STAMPS:
            del counts[min(counts)]
        return (KEY_STEP, ms, n)

    def _flush_gcs_batch(self) -> None:
        """Lockstep: push the GCS datagrams held since the last tick forwarded to it, keyed back from now."""
        batch, self._gcs_batch = self._gcs_batch, []
        after: dict[int, int] = {}
        keys = []
        for stamp, _ in reversed(batch):
            ms = _ms(stamp)
            keys.append((KEY_BACK, ms, after.get(ms, 0)))
            after[ms] = after.get(ms, 0) + 1
        for (stamp, data), key in zip(batch, reversed(keys)):
            self._push_up(stamp, data, key)

    def _gcs_stamp(self) -> float:
        """Sim time a GCS datagram is sent at: the oldest tick it has not acknowledged (module docstring)."""
        if self._gcs_acks and self._unacked:
            t = self._unacked[0][1]
            if t < self.sim_time:
                self.counters["gcs_lagged"] += 1
            return t
        return self.sim_time

    def _decode_control(self, data: bytes, want: int):
        msgs = self.codec.decode(data)
        for m in msgs:
            if m.get_msgId() == want:
                return m
        return None

    def _on_tick(self, msg, data: bytes, t_rx: "float | None" = None) -> None:
        c = self.counters
        c["ticks"] += 1
        if self.config.clock == "lockstep" and self._unacked and int(msg.tick) > self._unacked[-1][0]:
            self._held_tick = (msg, data, t_rx)  # the newest copy (a retry replaces it)
            c["ticks_held"] += 1
            return
        self._process_tick(msg, data, t_rx)

    def _process_tick(self, msg, data: bytes, t_rx: "float | None") -> None:
        c = self.counters
        self._flush_gcs_batch()
        rx = (t_rx if t_rx is not None else self._loop.time()) if self.config.clock == "realtime" else 0.0
        t_k = msg.time_ms / 1000.0
        k = int(msg.tick)
        if t_k < self.sim_time:
            c["clock_backwards"] += 1
        else:
            self.sim_time = t_k
        self.last_tick = k
        n = self._release("down", self.sim_time) + self._release("up", self.sim_time)
        if self._send("gcs", data) and (not self._unacked or self._unacked[-1][0] < k):
            self._unacked.append((k, t_k))
            if len(self._unacked) > MAX_GCS_LAG_TICKS:  # the GCS ignores ticks: gone, or not ack-capable
                self._unacked.clear()
                if self._gcs_acks:
                    c["gcs_unresponsive"] += 1
                self._gcs_acks = False
        side = self.sides.get("vehicle")
        if side is not None and not side.closed and side.sendto(data, self.peers["vehicle"]):
            c["tick_echoes"] += 1  # "shim alive, uplink due at t_k sent"
        if self.config.clock == "realtime" and k not in self._seen_ticks and len(self._tick_log) < 1_000_000:
            self._seen_ticks.add(k)
            self._tick_log.append((t_k, rx, self._loop.time(), n))
        for item in list(self._tick_waiters):
            if item[0] <= self.last_tick and not item[1].done():
                item[1].set_result(self.last_tick)
        self._tick_waiters = [w for w in self._tick_waiters if not w[1].done()]

    def _on_ack(self, msg, data: bytes) -> None:
        self.counters["acks"] += 1
        self._flush_gcs_batch()
        self._gcs_acks = True
        k = int(msg.tick)
        while self._unacked and self._unacked[0][0] <= k:
            self._unacked.popleft()
        self._send("vehicle", data)
        if self._held_tick is not None and not self._unacked:  # lockstep: the held tick may go now
            held, self._held_tick = self._held_tick, None
            self._process_tick(*held)

    # -- observability -----------------------------------------------------------------------------
    async def wait_tick(self, tick: int, timeout: float) -> int:
        """Wait (lockstep) until a tick >= ``tick`` has been processed; returns the last tick."""
        if self.last_tick is not None and self.last_tick >= tick:
            return self.last_tick
        fut = asyncio.get_running_loop().create_future()
        self._tick_waiters.append((tick, fut))
        return await asyncio.wait_for(fut, timeout)

    def _tick_origin(self) -> "float | None":
        """Wall origin of the tick schedule: min over ticks k >= 1 of (arrival - t_k / speed) (s)."""
        rows = [(t, rx) for t, rx, _, _ in self._tick_log if t > 0]
        if not rows:
            return None
        return min(rx - t / self.config.speed for t, rx in rows)

    def _tick_lateness(self) -> "np.ndarray | None":
        """Per released packet: wall s from its tick's ideal instant to the end of that tick's releases."""
        w0 = self._tick_origin()
        if w0 is None:
            return None
        out = [done - (w0 + t / self.config.speed) for t, _, done, n in self._tick_log if t > 0 for _ in range(n)]
        return np.array(out, float)

    def _tick_schedule_stats(self) -> dict:
        """How late ticks arrived against their schedule (ms): the vehicle's pacing plus the transit."""
        w0 = self._tick_origin()
        if w0 is None:
            return {"ticks": len(self._tick_log)}
        late = np.array([rx - (w0 + t / self.config.speed) for t, rx, _, _ in self._tick_log if t > 0]) * 1000.0
        return {"ticks": int(late.size), "arrival_late_p50_ms": float(np.percentile(late, 50)),
                "arrival_late_p99_ms": float(np.percentile(late, 99)), "arrival_late_max_ms": float(late.max())}


def _ms(t: float) -> int:
    """Sim time ``t`` (s) in whole milliseconds (>= 0), the unit of SIM_TICK times."""
    return max(0, int(round(t * 1000.0)))
