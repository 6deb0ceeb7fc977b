"""What this machine has (memory, cores), and a job's estimated peak memory checked against it
before anything is allocated or started.

A command that sizes its work from its inputs (a campaign's encounters x intruders x workers, a
wait map's grid) builds a :class:`MemoryEstimate` of its parts and calls :meth:`MemoryEstimate.check`
first: above :data:`MEMORY_SHARE` of the machine's memory (or of its cgroup's limit, if lower) it is
refused in one line naming the estimate and the memory, unless the user passed ``--allow-large``.
The estimates are upper bounds measured on the 2-core machine of ``docs/benchmarks.md`` (see each
estimator); they are meant to stop a typo, not to pack a machine to the last megabyte.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from daa_sil.config.settings import WORKERS_PER_CORE
from daa_sil.errors import UsageError
from daa_sil.runtime.spawned import usable_cpus

#: the share of the machine's memory one job may plan for (the rest: the system, other jobs)
MEMORY_SHARE = 0.8
#: what one of our Python processes holds before its data: interpreter, numpy, scipy, pyarrow and
#: the compiled DAA kernels (measured 0.2-0.3 GB RSS per campaign worker)
PROCESS_BASE_BYTES = 300 * 2**20
#: cgroup memory limits (v2, then v1) as the process sees them
_CGROUP_FILES = (Path("/sys/fs/cgroup/memory.max"), Path("/sys/fs/cgroup/memory/memory.limit_in_bytes"))


def gib(n: float) -> str:
    """``n`` bytes as ``"1.5 GiB"`` (``"512 MiB"`` below 1 GiB)."""
    return f"{n / 2**30:,.1f} GiB" if n >= 2**30 else f"{n / 2**20:,.0f} MiB"


def machine_memory() -> int:
    """Bytes of memory this process can have: the physical memory, or its cgroup's limit if lower."""
    try:
        total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (AttributeError, OSError, ValueError):  # pragma: no cover - not POSIX
        total = 8 * 2**30
    for f in _CGROUP_FILES:
        try:
            text = f.read_text().strip()
        except OSError:
            continue
        if text.isdigit() and 0 < int(text) < total:
            total = int(text)
    return int(total)


def memory_budget() -> int:
    """Bytes one job may plan for: :data:`MEMORY_SHARE` of :func:`machine_memory`."""
    return int(MEMORY_SHARE * machine_memory())


def max_workers() -> int:
    """The most worker processes a command starts: :data:`~daa_sil.config.settings.WORKERS_PER_CORE`
    per usable core."""
    return WORKERS_PER_CORE * usable_cpus()


def check_workers(workers: int, option: str = "--workers") -> int:
    """``workers`` if within ``[1, max_workers()]``; otherwise a one-line UsageError (exit 2)."""
    hi = max_workers()
    if isinstance(workers, bool) or not isinstance(workers, int) or not 1 <= workers <= hi:
        raise UsageError(f"{option} must be within [1, {hi}] ({WORKERS_PER_CORE} per usable core; "
                         f"this machine has {usable_cpus()}), got {workers!r}")
    return workers


@dataclass(frozen=True)
class MemoryEstimate:
    """A job's estimated peak memory: ``parts`` ``((label, bytes), ...)`` for the message, summed."""

    what: str
    parts: tuple

    @property
    def total(self) -> int:
        return int(sum(b for _, b in self.parts))

    def describe(self) -> str:
        """``"about 12.3 GiB (encounter set 9.8 GiB, 2 workers 2.0 GiB, ...)"``."""
        shown = [f"{label} {gib(b)}" for label, b in self.parts if b >= 2**20]
        return f"about {gib(self.total)}" + (f" ({', '.join(shown)})" if shown else "")

    def check(self, allow_large: bool = False, smaller: str = "") -> "MemoryEstimate":
        """Raise a one-line UsageError when the estimate exceeds :func:`memory_budget` and
        ``allow_large`` is False; ``smaller`` names the inputs that shrink it. Returns self."""
        budget = memory_budget()
        if self.total > budget and not allow_large:
            raise UsageError(f"{self.what} would need {self.describe()} of memory; this machine has "
                             f"{gib(machine_memory())} and a job may plan for {gib(budget)}: "
                             f"{(smaller + ', or ') if smaller else ''}pass --allow-large to run it anyway")
        return self


__all__ = ["MEMORY_SHARE", "PROCESS_BASE_BYTES", "gib", "machine_memory", "memory_budget", "max_workers",
           "check_workers", "MemoryEstimate"]
