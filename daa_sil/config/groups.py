"""Experiment groups as data: the group table ``daa_sil/data/groups.yaml`` and user group files.

A group is what one arm of the fast-time study flies: the one-way link delay (both links), the
wait function (none / a constant / the MDP map / always), W_T, the ProjL veto and its look-ahead,
blending and the wait rule. The paper's five groups (Tabassum & Bai Table 2: B-1, B-2, IC-1, ID-1,
ID-2) and the ablations ``ID-2-projl`` (the map ignored: wait unless ProjL) and ``ID-2-map`` (the
map alone, no ProjL) are rows of the table; :meth:`GroupSpec.policy` turns a row into the agent's
:class:`~daa_sil.config.policy.AllocationPolicy`. Nothing in the agent knows group names.

``--groups`` takes names from the table (``B-2,ID-2,ID-2-projl``) or a YAML file of definitions::

    my-group:                 # a new group (name: letters, digits, '.', '_', '-')
      base: ID-2              # start from a table row (optional)
      wait_threshold_s: 8
      latency: {type: constant, seconds: 2}
"""

from __future__ import annotations

import functools
import json
import re
from dataclasses import dataclass, replace
from importlib import resources
from pathlib import Path
from typing import Sequence

from daa_sil.config.policy import AllocationPolicy
from daa_sil.config.overrides import Overrides, canonical_keys
from daa_sil.config.settings import CONSTANT_WAIT, group_settings
from daa_sil.errors import FileFormatError, UsageError

#: the paper's groups (Table 2), in the paper's order
PAPER_GROUPS = ("B-1", "B-2", "IC-1", "ID-1", "ID-2")
WAITS = ("none", "map", "always")
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,39}$")


@dataclass(frozen=True)
class GroupSpec:
    """One experiment group (see the module docstring): its setup, its link latency and the agent's
    :class:`~daa_sil.config.policy.AllocationPolicy` (``allocation``: wait function, W_T, ProjL and
    N, blending, every per-group setting). Times in s."""

    name: str
    setup: str
    latency: dict  #: the YAML form of a :mod:`daa_sil.models.latency` model, used on uplink and downlink
    allocation: AllocationPolicy
    description: str = ""

    def __hash__(self) -> int:  # the latency mapping is not hashable; hash the JSON form
        return hash((self.name, json.dumps(self.to_dict(), sort_keys=True)))

    @property
    def wait(self) -> "str | float":
        """``none`` | ``map`` | ``always`` | the constant wait in s (the group file's ``wait``)."""
        p = self.allocation
        return p.constant_wait_s if p.wait_mode == "constant" else p.wait_mode

    @property
    def wait_mode(self) -> str:
        """The policy's wait mode: ``none``, ``constant``, ``map`` or ``always``."""
        return self.allocation.wait_mode

    @property
    def uses_map(self) -> bool:
        return self.allocation.wait_mode == "map"

    def delay_model(self):
        """The :mod:`daa_sil.models.latency` model used on the uplink and on the downlink."""
        from daa_sil.models.delay_spec import delay_model_from_dict  # lazy: start-up time

        return delay_model_from_dict(dict(self.latency), where=f"group {self.name} latency")

    def policy(self) -> AllocationPolicy:
        """The agent's :class:`~daa_sil.config.policy.AllocationPolicy` for this group."""
        return self.allocation

    def with_(self, **changes) -> "GroupSpec":
        """This group with ``changes``; a new ``name`` names its policy too (as :meth:`from_dict` does)."""
        if "name" in changes:
            changes["allocation"] = replace(changes.get("allocation", self.allocation), name=changes["name"])
        return replace(self, **changes)

    def to_dict(self) -> dict:
        """The group file's form: ``setup``, ``latency``, ``wait``, every per-group setting, ``projl``,
        ``blending``, ``wait_rule``, ``description``, ``enabled`` (what :meth:`from_dict` reads)."""
        p = self.allocation
        d = {"name": self.name, "setup": self.setup, "latency": dict(self.latency), "wait": self.wait}
        d.update({s.name: getattr(p, s.name) for s in group_settings() if s is not CONSTANT_WAIT})
        d.update({k: getattr(p, k) for k in _FLAGS})
        d.update({"wait_rule": p.wait_rule, "description": self.description})
        d["enabled"] = p.enabled
        return d

    @classmethod
    def from_dict(cls, name: str, d: dict, where: str = "group") -> "GroupSpec":
        """Validated spec from a mapping (one-line errors naming ``where`` and the field)."""
        if not isinstance(d, dict):
            raise UsageError(f"{where}: group {name!r} must be a mapping of fields, got {type(d).__name__}")
        if not isinstance(name, str) or not _NAME.match(name):
            raise UsageError(f"{where}: bad group name {name!r}; use letters, digits, '.', '_' or '-' (up to 40)")
        known = {"setup", "latency", "wait", "wait_rule", "description", "enabled", *_FLAGS,
                 *(k for k in Overrides.keys_read() if k not in CONSTANT_WAIT.keys)}
        unknown = set(d) - known
        if unknown:
            raise UsageError(f"{where}: group {name}: unknown field {sorted(unknown)[0]!r}; allowed: "
                             f"{', '.join(sorted(known))}")
        for req in ("setup", "latency", "wait"):
            if req not in d:
                raise UsageError(f"{where}: group {name}: missing field {req!r}")
        at = f"{where}: group {name}"
        wait = d["wait"]
        if isinstance(wait, bool) or not (wait in WAITS or isinstance(wait, (int, float))):
            raise UsageError(f"{at}: wait must be none, map, always or a number of seconds, got {wait!r}")
        settings = Overrides.read(d, at)
        if isinstance(wait, (int, float)):
            settings = settings.with_(CONSTANT_WAIT, CONSTANT_WAIT.check(wait, at, "a constant wait"))
        base = AllocationPolicy("constant" if isinstance(wait, (int, float)) else wait, name=name,
                                wait_rule=str(d.get("wait_rule", "threshold")),
                                **{k: _flag(d, k, True, at) for k in (*_FLAGS, "enabled")})  # validates wait_rule
        spec = cls(name=name, setup=str(d["setup"]), latency=dict(d["latency"]) if isinstance(d["latency"], dict)
                   else d["latency"], allocation=settings.applied(base, run_wide=False),
                   description=str(d.get("description", "")))
        spec.delay_model()  # validates latency
        return spec


#: the on/off fields of a group (the ProjL veto, blending)
_FLAGS = ("projl", "blending")


def _flag(d: dict, key: str, default: bool, where: str) -> bool:
    v = d.get(key, default)
    if not isinstance(v, bool):
        raise UsageError(f"{where}: {key} must be true or false, got {v!r}")
    return v


@functools.lru_cache(maxsize=1)
def group_table() -> dict[str, GroupSpec]:
    """The built-in groups (``daa_sil/data/groups.yaml``) by name, in file order."""
    from daa_sil.config.yaml_input import load_yaml  # lazy: start-up time

    text = resources.files("daa_sil").joinpath("data/groups.yaml").read_text(encoding="utf-8")
    raw = load_yaml(text, "daa_sil/data/groups.yaml", "group table")
    return {name: GroupSpec.from_dict(name, d, "daa_sil/data/groups.yaml") for name, d in raw.items()}


def group_spec(name: str) -> GroupSpec:
    """A built-in group by name (case-insensitive)."""
    table = group_table()
    by_upper = {k.upper(): k for k in table}
    key = by_upper.get(str(name).strip().upper())
    if key is None:
        raise UsageError(f"unknown group {name!r}; allowed: {', '.join(table)} (or a YAML file of group definitions)")
    return table[key]


def load_group_file(path: "str | Path") -> tuple[GroupSpec, ...]:
    """Group definitions from a YAML file (mapping name -> fields, ``base:`` a built-in group)."""
    from daa_sil.config.yaml_input import load_yaml_file  # lazy: start-up time

    p = Path(path)
    try:
        raw = load_yaml_file(p, "group definitions")  # bounded size, depth and aliases; one-line errors
    except FileNotFoundError:
        raise UsageError(f"group file {p} does not exist") from None
    if not isinstance(raw, dict) or not raw:
        raise UsageError(f"{p}: expected a mapping of group name -> fields, got {type(raw).__name__}")
    out = []
    for name, d in raw.items():
        d = canonical_keys(d, str(p)) if isinstance(d, dict) else d
        if isinstance(d, dict) and "base" in d:
            base = group_spec(d.pop("base")).to_dict()
            base.pop("name")
            base.update(d)
            d = base
        out.append(GroupSpec.from_dict(str(name), d, str(p)))
    return tuple(out)


def parse_groups(text: "str | Sequence[str] | None") -> tuple[GroupSpec, ...]:
    """``--groups``: ``"B-1,ID-2"`` (or a list of names), a YAML file of definitions, or None (the
    paper's five). Names must be unique."""
    if text is None:
        return tuple(group_spec(g) for g in PAPER_GROUPS)
    if isinstance(text, str) and (text.lower().endswith((".yaml", ".yml")) or Path(text).is_file()):
        specs = load_group_file(text)
    else:
        items = [s.strip() for s in (text.split(",") if isinstance(text, str) else text)]
        items = [s for s in items if s]
        if not items:
            raise UsageError(f"--groups is empty; allowed: {','.join(group_table())} or a YAML file")
        specs = tuple(group_spec(s) for s in items)
    names = [s.name for s in specs]
    dup = next((n for n in names if names.count(n) > 1), None)
    if dup:
        raise UsageError(f"group {dup} given twice in --groups")
    return specs


def policy_for_group(group: str) -> AllocationPolicy:
    """The policy of a named group of the group table (B-1, ..., ID-2-map)."""
    return group_spec(group).policy()


__all__ = ["GroupSpec", "policy_for_group", "PAPER_GROUPS", "group_table", "group_spec", "load_group_file", "parse_groups"]
