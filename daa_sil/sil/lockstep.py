"""The tick protocol, one end of it, sans-IO: :class:`TickPeer`, used by the vehicle and the GCS.

Per step ``k`` (sim time ``t_k``; ``docs/architecture.md``, "The step order")::

    vehicle                      shim                                   GCS
    SIM_TICK(k, t_k)  ───────▶  clock := t_k, release due packets  ───▶ (telemetry due, then the tick)
    (the shim's echo) ◀────────  echo of the tick                        step 1: pilot decides, sends cmds
    (cmds due, then the ack) ◀── cmds queued at t_k, ack forwarded ◀─── SIM_TICK_ACK(k)

The vehicle sends ticks and hears two partners: the shim, which echoes each tick it processed
(it is alive, and every uplink packet due at ``t_k`` has been sent), and the GCS, which
acknowledges each tick once its step is done (cumulative). The GCS hears one partner, the
vehicle side, whose ticks step it; a repeated tick is acknowledged again without a second step.
With signing, ticks and acks travel on their own signing stream
(:data:`~daa_sil.link.codec.CONTROL_LINK_ID`) because they overtake delayed data in the shim.

A :class:`TickPeer` encodes its own control messages and keeps, per partner, the newest tick it
confirmed and a :class:`daa_sil.sil.silence.Silence` watch (``SILENT_AFTER_S`` of the role). It
reads no clock and owns no socket: the caller passes wall times in and sends the bytes.
"""

from __future__ import annotations

import math

from daa_sil.link.codec import CONTROL_LINK_ID, MavCodec
from daa_sil.link.messages import sim_tick, sim_tick_ack
from .silence import SILENT_AFTER_S, Silence

#: who each role hears tick-protocol messages from: the vehicle the shim's echoes and the GCS's acks,
#: the GCS the ticks of the vehicle side (the vehicle, through a shim or not)
PARTNERS = {"vehicle": ("shim", "gcs"), "gcs": ("vehicle",)}


class TickPeer:
    """One end of the tick protocol: ``role`` ``"vehicle"`` (sends ticks) or ``"gcs"`` (acknowledges them).

    ``sent``: the newest tick this end sent (vehicle: SIM_TICK) or acknowledged (GCS: its step done).
    ``newest[who]``: the newest tick ``who`` confirmed (vehicle: echoed / acknowledged one it sent)
    or sent (GCS: the vehicle side's newest tick). ``partner`` (vehicle): who confirms its ticks --
    ``"shim"`` once one echoes, ``"gcs"`` wired straight to a GCS, ``"none"`` for a peer that
    answers no tick (free-running realtime).
    """

    def __init__(self, role: str, codec: MavCodec):
        if role not in PARTNERS:
            raise ValueError(f"role must be one of {', '.join(PARTNERS)}, got {role!r}")
        self.role = role
        self.codec = codec
        self.link_id = CONTROL_LINK_ID if codec.signed else None
        self.sent = -1
        self.newest = dict.fromkeys(PARTNERS[role], -1)
        self.heard = dict.fromkeys(PARTNERS[role], 0)  #: tick-protocol messages taken from each partner
        self.newest_t = -math.inf  #: GCS: sim time of the newest tick (s)
        self.skipped = 0  #: GCS: ticks never received between two received ones (no step ran for them)
        self.partner = "none"
        self.silence = {who: Silence(SILENT_AFTER_S[role]) for who in PARTNERS[role]}
        self.silence_warnings = 0

    # -- the vehicle's end -----------------------------------------------------------------------
    def tick(self, k: int, t: float) -> bytes:
        """The datagram of ``SIM_TICK(k, t)`` (``t`` sim s), alone; noted as sent."""
        data = self.codec.encode(sim_tick(k, t), link_id=self.link_id)
        self.sent = max(self.sent, int(k))
        return data

    def answered(self, who: str, k: int, now: float) -> "float | None":
        """An echo (``who="shim"``) or an ack (``"gcs"``) of tick ``k`` at wall time ``now`` (s).

        One of a tick never sent changes nothing. Returns the seconds ``who`` had been reported
        silent, if this answer ends that, else None."""
        if k > self.sent:
            return None
        self.heard[who] += 1
        self.newest[who] = max(self.newest[who], int(k))
        if who == "shim":
            self.partner = "shim"
        elif self.partner == "none":
            self.partner = "gcs"
        return self.silence[who].heard(now)

    def ready(self, k: int, need_ack: bool = False) -> bool:
        """Lockstep: may step ``k`` run? Once the GCS acknowledged tick ``k``; behind a shim already on
        its echo of tick ``k >= 1`` (the shim processes tick ``k`` only after the GCS acknowledged
        tick ``k - 1``, so every uplink packet due at ``t_k`` has been sent; what the GCS sends at
        ``t_k`` is released at tick ``k + 1`` at the earliest). Tick 0 and ``need_ack`` wait for the ack."""
        return self.newest["gcs"] >= k or (k > 0 and not need_ack and self.newest["shim"] >= k)

    def confirmed(self, k: int) -> bool:
        """Realtime: has the partner answered tick ``k``? (True without a partner: free-running.)"""
        if self.partner == "none":
            return True
        return self.newest[self.partner] >= k

    # -- the GCS's end ---------------------------------------------------------------------------
    def on_tick(self, k: int, t: float, now: float) -> "tuple[bool, float | None]":
        """``SIM_TICK(k, t)`` from the vehicle side at wall time ``now`` (s): ``(step, back)``. ``step``: ``k``
        is newer than every tick acknowledged so far, so run its step, then :meth:`ack` it (a step that
        failed is not acknowledged and runs again on the repeated tick); ``back``: the seconds the ticks
        had been reported silent, if this one ends that."""
        self.newest_t = max(self.newest_t, float(t))
        self.newest["vehicle"] = max(self.newest["vehicle"], int(k))
        self.heard["vehicle"] += 1
        back = self.silence["vehicle"].heard(now)
        done = self.sent
        if k <= done:
            return False, back
        if done >= 0 and k > done + 1:
            self.skipped += k - done - 1  # missed ticks: steps lockstep would have run
        return True, back

    def ack(self, k: int, time_ms: int, sent: int = 0) -> bytes:
        """The datagram of ``SIM_TICK_ACK(k)`` echoing the tick's ``time_ms``; ``sent``: messages of the step."""
        data = self.codec.encode(sim_tick_ack(k, time_ms / 1000.0, sent), link_id=self.link_id)
        self.sent = max(self.sent, int(k))
        return data

    # -- both ------------------------------------------------------------------------------------
    def check_silence(self, now: float, after_s: "float | None" = None) -> "list[tuple[str, float]]":
        """Partners that become silent at wall time ``now`` (s): ``[(who, quiet s)]``, each reported once
        until heard again. The GCS behind a silent shim is not reported: the shim is the news."""
        out = []
        for who, watch in self.silence.items():
            quiet = watch.check(now, after_s)
            if quiet is None or (who == "gcs" and self.silence["shim"].silent):
                continue
            out.append((who, quiet))
        self.silence_warnings += len(out)
        return out
