"""No compiled kernel (nor a helper compiled into one) takes more than 16 parameters: per-row inputs go
in records (tuples of arrays, of scalars), so that a new per-row field is one edit, not twenty.

Read with ``ast`` from the sources of ``daa_sil/daa/kernels/``: every function decorated with ``kernel(...)``,
``inline`` or ``inline_ir``."""

from __future__ import annotations

import ast
from pathlib import Path

KERNELS = Path(__file__).resolve().parents[1] / "daa_sil" / "daa" / "kernels"
LIMIT = 16


def _decorator_name(node: ast.expr) -> str:
    if isinstance(node, ast.Call):
        node = node.func
    if isinstance(node, ast.Attribute):
        return node.attr
    return node.id if isinstance(node, ast.Name) else ""


def compiled_functions(source: str) -> list[tuple[str, int]]:
    """``(name, parameter count)`` of every function of ``source`` compiled by numba (module docstring)."""
    out = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.FunctionDef) and any(_decorator_name(d) in ("kernel", "inline", "inline_ir")
                                                     for d in node.decorator_list):
            a = node.args
            out.append((node.name, len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs)))
    return out


def test_no_kernel_takes_more_than_16_parameters():
    found = {f"{p.stem}.{name}": n for p in sorted(KERNELS.glob("*.py")) for name, n in compiled_functions(p.read_text())}
    assert len(found) > 60  # (every kernel module was read)
    over = {k: n for k, n in found.items() if n > LIMIT}
    assert not over, f"kernels with more than {LIMIT} parameters (group them in records): {over}"


def test_the_check_sees_a_long_signature():
    src = "@kernel(void(I))\ndef k(" + ", ".join(f"a{i}" for i in range(17)) + "):\n    pass\n" \
          "@inline\ndef h(a, b):\n    pass\n\ndef plain(" + ", ".join(f"a{i}" for i in range(30)) + "):\n    pass\n"
    assert compiled_functions(src) == [("k", 17), ("h", 2)]
