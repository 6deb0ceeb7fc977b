"""The allowed values of the agent's and the pilot model's switchable rules, defined once: the agent
(:mod:`daa_sil.agent`), the pilot model (:mod:`daa_sil.models.pilot_config`) and the named readings
(:mod:`daa_sil.config.readings`) import them. What each value does is documented where it acts."""

from __future__ import annotations

#: the agent's waiting equation: ``threshold`` (w(S(k)) >= W_T read afresh every step) or
#: ``countdown`` (w is a budget counted from the start of the current wait)
WAIT_RULES = ("threshold", "countdown")
#: a fresh, unsafe "hold" (a pilot command without a maneuver intent): ``blend`` it like any command
#: (Algorithm 1), or treat it as ``no-command`` (the agent decides wait / no wait)
UNSAFE_HOLDS = ("blend", "no-command")
#: the wait read for a state outside the wait map's box: ``clamp`` (the nearest state of the box) or
#: ``far`` (the map does not model that intruder: w = H)
OUTSIDE_BOX = ("clamp", "far")
#: when the pilot model stops streaming: ``alert`` (when its alert clears) or ``safe-avoidance``
#: (when its display shows no alert and every intruder past its closest point of approach)
PILOT_STOPS = ("alert", "safe-avoidance")

#: when the agent decides: from the ``corrective`` alert (its active phase), or over the whole
#: ``encounter`` -- every step from the start until safe avoidance (no alert, every intruder past
#: its closest point of approach), and from any later corrective alert
AGENT_ACTIVE = ("corrective", "encounter")

__all__ = ["WAIT_RULES", "UNSAFE_HOLDS", "OUTSIDE_BOX", "PILOT_STOPS", "AGENT_ACTIVE"]
