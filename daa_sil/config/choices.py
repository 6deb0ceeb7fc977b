"""The allowed values of the agent's and the pilot model's switchable rules, defined once: the agent
(:mod:`daa_sil.agent.step`), the pilot model (:mod:`daa_sil.models.pilot_config`) and the named readings
(:mod:`daa_sil.config.readings`) import them; so do the run configuration's presets
(:mod:`daa_sil.config.run_config` and the ``--config`` option, :mod:`daa_sil.config.config_option`). What each value does is documented where it acts."""

from __future__ import annotations

#: the agent's waiting equation: ``threshold`` (w(S(k)) >= W_T read afresh every step) or
#: ``countdown`` (w is a budget counted from the start of the current wait)
WAIT_RULES = ("threshold", "countdown")
#: a fresh, unsafe "hold" (a pilot command without a maneuver intent): ``blend`` it like any command
#: (Algorithm 1), or treat it as ``no-command`` (the agent decides wait / no wait)
UNSAFE_HOLDS = ("blend", "no-command")
#: the wait read for a state outside the wait map's box: ``clamp`` (the nearest state of the box),
#: ``far`` (the map does not model that intruder: w = H) or ``approach`` (the time the relative state
#: needs, on a straight line, to enter the box plus the wait at its entry point, at most H; H where
#: it never enters): :func:`daa_sil.agent.wait_function.make_wait_lookup`
OUTSIDE_BOX = ("clamp", "far", "approach")
#: when the pilot model stops streaming: ``alert`` (when its alert clears) or ``safe-avoidance``
#: (when its display shows no alert and every intruder past its closest point of approach)
PILOT_STOPS = ("alert", "safe-avoidance")

#: when the agent decides: from the ``corrective`` alert (its active phase), or over the whole
#: ``encounter`` -- every step from the start until safe avoidance (no alert, every intruder past
#: its closest point of approach), and from any later corrective alert
AGENT_ACTIVE = ("corrective", "encounter")

#: what the agent does on a step without a fresh command once the onboard DAA holds authority:
#: ``per-step`` (Algorithm 1 every step: wait or not by Eq. 11 afresh) or ``until-clear`` (our
#: extension: the DAA keeps authority on such steps until no intruder raises any alert; a fresh
#: pilot command is still decided by Algorithm 1)
DAA_AUTHORITY = ("per-step", "until-clear")

#: how a link delay drawn from a distribution varies: one draw per ``epoch`` (the link's delay epoch,
#: :data:`daa_sil.config.settings.DELAY_EPOCH`) or one draw per ``encounter`` (constant over it)
DELAY_DRAWS = ("epoch", "encounter")

#: the named run-configuration presets (:func:`daa_sil.config.run_config.preset`); here, below both
#: the ``--config`` option and the configuration it loads, so that neither imports the other for them
PRESET_NAMES = ("paper", "do365", "daidalus")

__all__ = ["WAIT_RULES", "UNSAFE_HOLDS", "OUTSIDE_BOX", "PILOT_STOPS", "AGENT_ACTIVE", "DAA_AUTHORITY",
           "DELAY_DRAWS", "PRESET_NAMES"]
