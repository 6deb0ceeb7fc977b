"""The fixed sections of a run configuration (:class:`daa_sil.config.run_config.RunConfig`) as typed
dataclasses: ``waitmap``, ``reading`` and ``study``. (``allocation`` and ``link`` hold per-group
settings: :class:`daa_sil.config.overrides.Overrides`.)

Each field takes its default, its range and its help from a :class:`~daa_sil.config.settings.Setting`
(``metadata["setting"]``), so a YAML file, a command-line flag and ``config show --full`` check and
describe the same thing. A section also reads as a mapping (``cfg.study["seed"]``,
``dict(cfg.study)``) and compares equal to the plain mapping of its fields.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from typing import Any

from daa_sil.config.readings import DEFAULT_READING
from daa_sil.config.settings import CHUNK_SIZE, DURATION, ENCOUNTERS, GAMMA, INTRUDERS, SEED, WAITMAP
from daa_sil.errors import UsageError


@dataclass(frozen=True, eq=False)
class Section(Mapping):
    """Base of a section: a typed dataclass that is also a read-only mapping of its fields."""

    @classmethod
    def keys_allowed(cls) -> tuple[str, ...]:
        """The section's keys, in order."""
        return tuple(f.name for f in fields(cls))

    def __getitem__(self, key: str) -> Any:
        if key not in self.keys_allowed():
            raise KeyError(key)
        return getattr(self, key)

    def __iter__(self):
        return iter(self.keys_allowed())

    def __len__(self) -> int:
        return len(fields(self))

    def updated(self, node: Any, key: str, where: str) -> "Section":
        """This section with the keys of a YAML mapping ``node`` changed (unknown key: one line)."""
        allowed = self.keys_allowed()
        if not isinstance(node, dict):
            raise UsageError(f"{where}: {key} must be a mapping with keys {', '.join(allowed)}")
        bad = [k for k in node if k not in allowed]
        if bad:
            raise UsageError(f"{where}: unknown key '{key}.{bad[0]}'; allowed: {', '.join(allowed)}")
        return replace(self, **node)

    def check(self, key: str, where: str) -> None:
        """Every set value within its setting's range (one line naming ``where`` and ``key.field``)."""
        for f in fields(self):
            setting = f.metadata.get("setting")
            value = getattr(self, f.name)
            if setting is not None and setting.lo is not None and value is not None:
                setting.check(value, where, f"{key}.{f.name}")


@dataclass(frozen=True, eq=False)
class WaitmapSection(Section):
    """``source``: a map preset (``alerting``, ``paper``, ``fine``), a grid spec or a ``waitmap
    build`` directory; ``gamma``: the MDP discount (None = the source's)."""

    source: str = WAITMAP.field()
    gamma: "float | None" = GAMMA.field()


@dataclass(frozen=True, eq=False)
class ReadingSection(Section):
    """``name``: a named reading (:mod:`daa_sil.config.readings`); ``set``: its overrides."""

    name: str = DEFAULT_READING
    set: dict = field(default_factory=dict)


@dataclass(frozen=True, eq=False)
class StudySection(Section):
    """What a campaign flies: its size, seed, encounter length T (s) and intruders."""

    encounters: int = ENCOUNTERS.field()
    seed: int = SEED.field()
    duration_s: float = DURATION.field()
    intruders: int = INTRUDERS.field()
    chunk_size: int = CHUNK_SIZE.field()


#: the fixed sections by their key in a configuration file
SECTIONS = {"waitmap": WaitmapSection, "reading": ReadingSection, "study": StudySection}
#: the sections of per-group settings (:func:`daa_sil.config.overrides.settings_of` each)
SETTING_SECTIONS = ("allocation", "link")

__all__ = ["Section", "WaitmapSection", "ReadingSection", "StudySection", "SECTIONS", "SETTING_SECTIONS"]
