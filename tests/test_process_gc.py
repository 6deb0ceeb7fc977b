"""The garbage collector over a process's life (:mod:`daa_sil.runtime.process_gc`): relaxed while a SIL node starts,
frozen at its READY, and frozen at the exit of every command, each in a fresh interpreter (the test
process's collector is left alone)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_startup_relaxes_collects_garbage_and_then_freezes_and_restores():
    """Relaxed, the young threshold is STARTUP_THRESHOLD and a garbage cycle is still freed by the
    collector once that many objects were allocated; frozen, every live object is in the permanent
    generation and the thresholds are the ones found at the start."""
    code = """
import gc, json, weakref
from daa_sil.runtime import process_gc as S
before = gc.get_threshold()
S.relax_for_startup()
relaxed = gc.get_threshold()
class Node: pass
a, b = Node(), Node(); a.peer, b.peer = b, a
gone = weakref.ref(a); del a, b
keep = [[] for _ in range(S.STARTUP_THRESHOLD // 10)]      # fewer allocations than the threshold
early = gone() is None
keep += [[] for _ in range(2 * S.STARTUP_THRESHOLD)]      # more than the threshold
late = gone() is None
S.freeze_after_startup()
print(json.dumps({"before": before, "relaxed": relaxed, "early": early, "late": late,
                  "after": gc.get_threshold(), "frozen": gc.get_freeze_count(), "alive": len(gc.get_objects())}))
"""
    res = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stderr[-2000:]
    out = json.loads(res.stdout.strip().splitlines()[-1])
    from daa_sil.runtime.process_gc import STARTUP_THRESHOLD

    assert out["relaxed"] == [STARTUP_THRESHOLD, *out["before"][1:]] and out["before"][0] < STARTUP_THRESHOLD
    assert (out["early"], out["late"]) == (False, True)  # relaxed, not off: the cycle went once the threshold passed
    assert out["after"] == out["before"]
    assert out["frozen"] > 2 * STARTUP_THRESHOLD and out["alive"] < 100  # the kept lists are frozen, not tracked


@pytest.mark.parametrize("node", ["vehicle", "gcs"])
def test_sil_nodes_start_relaxed_and_are_frozen_with_default_thresholds_at_ready(node, tmp_path):
    """The real ``python -m vehicle`` / ``python -m gcs`` start-up, stopped at its READY line: by then the
    start-up's objects (numba's, the kernels', the dialect's) are frozen and the thresholds are the
    interpreter's defaults again; before READY (here: ``--help``) the collector is the relaxed one."""
    from daa_sil.runtime.process_gc import STARTUP_THRESHOLD

    argv = {"vehicle": ["vehicle", "scenarios/head_on.yaml", "--listen", "udp:127.0.0.1:0", "--out", "udp:127.0.0.1:9",
                        "--steplog", str(tmp_path / "steps.parquet"), "--tap", "none", "--clock", "lockstep"],
            "gcs": ["gcs", "--scenario", "scenarios/head_on.yaml", "--listen", "udp:127.0.0.1:0",
                    "--vehicle", "udp:127.0.0.1:9", "--clock", "lockstep", "--no-display"]}[node]
    code = f"""
import builtins, gc, json, os, runpy, sys
defaults = gc.get_threshold()
sys.argv = {argv!r} + sys.argv[1:]
show = builtins.print
def at_ready(*a, **k):
    if a and str(a[0]).startswith("READY"):
        show(json.dumps({{"defaults": defaults, "now": gc.get_threshold(), "frozen": gc.get_freeze_count()}}), flush=True)
        os._exit(0)
    show(*a, **k)
builtins.print = at_ready
try:
    runpy.run_module({node!r}, run_name="__main__")
except SystemExit:
    show(json.dumps({{"defaults": defaults, "now": gc.get_threshold(), "frozen": gc.get_freeze_count()}}), flush=True)
"""
    for extra, want_relaxed in (([], False), (["--help"], True)):
        res = subprocess.run([sys.executable, "-c", code, *extra], cwd=ROOT, capture_output=True, text=True,
                             timeout=300)
        assert res.returncode == 0, res.stderr[-2000:]
        out = json.loads(res.stdout.strip().splitlines()[-1])
        if want_relaxed:
            assert out["now"] == [STARTUP_THRESHOLD, *out["defaults"][1:]] and out["frozen"] == 0
        else:
            assert out["now"] == out["defaults"] and out["frozen"] > 50_000, out


def test_every_command_freezes_the_collector_at_exit_after_the_other_exit_handlers():
    """``daa-sil`` (``cli.main``) and the node scripts (``cli.run_guarded``) register the freeze: it runs after
    every exit handler registered after it (they still see a working collector) and before those
    registered earlier; the command's output is complete."""
    code = """
import atexit, gc, sys
atexit.register(lambda: print("earlier handler sees frozen", gc.get_freeze_count() > 0, flush=True))
from daa_sil.cli import main, run_guarded
rc = main(["geometry", "--own", "0,0,1000,0,55,0", "--intruder", "0,6000,1000,0,-100,0", "--json"]) if ENTRY == "main" \
    else run_guarded("daa-test", lambda: print('{"done": true}'))
atexit.register(lambda: print("later handler sees frozen", gc.get_freeze_count() > 0, flush=True))
sys.exit(rc)
"""
    for entry in ("main", "run_guarded"):
        res = subprocess.run([sys.executable, "-c", code.replace("ENTRY", repr(entry))], cwd=ROOT, capture_output=True,
                             text=True, timeout=120)
        assert res.returncode == 0, res.stderr[-2000:]
        lines = res.stdout.strip().splitlines()
        assert lines[-2:] == ["later handler sees frozen False", "earlier handler sees frozen True"], lines
        assert json.loads("\n".join(lines[:-2]))  # the command's own output, whole
