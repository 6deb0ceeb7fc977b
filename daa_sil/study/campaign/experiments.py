"""The experiments that explain where the ``paper`` reading misses the paper: single-factor runs on the
same encounters (one campaign seed: every run draws the same encounter set, so groups and readings
compare encounter by encounter), each resumable, and the replays that read step logs.

:data:`RUNS` lists the campaigns beyond the readings' own (``docs/results/regenerate.py`` runs every
reading; :func:`run_experiments` runs these next to them, into ``RUNS_DIR/exp-<name>``): the
unmitigated encounter set, ``paper-feet`` at the rare-event size, blends without waiting and at
other latencies, the no-command pilot with and without the DAA keeping its authority, and SM(u)'s
horizon. :mod:`daa_sil.study.analysis.experiment_analysis` turns them (and the readings) into the figures of
the experiments page and of the attribution table.

Sizes: ``large`` runs (rare events: LoWC, PI, NMAC, severity) fly ``n_large`` encounters per group,
the others ``n_small``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable

from daa_sil.config.groups import group_spec
from daa_sil.errors import UsageError

#: the report seed is never used by experiments run while developing (``docs/results/regenerate.py``
#: checks the seed it is given)
PAIRED = "one campaign seed: the same encounter set, encounter by encounter"


def _variant(base: str, name: str, latency: "dict | None" = None, **policy):
    """Group ``base`` named ``name``, with another ``latency`` and changes to its policy (``wait_mode``, ...)."""
    g = group_spec(base)
    g = g.with_(name=name, allocation=replace(g.allocation, **policy))
    return g.with_(latency=latency) if latency is not None else g


def _latency_groups() -> tuple:
    out = [group_spec("ID-2")]
    for spec, name in (("constant", 0.2), ("constant", 4.0), ("constant", 10.0)):
        out.append(_variant("ID-2", f"ID-2-lat{name:g}", latency={"type": spec, "seconds": name}))
    return tuple(out)


@dataclass(frozen=True)
class Run:
    """One experiment campaign: ``reading`` (with ``reading_set``) over ``groups`` (names or
    :class:`~daa_sil.config.groups.GroupSpec`), ``daa`` changes, ``size`` ``large`` or ``small``,
    and what it tests (``why``)."""

    name: str
    reading: str
    groups: "tuple | Callable[[], tuple]"
    why: str
    reading_set: dict = field(default_factory=dict)
    daa: dict = field(default_factory=dict)
    size: str = "small"

    def group_specs(self) -> tuple:
        return self.groups() if callable(self.groups) else tuple(self.groups)


#: the groups of every reading's campaign (``docs/results/regenerate.py``): the paper's five and the wait
#: map's ablations
READING_GROUPS = ("B-1", "B-2", "IC-1", "ID-1", "ID-2", "ID-2-projl", "ID-2-map")
#: a pilot that never maneuvers and sends nothing (a stock GCS, or the unmitigated encounter)
NO_PILOT = {"pilot_engage": "never", "hold_commands": False}
PAPER5 = ("B-1", "B-2", "IC-1", "ID-1", "ID-2")

RUNS: tuple[Run, ...] = (
    Run("unmitigated", "paper", ("unmitigated",), "the encounter set's own risk: no DAA, no pilot maneuver",
        reading_set=NO_PILOT, size="large"),
    Run("paper-feet", "paper-feet", PAPER5, "the HMD/VMD table read in feet, at the rare-event size", size="large"),
    Run("blend-no-wait", "paper", lambda: (group_spec("ID-2"), _variant("ID-2", "ID-2-no-wait", wait_mode="none")),
        "Algorithm 2 without waiting (ID-2 with w = 0: no waits, blends as before): does waiting cost the exact "
        "match? ('As the system waits, the encounter may go in a closer proximity')"),
    Run("blend-latency", "paper", _latency_groups,
        "ID-2 at a constant round trip of 0.2, 4 and 10 s: does latency cost the exact match? ('The found "
        "maneuver may be more aggressive ... due to the latency')"),
    Run("no-command-pilot", "paper", ("ID-2",), "a pilot that sends nothing (a stock GCS): the agent alone",
        reading_set=NO_PILOT),
    Run("no-command-pilot-keep", "paper-keep-daa", ("ID-2",),
        "the same with the DAA keeping its authority until clear (our extension)", reading_set=NO_PILOT),
    Run("sm35", "paper", ("B-2", "ID-2"), "SM(u)'s horizon 35 s instead of 55 s", daa={"sm_horizon_s": 35.0}),
    Run("sm25", "paper", ("B-2", "ID-2"), "SM(u)'s horizon 25 s instead of 55 s", daa={"sm_horizon_s": 25.0}),
)

#: the readings the experiments read (run by ``regenerate.py`` as readings; their directories under
#: the same runs directory), besides ``paper``
READINGS_USED = ("paper-clamp", "paper-outside-far", "paper-hold-none", "paper-h60", "paper-delay-per-encounter",
                 "paper-one-way", "paper-no-hold", "paper-keep-daa", "paper-corrective")


def run_dir(runs: Path, run: Run, n: int) -> Path:
    """Where an experiment campaign goes (its size in the name, so that --resume never mixes sizes)."""
    return Path(runs) / f"exp-{run.name}-{n}"


def run_config(run: Run, seed: int, n: int):
    """The :class:`~daa_sil.study.campaign.config.CampaignConfig` of an experiment run."""
    from daa_sil.study.campaign.config import CampaignConfig  # lazy: start-up time

    return CampaignConfig(groups=run.group_specs(), n_encounters=n, seed=seed, reading=run.reading,
                          reading_set=dict(run.reading_set), daa=dict(run.daa))


def run_experiments(runs: "str | Path", seed: int, n_small: int, n_large: int, workers: int = 2,
                    only: "tuple | None" = None, log: Callable[[str], None] = print) -> dict:
    """Run (or resume) every experiment campaign of :data:`RUNS` (``only``: those names); returns
    ``{name: directory}``."""
    from daa_sil.study.campaign.run import run_campaign  # lazy: start-up time

    names = {r.name for r in RUNS}
    bad = sorted(set(only or ()) - names)
    if bad:
        raise UsageError(f"unknown experiment {bad[0]!r}; allowed: {', '.join(sorted(names))}")
    out = {}
    for run in RUNS:
        if only and run.name not in only:
            continue
        n = n_large if run.size == "large" else n_small
        d = run_dir(Path(runs), run, n)
        again = d.is_dir() and any(d.iterdir())
        log(f"== experiment {run.name} ({n:,} encounters per group; {'resuming' if again else 'running'})")
        run_campaign(run_config(run, seed, n), d, workers=workers, resume=again, progress=False)
        out[run.name] = d
    return out


def commands_for(runs, meta: dict) -> list[str]:
    """The commands that make ``runs`` (reading and experiment names, as ``experiments.json`` lists them)
    and their figures, with ``meta``'s seed and sizes (the reading ``paper`` at the large size, as
    ``docs/results/regenerate.py`` runs it); RUNS stands for the runs directory."""
    names = {r.name for r in RUNS}
    seed, small, large = meta.get("seed"), meta.get("n_small"), meta.get("n_large")
    out = [f"daa-sil campaign run --reading {r} --groups {','.join(READING_GROUPS)} --encounters "
           f"{large if r == 'paper' else small} --seed {seed} --out RUNS/{r}" for r in dict.fromkeys(runs)
           if r not in names]
    exps = [r for r in dict.fromkeys(runs) if r in names]
    out.append(f"python docs/results/experiments.py --runs RUNS --seed {seed} --small {small} --large {large} "
               + (f"--only {','.join(exps)}" if exps else "--analyse-only"))
    return out


__all__ = ["Run", "RUNS", "READINGS_USED", "READING_GROUPS", "NO_PILOT", "PAPER5", "PAIRED", "run_dir", "run_config",
           "run_experiments", "commands_for"]
