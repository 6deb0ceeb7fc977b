"""Import rules of the SIL side (docs/architecture.md, "Packages"; docs/sil.md).

* the GCS imports nothing from the vehicle (what both ends share lives in ``daa_sil.link``);
* ``daa_sil.sil``, ``vehicle`` and ``gcs`` import nothing from ``daa_sil.study`` (seed streams live
  in ``daa_sil.models.streams``);
* the SIL's protocol modules are sans-IO: the shim's, the vehicle's and the GCS's protocol cores
  (:data:`SANS_IO`) import no ``asyncio``, ``socket``, ``selectors``, no endpoint nor the shim's socket side;
* the shim's socket module does not import the shim (no circle, not even for a type).

Every ``import`` statement is read with :mod:`ast` (module level and inside functions, under
``if TYPE_CHECKING`` too). Each rule is shown failing on a synthetic bad module.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SANS_IO = ("daa_sil.sil.shim_core", "daa_sil.sil.lockstep", "daa_sil.sil.silence", "daa_sil.sil.intake",
           "vehicle.protocol", "vehicle.tick_rules", "vehicle.services", "vehicle.orders", "vehicle.ports",
           "vehicle.peers", "vehicle.boot", "vehicle.announce", "vehicle.traffic", "gcs.protocol", "gcs.pilot",
           "gcs.view")
IO_MODULES = ("asyncio", "socket", "selectors", "daa_sil.sil.shim", "daa_sil.sil.shim_socket",
              "daa_sil.sil.endpoint", "daa_sil.sil.rtclock")


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports(source: str, module: str, is_package: bool = False) -> list[tuple[int, str]]:
    """(line, absolute module) of every import; ``from a import b`` also yields ``a.b``."""
    out = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            out.extend((node.lineno, a.name) for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            target = node.module or ""
            if node.level:
                base = module.split(".") if is_package else module.split(".")[:-1]
                base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            out.append((node.lineno, target))
            out.extend((node.lineno, f"{target}.{a.name}") for a in node.names)
    return out


def _under(target: str, prefix: str) -> bool:
    return target == prefix or target.startswith(prefix + ".")


def violations(source: str, module: str, is_package: bool = False) -> list[str]:
    """The rules broken by ``module`` (its ``source``), one line each."""
    bad = []
    for line, target in imports(source, module, is_package):
        where = f"{module}:{line} imports {target}"
        if _under(module, "gcs") and _under(target, "vehicle"):
            bad.append(f"{where} (the GCS takes what it shares with the vehicle from daa_sil.link)")
        if any(_under(module, p) for p in ("daa_sil.sil", "vehicle", "gcs")) and _under(target, "daa_sil.study"):
            bad.append(f"{where} (the SIL needs nothing from the study; seed streams: daa_sil.models.streams)")
        if module in SANS_IO and any(_under(target, m) for m in IO_MODULES):
            bad.append(f"{where} (a sans-IO protocol module)")
        if module == "daa_sil.sil.shim_socket" and _under(target, "daa_sil.sil.shim") and target != module:
            bad.append(f"{where} (the socket side is below the shim)")
    return bad


def sil_files() -> list[Path]:
    files = [*(ROOT / "daa_sil" / "sil").rglob("*.py"), *(ROOT / "vehicle").rglob("*.py"), *(ROOT / "gcs").rglob("*.py")]
    return sorted(p for p in files if "__pycache__" not in p.parts)


def test_the_rules_see_the_sil():
    mods = {module_name(p) for p in sil_files()}
    assert {"gcs.node", "vehicle.node", "daa_sil.sil.shim", "daa_sil.sil.shim_socket", *SANS_IO} <= mods


def test_the_sil_keeps_its_import_rules():
    bad = []
    for p in sil_files():
        bad += violations(p.read_text(encoding="utf-8"), module_name(p), p.name == "__init__.py")
    assert bad == []


@pytest.mark.parametrize("source, module, expected", [
    ("def f():\n    from vehicle.identity import mode_name\n", "gcs.view", "gcs.view:2 imports vehicle.identity"),
    ("import vehicle.telemetry\n", "gcs.node", "gcs.node:1 imports vehicle.telemetry"),
    ("from daa_sil.study.simulation.fasttime import STREAM_UP\n", "daa_sil.sil.shim_config",
     "daa_sil.sil.shim_config:1 imports daa_sil.study.simulation.fasttime"),
    ("from daa_sil.study.simulation import fasttime\n", "gcs.node", "gcs.node:1 imports daa_sil.study.simulation.fasttime"),
    ("import asyncio\n", "daa_sil.sil.shim_core", "daa_sil.sil.shim_core:1 imports asyncio"),
    ("from .shim_socket import ShimSocket\n", "daa_sil.sil.shim_core", "daa_sil.sil.shim_core:1 imports daa_sil.sil.shim_socket"),
    ("from . import endpoint\n", "daa_sil.sil.lockstep", "daa_sil.sil.lockstep:1 imports daa_sil.sil.endpoint"),
    ("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from daa_sil.sil.shim import DelayShim\n",
     "daa_sil.sil.shim_socket", "daa_sil.sil.shim_socket:3 imports daa_sil.sil.shim"),
])
def test_each_rule_can_fail(source, module, expected):
    assert any(v.startswith(expected) for v in violations(source, module)), violations(source, module)


def test_allowed_imports_pass():
    src = ("from daa_sil.link.plane import mode_name\nfrom daa_sil.models.streams import STREAM_UP\n"
           "from .shim_config import ShimConfig\nfrom .silence import Silence\n")
    assert violations(src, "daa_sil.sil.shim_core") == []
    assert violations(src, "gcs.node") == []
