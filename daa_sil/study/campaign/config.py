"""Everything that determines a campaign's results (:class:`CampaignConfig`, recorded in
``campaign.json`` and checked on ``--resume``): the groups with the campaign's overrides, the
encounter set, the wait maps, the reading, and the DAA, pilot and link settings of its run
configuration (:mod:`daa_sil.config.run_config`)."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace

import numpy as np

from daa_sil.config.groups import GroupSpec, parse_groups
from daa_sil.config.overrides import Overrides, group_policy, setting_for_key
from daa_sil.config.readings import DEFAULT_READING, LEGACY_READING
from daa_sil.config.settings import (CHUNK_SIZE, DURATION, ENCOUNTERS, GAMMA, INTRUDERS, PRESET, SEED, STEP,
                                     group_settings)
from daa_sil.errors import FileFormatError, UsageError
from daa_sil.geometry.thresholds import PRESETS
from daa_sil.waitmap.source import DEFAULT_MAP
from daa_sil.config.readings import canonical_name
from daa_sil.waitmap.source import check_source
from daa_sil.config.settings import DELAY_EPOCH
from daa_sil.config.readings import reading_for
from daa_sil.models.link_rule import link_legs
from daa_sil.geometry.thresholds import get_thresholds

#: default step dt (s), paper §IV (:data:`daa_sil.config.settings.STEP`)
DEFAULT_DT_S = STEP.default


#: encounters per task (:data:`daa_sil.config.settings.CHUNK_SIZE`, which says why 2000)
DEFAULT_CHUNK = CHUNK_SIZE.default


@dataclass(frozen=True)
class ResolvedGroup:
    """One group as the simulation flies it: the agent's policy, the link legs, map or not."""

    policy: object  #: :class:`~daa_sil.config.policy.AllocationPolicy`
    legs: object  #: :class:`~daa_sil.models.link_rule.LinkLegs`
    uses_map: bool


@dataclass(frozen=True)
class ResolvedCampaign:
    """A campaign's settings resolved once (:meth:`CampaignConfig.resolve`): typed fields only."""

    daa: object  #: :class:`~daa_sil.daa.config.DaaConfig`
    pilot: object  #: :class:`~daa_sil.models.pilot_config.PilotConfig`
    groups: dict  #: group name -> :class:`ResolvedGroup`
    preset: str
    duration_s: float
    dt_s: float
    epoch_s: float


@dataclass(frozen=True)
class CampaignConfig:
    """Everything that determines a campaign's results (stored in ``campaign.json``).

    ``groups`` are the group definitions as given (:mod:`daa_sil.config.groups`); ``settings`` (the
    per-group settings the run configuration and the flags give: W_T of every group with a wait
    function, ProjL N, the link timeouts, ...; :class:`~daa_sil.config.overrides.Overrides`) and
    ``latency`` (a delay spec such as ``gauss:5,3`` for every group's links) apply on top
    (:attr:`effective_groups`). ``waitmap`` is a map preset, grid spec or family directory
    (:func:`daa_sil.waitmap.family_for`), ``gamma`` the MDP discount (None: the map preset's).
    """

    groups: tuple = field(default_factory=lambda: parse_groups(None))
    n_encounters: int = ENCOUNTERS.default
    seed: int = SEED.default
    chunk_size: int = DEFAULT_CHUNK
    preset: str = PRESET.default
    duration_s: float = DURATION.default
    dt_s: float = DEFAULT_DT_S
    waitmap: str = DEFAULT_MAP
    gamma: "float | None" = None
    settings: Overrides = field(default_factory=Overrides)  #: per-group settings of every group (flags, file)
    latency: "str | None" = None
    n_intruders: int = INTRUDERS.default
    reading: str = DEFAULT_READING  #: a named reading of :mod:`daa_sil.config.readings` (old names accepted)
    reading_set: dict = field(default_factory=dict)  #: overrides of the reading's settings
    daa: dict = field(default_factory=dict)  #: DaaConfig field changes on top of the preset's
    pilot: dict = field(default_factory=dict)  #: PilotConfig field changes (the reading's then apply)

    def __post_init__(self):
        # groups may be given by name (``("B-2", "ID-2")``) or as a --groups string
        g = self.groups
        if isinstance(g, str) or (isinstance(g, (tuple, list)) and any(isinstance(x, str) for x in g)):
            names = g if isinstance(g, str) else [x if isinstance(x, str) else x.name for x in g]
            specs = {s.name: s for s in g if isinstance(s, GroupSpec)} if not isinstance(g, str) else {}
            parsed = parse_groups(names)
            object.__setattr__(self, "groups", tuple(specs.get(p.name, p) for p in parsed))
        else:
            object.__setattr__(self, "groups", tuple(g))

        object.__setattr__(self, "reading", canonical_name(self.reading)[0])  # old names -> current

    def validate(self) -> "CampaignConfig":
        """Raise UsageError (one line) on a bad value; returns self."""
        if not self.groups or not all(isinstance(g, GroupSpec) for g in self.groups):
            raise UsageError("a campaign needs at least one group definition")
        for name, val, setting in (("--encounters", self.n_encounters, ENCOUNTERS), ("--chunk-size", self.chunk_size,
                                   CHUNK_SIZE), ("--intruders", self.n_intruders, INTRUDERS), ("--seed", self.seed, SEED)):
            if not isinstance(val, (int, np.integer)) or isinstance(val, bool):
                raise UsageError(f"{name} must be an integer, got {val!r}")
            setting.check(int(val), key=name)  # both ends of its range (paper Table 6: 1..8 intruders)
        if self.preset not in PRESETS:
            raise UsageError(f"unknown --preset {self.preset!r}; allowed: {', '.join(PRESETS)}")
        DURATION.check(self.duration_s, key="duration")
        if not (math.isfinite(self.dt_s) and self.dt_s > 0):
            raise UsageError(f"dt must be > 0 s, got {self.dt_s!r}")
        for setting in group_settings():  # (flags and files check theirs as they read them)
            val = self.settings.of(setting)
            if val is not None:
                setting.check(val, key=setting.flag or setting.name)
        lo, hi = GAMMA.range
        if self.gamma is not None and not (isinstance(self.gamma, (int, float)) and math.isfinite(self.gamma)
                                           and lo <= self.gamma <= hi):
            raise UsageError(f"--gamma must be within [{lo:g}, {hi:g}], got {self.gamma!r}")
        if self.latency is not None:
            from daa_sil.models.delay_spec import parse_delay_spec  # lazy: start-up time

            parse_delay_spec(self.latency)
        self.effective_groups  # noqa: B018 -- validates the overridden definitions
        for what, build in (("daa", self.daa_config), ("pilot", self.pilot_config)):
            try:
                build()
            except TypeError as exc:
                raise UsageError(f"{what}: {exc}") from None
        r = self.effective_reading
        if r.waitmap is not None and self.waitmap not in (DEFAULT_MAP, r.waitmap):
            raise UsageError(f"reading {r.name!r} sets the wait maps to {r.waitmap!r}; to read {self.waitmap!r} "
                             f"instead, set the reading's grid (--reading-set waitmap={self.waitmap})")
        if self.uses_map:
            check_source(self.map_source, self.preset, self.gamma, self.map_horizon)
        return self

    @property
    def map_horizon(self) -> "float | None":
        """The wait maps' horizon H (s) the reading sets (None: the map preset's)."""
        return self.effective_reading.wait_horizon_s

    @property
    def epoch_s(self) -> float:
        """The links' delay epoch (s): the link's (:data:`daa_sil.config.settings.DELAY_EPOCH`), or one
        draw per encounter under a reading with ``delay_draw = "encounter"``."""

        return self.effective_reading.epoch_s(DELAY_EPOCH.default, self.duration_s, self.dt_s)

    @property
    def map_source(self) -> str:
        """The ``--waitmap`` the map groups read: the reading's, else the campaign's."""
        return self.effective_reading.waitmap or self.waitmap

    @property
    def effective_reading(self):
        """The :class:`daa_sil.config.readings.Reading` flown and counted (named bundle + overrides)."""

        return reading_for(self.reading, **dict(self.reading_set))

    @property
    def group_names(self) -> tuple[str, ...]:
        return tuple(g.name for g in self.groups)

    @property
    def effective_groups(self) -> tuple[GroupSpec, ...]:
        """The groups with the campaign's overrides applied (what is flown)."""
        latency = None
        if self.latency is not None:
            from daa_sil.models.delay_spec import parse_delay_spec  # lazy: start-up time

            latency = parse_delay_spec(self.latency).to_dict()
        out = []
        for g in self.groups:
            g = g.with_(allocation=self.policy(g.name))
            out.append(g.with_(latency=dict(latency)) if latency is not None else g)
        return tuple(out)

    def link_legs(self, name: str):
        """What each link of group ``name`` applies (:class:`daa_sil.models.link_rule.LinkLegs`): the
        group's latency under the reading's rule (``one-way`` or ``round-trip``)."""

        return link_legs(self.group(name).delay_model(), self.effective_reading.latency)

    def group(self, name: str) -> GroupSpec:
        """The effective definition of one of the campaign's groups (what ``campaign.json`` records)."""
        self.given_group(name)
        return next(g for g in self.effective_groups if g.name == name)

    def given_group(self, name: str) -> GroupSpec:
        """One of the campaign's groups as given, before the campaign's overrides."""
        for g in self.groups:
            if g.name == name:
                return g
        raise UsageError(f"group {name!r} is not part of this campaign ({', '.join(self.group_names)})")

    @property
    def uses_map(self) -> bool:
        return any(g.uses_map for g in self.groups)

    @property
    def n_chunks(self) -> int:
        return (self.n_encounters + self.chunk_size - 1) // self.chunk_size

    def chunk_range(self, chunk: int) -> tuple[int, int]:
        """Encounter index range ``[lo, hi)`` of a chunk."""
        lo = chunk * self.chunk_size
        return lo, min(lo + self.chunk_size, self.n_encounters)

    def daa_config(self):
        """The :class:`~daa_sil.daa.config.DaaConfig` flown: the preset's with :attr:`daa` applied."""
        from daa_sil.daa.config import DaaConfig  # lazy: start-up time

        return DaaConfig.for_preset(self.preset, **self.daa)

    def pilot_config(self):
        """The :class:`~daa_sil.models.pilot_config.PilotConfig` flown: :attr:`pilot`, then the reading's."""
        from daa_sil.models.pilot_config import PilotConfig  # lazy: start-up time

        return self.effective_reading.pilot_config(PilotConfig(**self.pilot))

    def policy(self, name: str):
        """The agent's :class:`~daa_sil.config.policy.AllocationPolicy` of group ``name``: the group as
        given, the reading's agent rules, then :attr:`settings`
        (:func:`~daa_sil.config.overrides.group_policy`, the one rule the vehicle follows too). W_T
        thus travels ``--wt`` -> :attr:`settings` (an Overrides) -> the policy: two types."""
        return group_policy(self.given_group(name).policy(), reading=self.effective_reading, flags=self.settings)

    def resolve(self) -> "ResolvedCampaign":
        """Every object the simulation reads, built once (cached): the DAA and pilot configurations,
        and per group its policy, its link legs and whether it reads the wait map."""
        got = self.__dict__.get("_resolved")
        if got is None:
            groups = {g.name: ResolvedGroup(self.policy(g.name), self.link_legs(g.name), g.uses_map)
                      for g in self.groups}
            got = ResolvedCampaign(self.daa_config(), self.pilot_config(), groups, self.preset, self.duration_s,
                                   self.dt_s, self.epoch_s)
            object.__setattr__(self, "_resolved", got)  # (not a field: equality, to_dict, replace ignore it)
        return got

    def differences(self, other: "CampaignConfig") -> list:
        """The fields where ``other`` differs (a per-group setting by its flag, ``--wt``, or name)."""
        a, b = self.to_dict(), other.to_dict()
        out = [k for k in a if k != "settings" and a[k] != b.get(k)]
        mine, theirs = self.settings, other.settings
        return out + [s.flag or s.name for s in group_settings() if mine.of(s) != theirs.of(s)]

    def to_dict(self) -> dict:
        d = asdict(self)
        d["groups"] = [g.to_dict() for g in self.groups]
        d["reading_set"] = dict(self.reading_set)
        d["daa"] = {k: (list(v) if isinstance(v, tuple) else v) for k, v in self.daa.items()}
        d["pilot"] = {k: (list(v) if isinstance(v, tuple) else v) for k, v in self.pilot.items()}
        d["settings"] = self.settings.given()
        d["readings"] = self.effective_reading.to_dict()  # derived: every setting of the reading
        return d

    def resolved(self) -> dict:
        """Every value the campaign flies with, resolved: thresholds, the full DAA and pilot
        configurations, the agent policy of each group (recorded in ``campaign.json``)."""

        def plain(obj):
            return {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(obj).items()}

        daa = plain(self.daa_config())
        daa.pop("thresholds", None)
        return {"thresholds": asdict(get_thresholds(self.preset)), "daa": daa, "pilot": plain(self.pilot_config()),
                "policies": {g.name: plain(self.policy(g.name)) for g in self.groups},
                "reading": self.effective_reading.to_dict()}

    @classmethod
    def from_run_config(cls, run) -> "CampaignConfig":
        """The campaign a :class:`~daa_sil.config.run_config.RunConfig` describes (built here, in study,
        so that config/ never imports study)."""
        s = run.study
        return cls(groups=parse_groups(list(run.groups)), n_encounters=int(s["encounters"]),
                   seed=int(s["seed"]), chunk_size=int(s["chunk_size"]), preset=run.thresholds,
                   duration_s=float(s["duration_s"]), waitmap=str(run.waitmap["source"]),
                   gamma=run.waitmap["gamma"], settings=run.group_settings, latency=run.latency,
                   n_intruders=int(s["intruders"]), reading=str(run.reading["name"]),
                   reading_set=dict(run.reading["set"]), daa=dict(run.daa), pilot=dict(run.pilot))

    @classmethod
    def from_dict(cls, d: dict, where: str = "campaign.json") -> "CampaignConfig":
        try:
            groups = tuple(GroupSpec.from_dict(g["name"], {k: v for k, v in g.items() if k != "name"}, where)
                           for g in d["groups"])
            opt = {k: d.get(k) for k in ("gamma", "latency")}
            return cls(groups=groups, n_encounters=int(d["n_encounters"]), seed=int(d["seed"]),
                       chunk_size=int(d["chunk_size"]), preset=str(d["preset"]),
                       duration_s=float(d["duration_s"]), dt_s=float(d["dt_s"]), waitmap=str(d["waitmap"]),
                       n_intruders=int(d.get("n_intruders", 1)), reading=str(d.get("reading", LEGACY_READING)),
                       reading_set=dict(d.get("reading_set") or {}),
                       daa={k: (tuple(v) if isinstance(v, list) else v) for k, v in (d.get("daa") or {}).items()},
                       pilot={k: (tuple(v) if isinstance(v, list) else v) for k, v in (d.get("pilot") or {}).items()},
                       settings=stored_settings(d), **opt).validate()
        except (KeyError, TypeError, ValueError) as exc:
            raise FileFormatError(f"{where}: bad or missing config field ({exc})") from None
        except UsageError as exc:
            raise FileFormatError(f"{where}: {exc}") from None


def stored_settings(d: dict) -> Overrides:
    """The per-group settings a ``campaign.json`` config records: ``settings`` (``{name: value}``), or
    the keys of campaigns written before it (``wt``, ``projl_lookahead``, ``link``), read silently."""
    old = {"wt": d.get("wt"), "projl_lookahead": d.get("projl_lookahead"), **(d.get("link") or {}),
           **(d.get("settings") or {})}
    out = Overrides()
    for key, value in old.items():
        setting = setting_for_key(str(key))
        if setting is None:
            raise UsageError(f"unknown setting {key!r}")
        if value is not None:
            out = out.with_(setting, value)
    return out
