"""The client snippets of docs/sil.md run as written against a real vehicle (only the port replaced).

Each ``<!-- snippet: NAME -->`` is followed by a fenced ``python`` block: the MAVSDK one (a stock client in
the dev extra) and the pymavlink one. A snippet that stops working -- an import that moved, a call the
client no longer has, a vehicle that no longer answers as the page says -- fails here. On main the MAVSDK
snippet was two lines of prose, and its refusal came back as TIMEOUT.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from interop_helpers import ROOT, free_ports, start, stop, wait_for_text

DOC = ROOT / "docs" / "sil.md"
SNIPPET = re.compile(r"<!-- snippet: (\w+) -->\n```python\n(.*?)```", re.S)
#: how each snippet's vehicle is started (its --out), and what the snippet must print
CASES = {
    "mavsdk": ("udp:127.0.0.1:{port}", ["ownship ", "W_T 4.0", "refused: VALUE_OUT_OF_RANGE", "goto sent"]),
    "pymavlink": ("udpin:127.0.0.1:{port}", ["vehicle 1 ", "PARAM_VALUE", "ownship "]),
}


def snippets() -> dict:
    return {m.group(1): m.group(2) for m in SNIPPET.finditer(DOC.read_text())}


def test_the_page_has_the_snippets():
    assert set(snippets()) == set(CASES)


@pytest.mark.parametrize("name", sorted(CASES))
def test_snippet_runs_as_written(tmp_path, name):
    if name == "mavsdk":
        try:
            import mavsdk  # noqa: F401
        except ImportError:
            if os.environ.get("DAA_SIL_REQUIRE_INTEROP"):
                raise
            pytest.skip("MAVSDK-Python is in the dev extra: pip install -e '.[dev]'")
    out, expect = CASES[name]
    (port,) = free_ports(1)
    code = snippets()[name]
    assert "14550" in code
    script = tmp_path / f"snippet_{name}.py"  # (not mavsdk.py: it would shadow the package)
    script.write_text(code.replace("14550", str(port)))
    veh = start(["vehicle", ROOT / "scenarios" / "head_on.yaml", "--out", out.format(port=port), "--speed", "2"],
                tmp_path / "vehicle.log")
    try:
        wait_for_text(tmp_path / "vehicle.log", "READY", 120.0, veh)
        cp = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120, cwd=tmp_path)
    finally:
        stop(veh)
    assert cp.returncode == 0, cp.stdout[-2000:] + cp.stderr[-3000:]
    for text in expect:
        assert text in cp.stdout, (text, cp.stdout)
