"""A batch of encounters that fly different groups side by side (:class:`PolicyRows`, row ``i`` flies
``policies[index[i]]``, each an :class:`~daa_sil.config.policy.AllocationPolicy`).

Groups are data, not code paths (:mod:`daa_sil.config.groups`): the agent
(:func:`daa_sil.agent.step.agent_step`) reads every setting per row, so one call can decide for
encounters of several groups at once, with exactly the numbers each group would get alone.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Iterator, Sequence

import numpy as np

from daa_sil.config.policy import WAIT_MODES, AllocationPolicy
from daa_sil.errors import UsageError


#: the fields a :class:`PolicyRows` reads per row (every setting of the policy)
POLICY_FIELDS = frozenset(f.name for f in fields(AllocationPolicy))


@dataclass(frozen=True)
class PolicyRows:
    """The policies of a batch of N encounters: row ``i`` flies ``policies[index[i]]``.

    Each field of :class:`AllocationPolicy` reads as an attribute, one value per row ``(N,)``
    (``rows.wait_threshold_s``; :meth:`value`); :meth:`modes` splits rows by wait mode. A single
    :class:`AllocationPolicy` is the batch where every row flies it (:meth:`of`).
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
        """Setting ``name`` of :class:`AllocationPolicy` for every row, ``(N,)`` (read-only, computed once)."""
        got = self._cache.get(name)
        if got is None:
            got = np.asarray([getattr(p, name) for p in self.policies])[self.index]
            got.flags.writeable = False  # shared by every later call (and step): read-only
            self._cache[name] = got
        return got

    def __getattr__(self, name: str) -> np.ndarray:
        """A field of :class:`AllocationPolicy`, per row (:meth:`value`)."""
        if name in POLICY_FIELDS:
            return self.value(name)
        raise AttributeError(f"PolicyRows has no field {name!r}")

    def modes(self, rows: np.ndarray) -> Iterator[tuple[str, np.ndarray]]:
        """``(wait_mode, positions in rows)`` for each wait mode present among ``rows``."""
        mode = np.asarray([WAIT_MODES.index(p.wait_mode) for p in self.policies])[self.index[rows]]
        for code in np.unique(mode):
            yield WAIT_MODES[int(code)], np.flatnonzero(mode == code)


__all__ = ["PolicyRows", "POLICY_FIELDS"]
