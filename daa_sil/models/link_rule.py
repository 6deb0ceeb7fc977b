"""How a group's latency value reaches the two links: the latency rules of the readings.

The paper's only sentence on what its latency measures is "The round-trip latency duration can be in
the range of 0.2 to 10 seconds" (Problem Formulation); none says whether the groups' values are
one-way or round trip. :data:`LATENCY_RULES`:

* ``one-way`` -- the value is each link's delay, uplink and downlink drawn from their own streams
  (a round trip of twice the value);
* ``round-trip`` -- the value is the round trip, split evenly: each link applies
  :class:`HalfRoundTrip` of it, and both links read the *same* draw sequence (the uplink stream), so
  in every delay epoch uplink + downlink = the round trip drawn for it.

:func:`link_legs` gives the two links' models (:class:`LinkLegs`); the processes are built by
:func:`daa_sil.models.delay_process.link_delay_processes` (SIL) and
:func:`daa_sil.models.delay_process.batched_link_delays` (fast-time).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from daa_sil.errors import UsageError
from daa_sil.models.latency import DelayModel

#: how a group's latency value reaches the two links (see the module docstring)
LATENCY_RULES = ("one-way", "round-trip")


class HalfRoundTrip(DelayModel):
    """One link's share of a round-trip delay model: half of each draw of ``round_trip`` (s).

    Used by the ``round-trip`` rule (:func:`link_legs`): both links apply this model to the same
    draw sequence, so each gets exactly half of the round trip drawn for the epoch (halving is
    exact in binary floating point).
    """

    kind = "half"

    def __init__(self, round_trip: DelayModel):
        if not isinstance(round_trip, DelayModel) or isinstance(round_trip, HalfRoundTrip):
            raise UsageError(f"a half round trip needs a round-trip delay model, got {round_trip!r}")
        self.round_trip = round_trip

    def __eq__(self, other) -> bool:
        return isinstance(other, HalfRoundTrip) and other.round_trip == self.round_trip

    def __hash__(self) -> int:
        return hash(("half", self.round_trip.spec()))

    @property
    def draws(self) -> bool:
        """Whether :meth:`sample` reads its generator: the round trip's answer."""
        return self.round_trip.draws

    def sample(self, rng, t):
        return 0.5 * np.asarray(self.round_trip.sample(rng, t), dtype=float)

    def mean(self) -> float:
        return 0.5 * self.round_trip.mean()

    def to_dict(self) -> dict:
        return {"type": "half", "round_trip": self.round_trip.to_dict()}

    def spec(self) -> str:
        return f"half:{self.round_trip.spec()}"


@dataclass(frozen=True)
class LinkLegs:
    """What each link applies: ``up`` (GCS -> vehicle) and ``down`` (vehicle -> GCS) delay models,
    and whether the downlink reads the uplink's draw sequence (``shared``: one round trip per epoch)."""

    up: DelayModel
    down: DelayModel
    shared: bool = False
    rule: str = "one-way"


def link_legs(model: DelayModel, rule: str = "one-way", down: "DelayModel | None" = None) -> LinkLegs:
    """The two links' delays for a latency value under ``rule`` (:data:`LATENCY_RULES`).

    ``one-way``: ``model`` on the uplink and ``down`` (default ``model``) on the downlink, each from
    its own stream. ``round-trip``: ``model`` is the round trip; each link applies
    :class:`HalfRoundTrip` of it to the uplink stream's draws (``down`` must be None or equal).
    """
    if rule not in LATENCY_RULES:
        raise UsageError(f"latency rule must be one of {', '.join(LATENCY_RULES)}, got {rule!r}")
    if rule == "one-way":
        return LinkLegs(model, down if down is not None else model, False, rule)
    if down is not None and down != model:
        raise UsageError(f"a round trip is one delay, got {model.spec()} up and {down.spec()} down")
    if isinstance(model, HalfRoundTrip):
        return LinkLegs(model, model, True, rule)
    half = HalfRoundTrip(model)
    return LinkLegs(half, half, True, rule)


__all__ = ["LATENCY_RULES", "HalfRoundTrip", "LinkLegs", "link_legs"]
