"""Allocation policies: one group's settings (:class:`AllocationPolicy`) and a batch of encounters
that fly different groups side by side (:class:`PolicyRows`, row ``i`` flies ``policies[index[i]]``).

Groups are data, not code paths (:mod:`daa_sil.config.groups`): the agent
(:func:`daa_sil.agent.agent_step`) reads every setting per row, so one call can decide for
encounters of several groups at once, with exactly the numbers each group would get alone.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Iterator, Sequence

import numpy as np

from daa_sil.config.choices import AGENT_ACTIVE, UNSAFE_HOLDS, WAIT_RULES
from daa_sil.errors import UsageError

WAIT_MODES = ("none", "constant", "map", "always")


@dataclass(frozen=True)
class AllocationPolicy:
    """One experimental group's allocation settings (groups are data, not code paths: see
    :mod:`daa_sil.config.groups`). Times in s."""

    wait_mode: str  #: :data:`WAIT_MODES`: none (w = 0, always DAA), constant, map, always (w = inf)
    constant_wait_s: float = 5.0
    wait_threshold_s: float = 4.0  #: W_T
    projl: bool = True  #: ProjL veto on (the paper) or off (the map alone decides)
    projl_horizon_s: float = 25.0  #: the paper's N
    blending: bool = True  #: False = baseline: unsafe pilot command -> DAA override
    stale_command_s: float = 15.0
    link_timeout_s: float = 20.0
    wait_rule: str = "threshold"  #: :data:`WAIT_RULES`: w(S(k)) >= W_T every step, or a countdown budget
    name: str = "custom"
    #: :data:`UNSAFE_HOLDS`: an unsafe fresh "hold" is blended / overridden like any command (``blend``)
    #: or decided as if no command had arrived (``no-command``)
    unsafe_hold: str = "blend"
    #: :data:`AGENT_ACTIVE`: the agent decides from the corrective alert (``corrective``) or over the
    #: whole encounter, from its start until safe avoidance (``encounter``)
    active_from: str = "corrective"
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


@dataclass(frozen=True)
class PolicyRows:
    """The policies of a batch of N encounters: row ``i`` flies ``policies[index[i]]``.

    :meth:`value` gives one setting per row ``(N,)``; :meth:`modes` splits rows by wait mode. A
    single :class:`AllocationPolicy` is the batch where every row flies it (:meth:`of`).
    """

    policies: tuple
    index: np.ndarray  #: (N,) int, position in ``policies``
    _cache: dict = field(default_factory=dict, compare=False, repr=False)

    def __post_init__(self):
        idx = np.asarray(self.index, np.int64)
        if idx.ndim != 1 or (idx.size and (idx.min() < 0 or idx.max() >= len(self.policies))):
            raise UsageError(f"PolicyRows index must be (N,) positions in {len(self.policies)} policies")
        if not all(isinstance(p, AllocationPolicy) for p in self.policies):
            raise UsageError("PolicyRows holds AllocationPolicy objects only")
        object.__setattr__(self, "policies", tuple(self.policies))
        object.__setattr__(self, "index", idx)

    @classmethod
    def of(cls, policy: "AllocationPolicy | PolicyRows", n: int) -> "PolicyRows":
        """``policy`` for every one of ``n`` rows (a :class:`PolicyRows` of ``n`` rows is returned as is)."""
        if isinstance(policy, PolicyRows):
            if policy.index.size != n:
                raise UsageError(f"PolicyRows has {policy.index.size} rows, the batch {n}")
            return policy
        return cls((policy,), np.zeros(n, np.int64))

    @classmethod
    def stacked(cls, policies: Sequence[AllocationPolicy], sizes: Sequence[int]) -> "PolicyRows":
        """Blocks of rows: the first ``sizes[0]`` rows fly ``policies[0]``, the next ``sizes[1]`` ... ."""
        return cls(tuple(policies), np.repeat(np.arange(len(policies)), np.asarray(sizes, np.int64)))

    def __len__(self) -> int:
        return int(self.index.size)

    def value(self, name: str) -> np.ndarray:
        """Setting ``name`` of :class:`AllocationPolicy` for every row, ``(N,)``."""
        got = self._cache.get(name)
        if got is None:
            got = np.asarray([getattr(p, name) for p in self.policies])[self.index]
            self._cache[name] = got
        return got

    def modes(self, rows: np.ndarray) -> Iterator[tuple[str, np.ndarray]]:
        """``(wait_mode, positions in rows)`` for each wait mode present among ``rows``."""
        mode = np.asarray([WAIT_MODES.index(p.wait_mode) for p in self.policies])[self.index[rows]]
        for code in np.unique(mode):
            yield WAIT_MODES[int(code)], np.flatnonzero(mode == code)


__all__ = ["AllocationPolicy", "PolicyRows", "WAIT_MODES", "WAIT_RULES", "UNSAFE_HOLDS", "AGENT_ACTIVE"]
