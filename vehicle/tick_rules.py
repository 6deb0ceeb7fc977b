"""The vehicle's tick rules, sans-IO: when a step may run, when to send a tick again, when to give up,
and who to blame.

The protocol state (ticks sent, echoes and acks heard, silence) is a
:class:`daa_sil.sil.lockstep.TickPeer`; :class:`TickRules` adds the rules that need wall time. The
node (:mod:`vehicle.node`) only waits: it asks :meth:`TickWait.next_timer` when to wake and calls
:meth:`TickWait.on_timer` then.

* **lockstep**: send ``SIM_TICK(k, t_k)`` alone in its datagram to the peer (the shim), then
  receive until the shim echoes it: the shim processes tick ``k`` (releases every packet due at
  ``t_k``, forwards the tick to the GCS, echoes it) only once the GCS acknowledged tick ``k - 1``,
  so the GCS's step ``k`` and this step ``k`` run in parallel -- neither reads the other's output
  of the same tick, which the shim releases at tick ``k + 1`` at the earliest
  (:meth:`daa_sil.sil.lockstep.TickPeer.ready`). Tick 0 and the end of the run wait for the GCS's
  ``SIM_TICK_ACK``; wired straight to a GCS (no shim, no echo) every tick does. No answer within
  ``tick_timeout_s`` wall seconds -> :class:`TickTimeout` (one clear line naming who is silent:
  :meth:`TickRules.who_is_silent`). The tick is re-sent every ``tick_retry_s`` in case a datagram
  was lost (the GCS re-acks a tick it already did; a shim holding tick ``k`` for the GCS's ack of
  tick ``k - 1`` gets that one again too, and echoes it). So a shim that has echoed nothing for two
  retry periods has stopped itself (Ctrl-Z, SIGSTOP, gone), whatever the GCS behind it does, and is
  named; a shim that echoes while the GCS does not acknowledge names the GCS.
* **realtime** (docs/sil.md, "Realtime and lockstep"): the same ticks, paced by the wall clock.
  ``SIM_TICK(k)`` goes out a lead of half a step (at most 0.25 s) before the step's deadline
  ``W_k = t0 + t_k / speed``; once the partner's answer is in, every input of step ``k`` is there
  (uplink is released only at ticks), so the node computes the step then and publishes it at
  ``W_k``; it waits at most half a step past ``W_k`` for a late answer. Partner = the shim (it
  echoes) or, wired straight to a GCS, the GCS (it acks); a peer that answers no tick (a stock
  GCS) gives free-running realtime. A partner silent for ``SILENT_AFTER_S`` (:mod:`daa_sil.sil.silence`)
  is reported and not waited for until it answers again; steps that ran without their
  confirmation are counted (``steps_unconfirmed``: 0 means lockstep-equivalent input).
"""

from __future__ import annotations

from dataclasses import dataclass

from daa_sil.errors import DaaSilError
from daa_sil.sil.lockstep import TickPeer

#: realtime: SIM_TICK(k) is sent this fraction of a step before step k's deadline (at most TICK_LEAD_MAX_S)
TICK_LEAD_FRACTION = 0.5
TICK_LEAD_MAX_S = 0.25
#: realtime: wait at most this fraction of a step past the deadline for the partner's answer to the tick
CONFIRM_GRACE_FRACTION = 0.5
#: a partner is also silent after this many steps without an answer if that is shorter (fast runs), >= 1 s
SILENT_AFTER_STEPS = 10
#: the first retries of tick 0 come at most this often (s): the GCS and the shim may still be starting
START_RETRY_S = 0.2
#: an ICMP "port unreachable" this recent (s) means nothing listens at the peer
REFUSED_RECENT_S = 5.0


class TickTimeout(DaaSilError):
    """The lockstep partner did not acknowledge a tick in time."""


@dataclass(frozen=True)
class TickOptions:
    """The tick settings of a vehicle (wall seconds; ``clock`` ``realtime`` or ``lockstep``)."""

    clock: str = "realtime"
    speed: float = 1.0
    tick_timeout_s: float = 10.0
    tick_retry_s: float = 2.0
    start_timeout_s: "float | None" = None
    tick_sync: str = "auto"


class TickRules:
    """The vehicle's end of the tick protocol (see the module docstring). ``out_text``: the pilot
    link's address as given (for messages); ``dt``: the step (sim s); ``stats``: the node's counters
    (:class:`vehicle.node_options.VehicleStats`)."""

    def __init__(self, peer: TickPeer, opts: TickOptions, dt: float, stats, out_text: str):
        self.peer, self.opts, self.dt, self.stats, self.out_text = peer, opts, float(dt), stats, out_text

    # -- answers ---------------------------------------------------------------------------------
    def answered(self, who: str, k: int, t: float, now: float) -> "str | None":
        """An echo (``who="shim"``) or an ack (``"gcs"``) of tick ``k`` at wall ``now`` (s) during the step
        at ``t`` (sim s); returns a line to report if ``who`` had been reported silent."""
        back = self.peer.answered(who, k, now)
        self.stats.sync_partner = self.peer.partner
        if back is None:
            return None
        return (f"the {'shim' if who == 'shim' else 'GCS'} answers ticks again at t = {t:g} s "
                f"(silent for {back:.1f} s)")

    def silence_warnings(self, now: float) -> "list[str]":
        """Lines for a shim or GCS that answered ticks and then stopped (once, until it answers again):
        no answer for the role's SILENT_AFTER_S, or SILENT_AFTER_STEPS steps if that is shorter, >= 1 s."""
        watch = self.peer.silence["shim"]
        limit = max(1.0, min(watch.after_s, SILENT_AFTER_STEPS * self.dt / self.opts.speed))
        out = []
        for who, quiet in self.peer.check_silence(now, limit):
            self.stats.silence_warnings += 1
            if who == "shim":
                why = f"the shim at {self.out_text} has not echoed a tick for {quiet:.1f} s: has it stopped?"
            elif self.peer.partner == "shim":
                why = (f"the GCS behind the shim at {self.out_text} has not acknowledged a tick for {quiet:.1f} s "
                       f"(last tick acked: {self.peer.newest['gcs']}): has it stopped?")
            else:
                why = f"the GCS at {self.out_text} has not acknowledged a tick for {quiet:.1f} s: has it stopped?"
            out.append(f"warning: {why} Flying on; the agent hands over to the onboard DAA when the link times out")
        return out

    def who_is_silent(self, k: int, now: float, last_refused: "float | None" = None) -> str:
        """Why tick ``k`` got no answer by wall ``now`` (s): which of shim and GCS is not there (for the
        one-line error). ``last_refused``: wall time of the last ICMP port unreachable, if any."""
        peer, echoed, acked = self.out_text, self.peer.newest["shim"], self.peer.newest["gcs"]
        shim_last = self.peer.silence["shim"].last
        stalled_after = max(2 * self.opts.tick_retry_s, START_RETRY_S)
        if self.peer.partner == "shim" and shim_last is not None and now - shim_last >= stalled_after:
            # a live shim echoes every tick it processes, a repeated one too (the retries): no echo at all means
            # the shim itself stopped reading -- whatever the GCS behind it does
            return (f"the shim at {peer} has echoed nothing for {now - shim_last:.1f} s, not even the repeated "
                    f"ticks (last echo: tick {echoed}): is the shim still running, or stopped (Ctrl-Z, SIGSTOP)?")
        if k > 0 and echoed == k - 1 and acked < k - 1:
            return (f"the shim at {peer} holds tick {k} until the GCS behind it acknowledges tick {k - 1}, which "
                    f"it has not: is daa-gcs still running (with --clock lockstep), pointed at the shim's GCS side?")
        if echoed >= k:
            return (f"the shim at {peer} relays tick {k} but the GCS behind it does not acknowledge it: is daa-gcs "
                    f"running (with --clock lockstep) and pointed at the shim's GCS side?")
        if last_refused is not None and now - last_refused < REFUSED_RECENT_S:
            return (f"nothing is listening at {peer} (ICMP port unreachable): is the shim (or the GCS) running "
                    f"there?")
        return (f"no answer at all from {peer} (no tick echo, no ack): is a lockstep shim or GCS running there "
                f"with --clock lockstep?")

    # -- lockstep --------------------------------------------------------------------------------
    def wait(self, k: int, t: float, now: float, need_ack: bool = False) -> "TickWait":
        """The wait for step ``k`` (at ``t`` sim s) that starts at wall ``now`` (s); send tick ``k`` first."""
        return TickWait(self, k, t, now, need_ack)

    # -- realtime --------------------------------------------------------------------------------
    def lead_s(self, period: float) -> float:
        """How long (wall s) before a step's deadline its tick goes out."""
        return min(TICK_LEAD_FRACTION * period, TICK_LEAD_MAX_S)

    def note_late_ack(self, k: int) -> None:
        """Realtime, before tick ``k`` goes out: count the GCS's ack of ``k - 1`` as late if it is missing
        while both partners are heard."""
        gcs, shim = self.peer.silence["gcs"], self.peer.silence["shim"]
        if self.peer.newest["gcs"] < k - 1 and gcs.last is not None and not gcs.silent and not shim.silent:
            self.stats.acks_late += 1

    def confirm_deadline(self, due: float, period: float) -> "tuple[float, bool]":
        """Realtime: until when (wall s) to take messages before publishing the step due at ``due``, and
        whether to stop as soon as the tick is confirmed: with a partner that is not silent, up to a
        grace past the deadline; without one, the deadline itself."""
        partner = self.peer.partner
        if partner == "none" or self.peer.silence[partner].silent:
            return due, False
        return due + CONFIRM_GRACE_FRACTION * period, True

    def confirmed(self, k: int) -> bool:
        return self.peer.confirmed(k)

    def note_unconfirmed(self, k: int) -> None:
        """Realtime: count step ``k`` if it runs before its tick was confirmed."""
        if not self.peer.confirmed(k):
            self.stats.steps_unconfirmed += 1


class TickWait:
    """Lockstep: waiting for step ``k`` (a :meth:`TickRules.wait`). ``ready()`` says it may run;
    ``next_timer()`` is the wall time (s) to wake if nothing arrives; ``on_timer(now)`` returns the
    ticks ``(k, t)`` to send again, or raises :class:`TickTimeout` past the limit."""

    def __init__(self, rules: TickRules, k: int, t: float, now: float, need_ack: bool):
        opts = rules.opts
        self.rules, self.k, self.t, self.need_ack = rules, int(k), float(t), bool(need_ack)
        self.limit = opts.start_timeout_s if k == 0 and opts.start_timeout_s is not None else opts.tick_timeout_s
        self.deadline = now + self.limit
        self.retry = opts.tick_retry_s if k > 0 else min(START_RETRY_S, opts.tick_retry_s)
        self.next_retry = now + self.retry

    def ready(self) -> bool:
        return self.rules.peer.ready(self.k, self.need_ack)

    def next_timer(self) -> float:
        return min(self.deadline, self.next_retry)

    def on_timer(self, now: float, last_refused: "float | None" = None) -> "list[tuple[int, float]]":
        """The timer fired at wall ``now`` (s): the ticks to send again (``(k, t)``), or TickTimeout."""
        rules = self.rules
        if now >= self.deadline:
            peer = rules.peer
            what = "SIM_TICK_ACK" if self.need_ack or self.k == 0 or peer.partner != "shim" else "echo"
            raise TickTimeout(f"no {what} for tick {self.k} (t = {self.t:g} s) within {self.limit:g} s: "
                              + rules.who_is_silent(self.k, now, last_refused))
        if now < self.next_retry:
            return []
        again = []
        if self.k > 0 and not self.need_ack and rules.peer.newest["gcs"] < self.k - 1:
            # a shim holds tick k until the GCS acknowledges tick k - 1: send that one again too (the shim
            # forwards a repeated tick), in case it was lost
            again.append((self.k - 1, self.t - rules.dt))
        again.append((self.k, self.t))
        rules.stats.tick_retries += 1
        self.next_retry = now + self.retry
        return again
