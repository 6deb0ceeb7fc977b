"""Input files without bounds (issue 20 item 5), through the installed console scripts.

On bba2fd8 about 500 levels of nesting in a scenario, a ``--groups`` or a ``--config`` file gave
a RecursionError traceback, a 50 MB YAML file parsed for minutes in 2.7 GB of memory, and a NUL
byte gave a two-line error. Every YAML input now goes through one loader
(``daa_sil.config.yaml_input``) that caps size, nesting and alias expansion: each hostile file
below must give exactly one ``<program>: error:`` line naming the file, exit 2, no traceback, and
no output directory.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from daa_sil.config.yaml_input import MAX_BYTES, MAX_DEPTH, MAX_NODES, load_yaml
from daa_sil.errors import FileFormatError

ROOT = Path(__file__).resolve().parents[1]
LIMIT_S = 300.0

#: kind -> (file bytes, a fragment the error line must carry)
HOSTILE = {
    "nested-lists": (b"name: x\nownship: " + b"[" * 500 + b"]" * 500 + b"\n", f"nested more than {MAX_DEPTH} levels"),
    "nested-mappings": (b"name: x\nownship: " + b"{a: " * 500 + b"1" + b"}" * 500 + b"\n",
                        f"nested more than {MAX_DEPTH} levels"),
    "nested-blocks": (b"name: x\n" + b"".join(b"  " * i + b"k%d:\n" % i for i in range(200)) + b"  " * 200 + b"v: 1\n",
                      f"nested more than {MAX_DEPTH} levels"),
    "50-MB": (b"name: x\n" + b"# padding padding padding padding padding padding\n" * 1_000_000,
              f"50,000,008 bytes; a"),
    "NUL-byte": (b"name: x\x00\n", ":1: not valid YAML: the control character U+0000 is not allowed"),
    "alias-bomb": ("a: &a [1,1,1,1,1,1,1,1,1,1]\n".encode() + "".join(  # 10^6 values in 180 bytes
        f"{n}: &{n} [{','.join(['*' + p] * 10)}]\n" for p, n in zip("abcde", "bcdef")).encode(),
                   f"more than {MAX_NODES:,} values"),
    "not-UTF-8": (b"name: caf\xe9\n", "not UTF-8 text (byte 0xe9 at offset 9)"),
}
#: the kinds named in the issue, run through every input (all kinds run through the scenario)
NAMED = ("nested-lists", "50-MB", "NUL-byte")


def _console(name: str) -> str:
    path = Path(sys.executable).parent / name
    assert path.is_file(), f"{path} is not installed (pip install -e .)"
    return str(path)


def _commands(f: Path, out: Path) -> dict:
    """input -> argv that reads ``f`` as that input and would write ``out``."""
    head_on = ROOT / "scenarios" / "head_on.yaml"
    daa_sil = _console("daa-sil")
    return {
        "scenario (daa-sil run)": [daa_sil, "run", str(f), "--out", str(out)],
        "scenario (daa-vehicle)": [_console("daa-vehicle"), str(f), "--steplog", str(out / "s.parquet")],
        "--groups FILE": [daa_sil, "campaign", "run", "--groups", str(f), "--encounters", "2", "--out", str(out)],
        "--config FILE": [daa_sil, "run", str(head_on), "--config", str(f), "--out", str(out)],
        "--grid FILE": [daa_sil, "waitmap", "build", "--grid", str(f), "--out", str(out)],
    }


def test_hostile_yaml_is_one_line_exit_2_through_every_input(tmp_path):
    env = dict(os.environ, PYTHONDONTWRITEBYTECODE="1", DAA_SIL_CACHE=str(tmp_path / "cache"))
    runs = []
    for kind, (data, needle) in HOSTILE.items():
        f = tmp_path / f"{kind}.yaml"
        f.write_bytes(data)
        for what, argv in _commands(f, tmp_path / f"out-{kind}-{len(runs)}").items():
            if kind in NAMED or what == "scenario (daa-sil run)":
                runs.append((kind, what, needle, f, Path(argv[-1]) if argv[-2] == "--out" else Path(argv[-1]).parent,
                             subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                              env=env, cwd=tmp_path)))
    failures = []
    try:
        for kind, what, needle, f, out, proc in runs:
            try:
                stdout, stderr = proc.communicate(timeout=LIMIT_S)
            except subprocess.TimeoutExpired:
                failures.append(f"{kind} via {what}: still running after {LIMIT_S:g} s")
                continue
            lines = stderr.strip().splitlines()
            ok = (proc.returncode == 2 and len(lines) == 1 and ": error: " in lines[0] and str(f) in lines[0]
                  and needle in lines[0] and "Traceback" not in stderr and not out.exists())
            if not ok:
                failures.append(f"{kind} via {what}: exit {proc.returncode}, stderr {stderr[-300:]!r}")
    finally:
        for *_, proc in runs:  # nothing outlives the test
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    assert not failures, "\n".join(failures)
    assert len(runs) == len(HOSTILE) + 4 * len(NAMED)


def test_the_bounds_leave_real_inputs_alone():
    """Every scenario and data file we ship parses (deepest nesting, largest size within bounds)."""
    from daa_sil.config.groups import group_table
    from daa_sil.sil.scenario import load_scenario
    from daa_sil.study.analysis.findings import load_findings

    scenarios = sorted((ROOT / "scenarios").rglob("*.yaml"))
    assert scenarios and all(load_scenario(p).name for p in scenarios)
    assert group_table() and load_findings()


def test_limits_are_exact():
    """Just inside each bound parses; one step outside is refused."""
    nest = lambda n: "a: " + "[" * (n - 1) + "]" * (n - 1)  # noqa: E731 -- the mapping is level 1
    assert load_yaml(nest(MAX_DEPTH), "f", "test") == {"a": _nested(MAX_DEPTH - 1)}
    with pytest.raises(FileFormatError, match="nested more than"):
        load_yaml(nest(MAX_DEPTH + 1), "f", "test")
    # nodes: root, key a, list a (100 values), key b, list b, then m aliases of list a (100 each)
    aliases = lambda m: "a: &a [" + ",".join(["1"] * 99) + "]\nb: [" + ",".join(["*a"] * m) + "]\n"  # noqa: E731
    m_max = (MAX_NODES - 4) // 100 - 1  # 4 + 100 (m + 1) <= MAX_NODES
    assert len(load_yaml(aliases(m_max), "f", "test")["b"]) == m_max
    with pytest.raises(FileFormatError, match="values"):
        load_yaml(aliases(m_max + 1), "f", "test")
    big = "a: '" + "x" * (MAX_BYTES - 6) + "'\n"  # MAX_BYTES characters exactly
    assert len(big) == MAX_BYTES and len(load_yaml(big, "f", "test")["a"]) == MAX_BYTES - 6
    with pytest.raises(FileFormatError, match="at most"):
        load_yaml(big + " ", "f", "test")
    aliased = "a: &a [1, 2]\nb: *a\n"  # an ordinary alias is fine
    assert load_yaml(aliased, "f", "test") == {"a": [1, 2], "b": [1, 2]}


def _nested(n: int):
    out: list = []
    for _ in range(n - 1):
        out = [out]
    return out
