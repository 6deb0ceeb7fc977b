"""The per-group settings one input sets (:class:`Overrides`), read the same way from every input, and
the one rule that lays them on a group's :class:`~daa_sil.config.policy.AllocationPolicy`.

A per-group setting (:func:`daa_sil.config.settings.group_settings`: W_T, ProjL N, the constant
wait, the link timeouts, and any setting registered later) is set, later inputs winning, by:

1. its default (the :class:`~daa_sil.config.settings.Setting`);
2. the group's definition: the group table or a ``--groups`` file (a key of the group);
3. the run configuration file (``--config``: the setting's section, ``allocation`` or ``link``);
4. the scenario (SIL runs: its ``allocation`` section);
5. the command-line flag (``--wt``, ``--projl-horizon``, ...);
6. at run time, the vehicle's MAVLink parameter (``DAA_WT``, ...; :mod:`vehicle.params`).

Inputs 3 and 5 are run-wide: they change the groups the setting ``applies`` to (W_T: the groups
with a wait function). Inputs 2 and 4 define one group: they set the value as given.
:func:`group_policy` is that order, for fast-time and the vehicle alike.

Every input reads a value with :meth:`Setting.check` (one range, one message). Old YAML keys and
flags (:attr:`Setting.aliases`, :attr:`Setting.old_flags`) are read with a one-line notice.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any, Iterator

from daa_sil.config.settings import Setting, group_settings
from daa_sil.errors import UsageError

_SAID: set = set()


def notice(text: str) -> None:
    """One line on stderr, once per process (an old key or flag that is still read)."""
    if text not in _SAID:
        _SAID.add(text)
        print(f"daa-sil: note: {text}", file=sys.stderr)


def settings_of(section: "str | None" = None) -> tuple:
    """The per-group settings of a run-configuration section (None: all of them)."""
    return tuple(s for s in group_settings() if section is None or s.section == section)


def setting_for_key(key: str, section: "str | None" = None) -> "Setting | None":
    """The per-group setting a YAML key names (its name or an old key), None if none does."""
    return next((s for s in settings_of(section) if key in s.keys), None)


def canonical_keys(node: Mapping, where: str, prefix: str = "") -> dict:
    """``node`` with each old key of a per-group setting renamed to the setting's name (one notice each)."""
    out = {}
    for key, value in node.items():
        s = setting_for_key(str(key))
        if s is not None and key != s.name:
            if s.name in node:
                raise UsageError(f"{where}: {prefix}{s.name} is given twice (also as {prefix}{key})")
            if value is not None:
                s.check(value, where, f"{prefix}{key}")  # (first: a bad value is one line, the error)
            notice(f"{where}: {prefix}{key} is now called {prefix}{s.name} (read as such)")
            key = s.name
        out[key] = value
    return out


def applies_to(setting: Setting, wait_mode: str) -> bool:
    """Whether a run-wide value of ``setting`` changes a group of ``wait_mode`` (:attr:`Setting.applies`)."""
    if setting.applies == "waiting":
        return wait_mode != "none"
    if setting.applies == "constant":
        return wait_mode == "constant"
    return True


@dataclass(frozen=True)
class Overrides(Mapping):
    """The per-group settings one input sets: ``(name, value)`` pairs in registration order. It reads
    as a mapping of every setting of ``section`` (all per-group settings when None) to its value or
    None (unset); code reads one with :meth:`of`, by its :class:`Setting`."""

    pairs: tuple = ()
    section: "str | None" = None

    def of(self, setting: Setting) -> "float | None":
        """The value this input gives ``setting`` (None: unset, the layer below holds)."""
        return next((v for k, v in self.pairs if k == setting.name), None)

    def with_(self, setting: Setting, value: "float | None") -> "Overrides":
        """These overrides with ``setting`` set to ``value`` (checked; None unsets it)."""
        given = {k: v for k, v in self.pairs if k != setting.name}
        if value is not None:
            given[setting.name] = setting.check(value, key=setting.flag or setting.name)
        return Overrides(tuple((s.name, given[s.name]) for s in group_settings() if s.name in given), self.section)

    def over(self, below: "Overrides") -> "Overrides":
        """``below`` with these values on top (this input wins)."""
        given = {**dict(below.pairs), **dict(self.pairs)}
        section = self.section if self.section == below.section else None
        return Overrides(tuple((s.name, given[s.name]) for s in group_settings() if s.name in given), section)

    def given(self) -> dict:
        """``{name: value}`` of the settings this input sets (what a record keeps)."""
        return dict(self.pairs)

    def applied(self, target, run_wide: bool = True):
        """``target`` (an AllocationPolicy) with these values; ``run_wide``: only where
        :func:`applies_to` says so (a flag, a run configuration), else as given (a group, a scenario)."""
        changes = {}
        for s in group_settings():
            v = self.of(s)
            if v is not None and (not run_wide or applies_to(s, target.wait_mode)):
                changes[s.name] = v
        return replace(target, **changes) if changes else target

    # -- the mapping view (``config show``, ``to_dict``) ------------------------------------------
    def __getitem__(self, key: str) -> Any:
        s = setting_for_key(key, self.section)
        if s is None:
            raise KeyError(key)
        return self.of(s)

    def __iter__(self) -> Iterator[str]:
        return iter(s.name for s in settings_of(self.section))

    def __len__(self) -> int:
        return len(settings_of(self.section))

    def __eq__(self, other) -> bool:
        if isinstance(other, Overrides):
            return self.pairs == other.pairs
        if isinstance(other, Mapping):  # a plain mapping: of the settings set, None for the rest
            return {k: v for k, v in other.items() if v is not None} == dict(self.pairs)
        return NotImplemented

    __hash__ = None  # type: ignore[assignment]

    @classmethod
    def of_values(cls, values: "Mapping[Setting, float]") -> "Overrides":
        """``{setting: value}`` (each checked) as overrides: code that sets settings itself."""
        out = cls()
        for setting, value in values.items():
            out = out.with_(setting, value)
        return out

    # -- reading each input --------------------------------------------------------------------------
    @classmethod
    def read(cls, node: Mapping, where: str, prefix: str = "", section: "str | None" = None) -> "Overrides":
        """The keys of a YAML mapping ``node`` that name a per-group setting (of ``section``), each
        checked against its range; other keys are the caller's. An old key is read with a notice."""
        given: dict = {}
        for key, value in node.items():
            s = setting_for_key(str(key), section)
            if s is None:
                continue
            if s.name in given:
                raise UsageError(f"{where}: {prefix}{s.name} is given twice (also as {prefix}{key})")
            given[s.name] = None if value is None else s.check(value, where, f"{prefix}{key}")
            if key != s.name:  # (after the check: a bad value is one line, the error)
                notice(f"{where}: {prefix}{key} is now called {prefix}{s.name} (read as such)")
        return cls(tuple((s.name, given[s.name]) for s in group_settings()
                         if given.get(s.name) is not None), section)

    @staticmethod
    def keys_read(section: "str | None" = None) -> tuple:
        """Every YAML key :meth:`read` takes (names, then old keys)."""
        return tuple(k for s in settings_of(section) for k in s.keys)

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> "Overrides":
        """The per-group flags given on a command line (:func:`add_flags`)."""
        given = {s.name: getattr(args, flag_dest(s), None) for s in group_settings() if s.flag}
        return cls(tuple((k, v) for k, v in given.items() if v is not None))


def flag_dest(setting: Setting) -> str:
    """The ``argparse`` destination of a setting's flag."""
    return f"setting_{setting.name}"


class _OldFlag(argparse.Action):
    """Stores the value; an old spelling of the flag says its new one once."""

    def __call__(self, parser, namespace, values, option_string=None):
        new = self.option_strings[0]
        if option_string and option_string != new:
            notice(f"{option_string} is now called {new} (read as such)")
        setattr(namespace, self.dest, values)


def add_flags(parser: argparse.ArgumentParser, what: str = "of every group") -> None:
    """A flag for every per-group setting that has one (value checked against its range; default:
    each group's)."""
    for s in group_settings():
        if not s.flag:
            continue

        def parse(text: str, s: Setting = s) -> float:  # (a UsageError: one line, exit 2, as every flag)
            try:
                value = float(text)
            except ValueError:
                raise UsageError(f"{s.flag} must be a number, got {text!r}") from None
            return s.check(value, key=s.flag)

        parser.add_argument(s.flag, *s.old_flags, dest=flag_dest(s), type=parse, default=None, metavar="S",
                            action=_OldFlag, help=s.flag_help(f"{s.help} {what}".strip())
                            .replace("(default", "(default: each group's,"))


def group_policy(policy, *, reading=None, file: "Overrides | None" = None, scenario: "Overrides | None" = None,
                 flags: "Overrides | None" = None):
    """The agent's policy of one group: its definition ``policy``, the reading's agent rules, then the
    run configuration's ``file``, the ``scenario``'s and the ``flags``' per-group settings (module
    docstring). Fast-time (:meth:`CampaignConfig.policy`) and the vehicle both call this."""
    if reading is not None:
        policy = reading_rules(policy, reading)
    if file is not None:
        policy = file.applied(policy)
    if scenario is not None:
        policy = scenario.applied(policy, run_wide=False)
    if flags is not None:
        policy = flags.applied(policy)
    return policy


def reading_rules(policy, reading):
    """``policy`` with a reading's agent rules (an unsafe 'hold', when the agent decides, the DAA's
    authority; its wait rule to a group that waits)."""
    changes = dict(reading.policy_overrides())
    rule = changes.pop("wait_rule", None)
    if rule is not None and policy.wait_mode != "none" and rule != policy.wait_rule:
        changes["wait_rule"] = rule
    return replace(policy, **changes) if changes else policy


__all__ = ["Overrides", "add_flags", "flag_dest", "group_policy", "reading_rules", "applies_to", "settings_of",
           "setting_for_key", "canonical_keys", "notice"]
