"""One configuration for a run, with named presets (DAIDALUS-style configuration files).

:class:`RunConfig` holds every parameter of a run, in sections:

============== ===================================================================================
``thresholds`` the well-clear / NMAC threshold preset (:mod:`daa_sil.geometry.thresholds`)
``daa``        changes to the DAA configuration of that preset (fields of
               :class:`daa_sil.daa.config.DaaConfig`, SI units: m, s, m/s, rad)
``waitmap``    ``source`` (a map preset ``alerting`` / ``paper`` / ``fine``, a grid spec or a
               ``waitmap build`` directory) and ``gamma`` (the MDP discount; null = the source's)
``allocation`` per-group settings of every group: ``wait_threshold_s`` (W_T, s), ``projl_horizon_s``
               (ProjL N, s), ``constant_wait_s`` (null = each group's; :mod:`daa_sil.config.overrides`)
``groups``     the groups flown, by name from the group table ``daa_sil/data/groups.yaml`` (the
               one place groups are defined)
``pilot``      changes to the remote-pilot model (fields of
               :class:`daa_sil.models.pilot_config.PilotConfig`; times s, angles deg, ft)
``latency``    a delay spec (``const:4``, ``gauss:5,3``) for every group's links (null = each group's)
``link``       per-group ``stale_command_s`` and ``link_timeout_s`` of the agent (null = the policy's 15 / 20 s)
``reading``    ``name`` (a named reading of :mod:`daa_sil.config.readings`) and ``set`` (its overrides)
``study``      ``encounters``, ``seed``, ``duration_s``, ``intruders``, ``chunk_size`` of a campaign
               (:meth:`daa_sil.study.campaign.config.CampaignConfig.from_run_config` reads them)
============== ===================================================================================

What each command reads (the rest of a configuration does not apply to it; the record in its
output shows what was flown):

* ``campaign run`` / ``campaign sweep``: every section;
* ``daa``, ``conformance``: ``thresholds`` (unless ``--preset``) and ``daa``;
* ``waitmap build``: ``thresholds`` (unless ``--preset``) and ``waitmap.gamma``;
* ``run``, ``demo``, ``daa-vehicle``, ``daa-gcs``: the scenario file sets the thresholds, the
  encounter, the link and the group; the configuration adds ``daa``, ``waitmap.source``,
  ``allocation`` and ``link`` (where the scenario sets none: a scenario's value wins over a
  file's, a flag's over both) and ``pilot``.

The fixed sections (``waitmap``, ``reading``, ``study``) are the typed dataclasses of
:mod:`daa_sil.config.sections`; ``allocation`` and ``link`` are
:class:`~daa_sil.config.overrides.Overrides` (the per-group settings of that section, old keys
such as ``wt`` and ``projl_lookahead`` read with a notice); their defaults and ranges are those of
:mod:`daa_sil.config.settings`.

Presets: ``paper`` (the paper's thresholds, HMD* 1220 m / d_h* 122 m; what ``campaign run`` flew
before this object existed), ``do365`` (DO-365B thresholds) and ``daidalus`` (NASA DAIDALUS v2.0.4
``DO_365B_no_SUM.conf``: thresholds and band settings). A YAML file names a preset under ``base``
(default ``paper``) and changes any subset of the sections; an unknown key or a bad value is a
one-line :class:`~daa_sil.errors.UsageError` naming the file and the key. Explicit command-line
flags override the configuration; every output records the full configuration
(:meth:`RunConfig.to_dict` with ``full=True``).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any, Mapping

import yaml

from daa_sil.config.choices import PRESET_NAMES
from daa_sil.config.overrides import Overrides, reading_rules
from daa_sil.config.sections import SECTIONS, SETTING_SECTIONS, ReadingSection, StudySection, WaitmapSection
from daa_sil.config.settings import PRESET
from daa_sil.config.yaml_input import load_yaml_file
from daa_sil.errors import UsageError
from daa_sil.geometry.thresholds import PRESETS as THRESHOLD_PRESETS
from daa_sil.config.readings import reading_for

#: keys ``config show --full`` adds (derived values, ignored when a file is read back)
DERIVED_KEYS = ("resolved", "settings")
TOP_KEYS = ("base", "thresholds", "daa", "waitmap", "allocation", "groups", "pilot", "latency", "link",
            "reading", "study")


def _default_groups() -> tuple:
    from daa_sil.config.groups import PAPER_GROUPS  # lazy: start-up time

    return tuple(PAPER_GROUPS)


@dataclass(frozen=True)
class RunConfig:
    """Every parameter of a run (see the module docstring for the sections and their units)."""

    base: str = PRESET.default  #: the preset it started from
    thresholds: str = PRESET.default
    daa: dict = field(default_factory=dict)
    waitmap: WaitmapSection = field(default_factory=WaitmapSection)
    allocation: Overrides = field(default_factory=lambda: Overrides(section="allocation"))
    groups: tuple = field(default_factory=_default_groups)
    pilot: dict = field(default_factory=dict)
    latency: "str | None" = None
    link: Overrides = field(default_factory=lambda: Overrides(section="link"))
    reading: ReadingSection = field(default_factory=ReadingSection)
    study: StudySection = field(default_factory=StudySection)
    source: str = field(default="<preset>", compare=False)

    # --- the objects of the core --------------------------------------------------------------------
    def daa_config(self, thresholds: "str | None" = None):
        """The :class:`~daa_sil.daa.config.DaaConfig`: the threshold preset's, with ``daa`` applied."""
        from daa_sil.daa.config import DaaConfig  # lazy: start-up time

        return DaaConfig.for_preset(thresholds or self.thresholds, **self.daa)

    def pilot_config(self, **changes):
        """The :class:`~daa_sil.models.pilot_config.PilotConfig` with ``pilot`` (and ``changes``) applied,
        then the reading's pilot settings (when it streams, maneuvers and stops; the SIL GCS flies it)."""
        from daa_sil.models.pilot_config import PilotConfig  # lazy: start-up time

        return self.effective_reading.pilot_config(PilotConfig(**{**self.pilot, **changes}))

    # --- the reading, for the SIL (the study applies it in CampaignConfig) ---------------------------
    @property
    def effective_reading(self):
        """The named :class:`~daa_sil.config.readings.Reading` with its overrides (``reading`` section;
        default ``paper``, the study's)."""

        return reading_for(str(self.reading["name"]), **dict(self.reading["set"]))

    def onboard_policy(self, policy):
        """``policy`` (an :class:`~daa_sil.config.policy.AllocationPolicy`) with the reading's agent
        rules (an unsafe 'hold', when the agent decides, the DAA's authority; the wait rule to a group
        that waits): what the SIL vehicle flies, as a campaign of the same reading."""
        return reading_rules(policy, self.effective_reading)

    @property
    def group_settings(self) -> Overrides:
        """The per-group settings this file gives (``allocation`` and ``link`` together)."""
        return self.link.over(self.allocation)

    @property
    def map_source(self) -> str:
        """The wait maps the SIL reads: the reading's grid, else ``waitmap.source``."""
        return self.effective_reading.waitmap or str(self.waitmap["source"])

    def map_horizon(self, source: "str | None" = None) -> "float | None":
        """The reading's wait-map horizon H (s) for ``source`` (None unless it is the reading's own grid)."""
        r = self.effective_reading
        return r.wait_horizon_s if r.waitmap is not None and (source is None or source == r.waitmap) else None

    # --- YAML -------------------------------------------------------------------------------------
    def to_dict(self, full: bool = False) -> dict:
        """Plain data. ``full=True`` adds every resolved value (threshold numbers, every DAA and pilot
        field, the group definitions, the reading's settings): what outputs record."""
        d = {k: (list(v) if isinstance(v, tuple) else (dict(v) if isinstance(v, Mapping) else v))
             for k, v in ((f.name, getattr(self, f.name)) for f in fields(self) if f.name != "source")}
        d["reading"] = {"name": self.reading["name"], "set": dict(self.reading["set"])}
        if full:
            from daa_sil.config.groups import group_spec  # lazy: start-up time

            dc = self.daa_config()
            th = dc.th
            d["resolved"] = {
                "thresholds": asdict(th),
                "daa": {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(dc).items()
                        if k != "thresholds"},
                "pilot": {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(self.pilot_config()).items()},
                "groups": {g: group_spec(g).to_dict() for g in self.groups},
                "reading": reading_for(self.reading["name"], **self.reading["set"]).to_dict(),
            }
        return d

    def to_yaml(self, full: bool = False) -> str:
        return yaml.safe_dump(self.to_dict(full), sort_keys=False)

    def with_(self, **changes) -> "RunConfig":
        return replace(self, **changes)


def preset(name: str) -> RunConfig:
    """The named preset ``paper``, ``do365`` or ``daidalus``."""
    key = str(name).lower()
    if key not in PRESET_NAMES:
        raise UsageError(f"unknown configuration preset {name!r}; allowed: {', '.join(PRESET_NAMES)} or a YAML file")
    return RunConfig(base=key, thresholds=key, source=f"preset {key}")


def default_wait_maps() -> "tuple[str, float | None]":
    """``(source, horizon H in s or None)`` of the wait maps the SIL vehicle reads when nothing names
    them: the default configuration's reading's (the study's default reading)."""
    cfg = preset(PRESET.default)
    return cfg.map_source, cfg.map_horizon()


def load_config(spec: "str | Path | None") -> RunConfig:
    """A preset name or a YAML file (None = the default preset, ``paper``); one-line UsageError on any problem."""
    if spec is None:
        return preset(PRESET.default)
    if str(spec).lower() in PRESET_NAMES:
        return preset(str(spec))
    p = Path(spec)
    if not p.is_file():
        raise UsageError(f"--config {str(spec)!r} is neither a preset ({', '.join(PRESET_NAMES)}) nor a file")
    try:
        data = load_yaml_file(p, "run configuration")  # bounded size, depth and aliases; one-line errors
    except FileNotFoundError:
        raise UsageError(f"--config {str(spec)!r} is neither a preset ({', '.join(PRESET_NAMES)}) nor a file") from None
    return config_from_dict(data if data is not None else {}, str(p))


def config_from_dict(data: Any, where: str = "<config>") -> RunConfig:
    """Validate a mapping (the YAML form) into a :class:`RunConfig`; errors name ``where`` and the key."""
    if not isinstance(data, dict):
        raise UsageError(f"{where}: a configuration is a mapping of sections ({', '.join(TOP_KEYS)})")
    unknown = [k for k in data if k not in TOP_KEYS and k not in DERIVED_KEYS]
    if unknown:
        raise UsageError(f"{where}: unknown key {unknown[0]!r}; allowed: {', '.join(TOP_KEYS)}")
    cfg = preset(data.get("base", PRESET.default))
    changes: dict = {"base": cfg.base, "source": where}
    if "thresholds" in data:
        th = str(data["thresholds"]).lower()
        if th not in THRESHOLD_PRESETS:
            raise UsageError(f"{where}: thresholds must be one of {', '.join(THRESHOLD_PRESETS)}, got {data['thresholds']!r}")
        changes["thresholds"] = th
    for key in SECTIONS:
        if key in data:
            changes[key] = getattr(cfg, key).updated(data[key], key, where)
    for key in SETTING_SECTIONS:
        if key in data:
            changes[key] = _settings(data[key], key, where)
    if "daa" in data:
        changes["daa"] = _field_changes(data["daa"], "daa", _dataclass_fields("daa"), where)
    if "pilot" in data:
        changes["pilot"] = _field_changes(data["pilot"], "pilot", _dataclass_fields("pilot"), where)
    if "groups" in data:
        changes["groups"] = _groups(data["groups"], where)
    if "latency" in data:
        changes["latency"] = _latency(data["latency"], where)
    out = cfg.with_(**changes)
    _check(out, where)
    return out


def save_config(cfg: RunConfig, path: "str | Path", overwrite: bool = False) -> Path:
    """Write ``cfg`` as YAML (atomically; loadable by :func:`load_config`)."""
    from daa_sil.files import atomic_write_text  # lazy: start-up time

    return atomic_write_text(path, cfg.to_yaml(), overwrite=overwrite)


# --- validation ---------------------------------------------------------------------------------------
def _dataclass_fields(which: str) -> dict:
    if which == "daa":
        from daa_sil.daa.config import DaaConfig as cls  # lazy: start-up time
    else:
        from daa_sil.models.pilot_config import PilotConfig as cls  # lazy: start-up time
    return {f.name: f for f in fields(cls) if f.name != "thresholds"}


def _field_changes(node, key: str, known: dict, where: str) -> dict:
    if not isinstance(node, dict):
        raise UsageError(f"{where}: {key} must be a mapping of field changes")
    bad = [k for k in node if k not in known]
    if bad:
        raise UsageError(f"{where}: unknown key '{key}.{bad[0]}'; allowed: {', '.join(known)}")
    return {k: (tuple(v) if isinstance(v, list) else v) for k, v in node.items()}


def _settings(node, key: str, where: str) -> Overrides:
    """A section of per-group settings: each key a setting's name (or old key), each value checked."""
    allowed = Overrides.keys_read(key)
    if not isinstance(node, dict):
        raise UsageError(f"{where}: {key} must be a mapping with keys {', '.join(allowed)}")
    bad = [k for k in node if k not in allowed]
    if bad:
        raise UsageError(f"{where}: unknown key '{key}.{bad[0]}'; allowed: {', '.join(allowed)}")
    return Overrides.read(node, where, f"{key}.", key)


def _groups(node, where: str) -> tuple:
    from daa_sil.config.groups import group_table  # lazy: start-up time

    names = node.split(",") if isinstance(node, str) else node
    if not isinstance(names, (list, tuple)) or not names:
        raise UsageError(f"{where}: groups must be a list of group names")
    table = group_table()
    for g in names:
        if g not in table:
            raise UsageError(f"{where}: unknown group {g!r} in groups; allowed: {', '.join(table)}")
    return tuple(str(g) for g in names)


def _latency(node, where: str) -> "str | None":
    if node is None:
        return None
    from daa_sil.models.delay_spec import SPEC_HELP, parse_delay_spec  # lazy: start-up time

    try:
        parse_delay_spec(str(node))
    except UsageError as exc:
        raise UsageError(f"{where}: latency: {exc} (allowed: {SPEC_HELP})") from None
    return str(node)


def _check(cfg: RunConfig, where: str) -> None:
    """Values of the sections (each field's setting's range, as on the command line); builds the
    objects they feed."""
    w = cfg.waitmap
    if not isinstance(w["source"], str) or not w["source"]:
        raise UsageError(f"{where}: waitmap.source must be a map preset, grid spec or directory, got {w['source']!r}")
    for key in SECTIONS:
        getattr(cfg, key).check(key, where)

    r = cfg.reading
    if not isinstance(r["set"], dict):
        raise UsageError(f"{where}: reading.set must be a mapping of reading settings")
    try:
        reading_for(str(r["name"]), **r["set"])
    except UsageError as exc:
        raise UsageError(f"{where}: reading: {exc}") from None
    except TypeError as exc:
        raise UsageError(f"{where}: reading.set: {exc}") from None
    for what, build in (("daa", cfg.daa_config), ("pilot", cfg.pilot_config)):
        try:
            build()
        except UsageError as exc:
            raise UsageError(f"{where}: {what}: {exc}") from None
        except (TypeError, ValueError) as exc:
            raise UsageError(f"{where}: {what}: bad value ({exc})") from None


__all__ = ["RunConfig", "PRESET_NAMES", "preset", "load_config", "default_wait_maps", "config_from_dict", "save_config"]
