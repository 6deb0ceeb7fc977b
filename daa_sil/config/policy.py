"""One experimental group's allocation settings (:class:`AllocationPolicy`): what the agent
(:func:`daa_sil.agent.step.agent_step`) reads per row. It sits in config/ because the group table
(:mod:`daa_sil.config.groups`) builds it and the agent reads it: both import it from here, downward.
Defaults and ranges of its numeric fields are the :mod:`daa_sil.config.settings` ones."""

from __future__ import annotations

from dataclasses import dataclass

from daa_sil.config.choices import AGENT_ACTIVE, DAA_AUTHORITY, UNSAFE_HOLDS, WAIT_RULES
from daa_sil.config.settings import (CONSTANT_WAIT, LINK_TIMEOUT, PROJL_HORIZON, STALE_COMMAND, WAIT_THRESHOLD,
                                     group_settings)
from daa_sil.errors import UsageError

WAIT_MODES = ("none", "constant", "map", "always")


def with_group_settings(cls):
    """Add a field (default and setting from :meth:`Setting.field`) for every registered per-group
    setting the class does not declare itself: a setting registered in
    :mod:`daa_sil.config.settings` is a policy field with no other edit."""
    notes = cls.__dict__.get("__annotations__")
    if notes is None:
        notes = {}
        cls.__annotations__ = notes
    for s in group_settings():
        if s.name not in notes:
            notes[s.name] = "float"
            setattr(cls, s.name, s.field())
    return cls


@dataclass(frozen=True)
@with_group_settings
class AllocationPolicy:
    """One experimental group's allocation settings (groups are data, not code paths: see
    :mod:`daa_sil.config.groups`). Times in s."""

    wait_mode: str  #: :data:`WAIT_MODES`: none (w = 0, always DAA), constant, map, always (w = inf)
    constant_wait_s: float = CONSTANT_WAIT.field()
    wait_threshold_s: float = WAIT_THRESHOLD.field()  #: W_T
    projl: bool = True  #: ProjL veto on (the paper) or off (the map alone decides)
    projl_horizon_s: float = PROJL_HORIZON.field()  #: the paper's N
    blending: bool = True  #: False = baseline: unsafe pilot command -> DAA override
    stale_command_s: float = STALE_COMMAND.field()
    link_timeout_s: float = LINK_TIMEOUT.field()
    wait_rule: str = "threshold"  #: :data:`WAIT_RULES`: w(S(k)) >= W_T every step, or a countdown budget
    name: str = "custom"
    #: :data:`UNSAFE_HOLDS`: an unsafe fresh "hold" is blended / overridden like any command (``blend``)
    #: or decided as if no command had arrived (``no-command``)
    unsafe_hold: str = "blend"
    #: :data:`AGENT_ACTIVE`: the agent decides from the corrective alert (``corrective``) or over the
    #: whole encounter, from its start until safe avoidance (``encounter``)
    active_from: str = "corrective"
    #: :data:`DAA_AUTHORITY`: on a step without a fresh command, Algorithm 1 afresh (``per-step``), or
    #: the DAA keeps an authority it holds until no intruder raises any alert (``until-clear``)
    daa_authority: str = "per-step"
    #: False = the agent never takes authority: the pilot's last command is always flown, the
    #: decision is always ``none`` (alert levels are still computed); the SIL's ``DAA_ENABLE 0``
    enabled: bool = True

    def __post_init__(self):
        if self.wait_mode not in WAIT_MODES:
            raise UsageError(f"wait_mode must be one of {', '.join(WAIT_MODES)}, got {self.wait_mode!r}")
        if self.wait_rule not in WAIT_RULES:
            raise UsageError(f"wait_rule must be one of {', '.join(WAIT_RULES)}, got {self.wait_rule!r}")
        if self.unsafe_hold not in UNSAFE_HOLDS:
            raise UsageError(f"unsafe_hold must be one of {', '.join(UNSAFE_HOLDS)}, got {self.unsafe_hold!r}")
        if self.active_from not in AGENT_ACTIVE:
            raise UsageError(f"active_from must be one of {', '.join(AGENT_ACTIVE)}, got {self.active_from!r}")
        if self.daa_authority not in DAA_AUTHORITY:
            raise UsageError(f"daa_authority must be one of {', '.join(DAA_AUTHORITY)}, got {self.daa_authority!r}")


__all__ = ["AllocationPolicy", "WAIT_MODES", "with_group_settings"]
