"""The package boundary is the sans-IO boundary (docs/architecture.md, "Packages").

The core packages (geometry, waitmap, daa, models, study, config, link, agent, onboard, steplog,
files, errors) import nothing from ``daa_sil.sil``, ``daa_sil.viz`` or ``daa_sil.commands``, and
none of the modules that do network or process I/O (``asyncio``, ``socket``, ``selectors``,
``subprocess``, ``threading``; a campaign's process pool is allowed). The rule reads every ``import`` statement with :mod:`ast` (module
level and inside functions), so a lazy import inside a function is caught too.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[1] / "daa_sil"

#: the I/O side of the boundary (packages of daa_sil) and the standard modules the core must not use
IO_PACKAGES = ("daa_sil.sil", "daa_sil.viz", "daa_sil.commands", "daa_sil.cli")
#: (a process pool for a campaign's chunks is computation, not I/O: ``concurrent.futures`` and
#: ``multiprocessing`` are allowed)
IO_STDLIB = ("asyncio", "socket", "selectors", "subprocess", "threading")


def module_name(path: Path) -> str:
    rel = path.relative_to(PKG.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def is_core(module: str) -> bool:
    """Everything in daa_sil except the I/O packages (and the generated dialect, which pymavlink writes)."""
    if module.startswith("daa_sil.link.dialect"):
        return False
    return not any(module == p or module.startswith(p + ".") for p in IO_PACKAGES)


def imported_modules(source: str, module: str, is_package: bool = False) -> list[tuple[int, str]]:
    """(line, absolute module) of every import in ``source``; relative imports resolved against ``module``."""
    out = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            out.extend((node.lineno, a.name) for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = module.split(".") if is_package else module.split(".")[:-1]
                base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            out.append((node.lineno, target))
            # ``from daa_sil import sil`` imports the package daa_sil.sil
            out.extend((node.lineno, f"{target}.{a.name}") for a in node.names)
    return out


def violations(source: str, module: str, is_package: bool = False) -> list[str]:
    """Lines breaking the rule in the source of core ``module``."""
    bad = []
    for line, target in imported_modules(source, module, is_package):
        top = target.split(".")[0]
        if top in IO_STDLIB:
            bad.append(f"{module}:{line} imports {target}")
        elif any(target == p or target.startswith(p + ".") for p in IO_PACKAGES):
            bad.append(f"{module}:{line} imports {target}")
    return bad


def core_files() -> list[Path]:
    return sorted(p for p in PKG.rglob("*.py") if is_core(module_name(p)))


def test_the_core_is_most_of_the_package():
    """The population the rule is checked on: every core package is there (a rename would empty it)."""
    mods = {module_name(p) for p in core_files()}
    for pkg in ("daa_sil.geometry.wellclear", "daa_sil.waitmap.solve", "daa_sil.daa.bands", "daa_sil.agent.step",
                "daa_sil.onboard", "daa_sil.models.pilot", "daa_sil.study.campaign.run", "daa_sil.link.delayline",
                "daa_sil.link.codec"):
        assert pkg in mods
    for io_mod in ("daa_sil.sil.shim", "daa_sil.sil.endpoint", "daa_sil.viz.recorder", "daa_sil.commands.run"):
        assert io_mod not in mods


def test_core_imports_nothing_from_the_io_side():
    bad = []
    for p in core_files():
        bad += violations(p.read_text(encoding="utf-8"), module_name(p), p.name == "__init__.py")
    assert bad == []


@pytest.mark.parametrize("source, module, expected", [
    ("import asyncio\n", "daa_sil.agent.step", "daa_sil.agent.step:1 imports asyncio"),
    ("def f():\n    from socket import socket\n", "daa_sil.study.campaign.run", "daa_sil.study.campaign.run:2 imports socket"),
    ("from ...sil.shim import DelayShim\n", "daa_sil.study.simulation.fasttime", "daa_sil.study.simulation.fasttime:1 imports daa_sil.sil.shim"),
    ("from .. import viz\n", "daa_sil.models.pilot", "daa_sil.models.pilot:1 imports daa_sil.viz"),
    ("from daa_sil.commands.run import run\n", "daa_sil.onboard", "daa_sil.onboard:1 imports daa_sil.commands.run"),
    ("from . import sil\n", "daa_sil", "daa_sil:1 imports daa_sil.sil"),
])
def test_the_rule_catches_a_bad_import(source, module, expected):
    """The checker fails on each kind of forbidden import (so the test above can fail)."""
    assert expected in violations(source, module, is_package=(module == "daa_sil"))


def test_the_rule_allows_core_imports():
    src = "from ..geometry.wellclear import wcv\nfrom daa_sil.link.delayline import DelayLine\nimport numpy as np\n"
    assert violations(src, "daa_sil.study.simulation.fasttime") == []
