"""docs/results/regenerate.py, the one command behind the published study: it refuses a development seed
as the report seed, a re-render needs the finished runs, and the record of the code that simulated is
written once and kept (a re-render on later code names the code that ran the campaigns)."""

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "docs" / "results" / "regenerate.py"


def _module():
    spec = importlib.util.spec_from_file_location("regenerate", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _run(*argv):
    return subprocess.run([sys.executable, str(SCRIPT), *argv], capture_output=True, text=True, timeout=120)


def test_a_development_seed_is_refused_and_nothing_is_written(tmp_path):
    mod = _module()
    assert 2718 in mod.DEV_SEEDS and 424242 in mod.DEV_SEEDS and 7350411 not in mod.DEV_SEEDS
    for seed in ("2718", "424242"):
        r = _run("--runs", str(tmp_path / "runs"), "--seed", seed, "--docs", str(tmp_path / "docs"))
        assert r.returncode == 2 and "used while developing" in r.stderr and "Traceback" not in r.stderr
    assert not (tmp_path / "runs").exists() and not (tmp_path / "docs").exists()


def test_render_only_needs_the_finished_runs(tmp_path):
    r = _run("--runs", str(tmp_path / "runs"), "--seed", "7350411", "--render-only", "--docs", str(tmp_path / "d"))
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1
    assert "missing: 26 campaign(s), the first" in r.stderr and str(tmp_path / "runs" / "paper") in r.stderr
    assert not (tmp_path / "d").exists()


def test_the_code_that_simulated_is_recorded_once(tmp_path):
    mod = _module()
    (tmp_path / "code.json").write_text(json.dumps({"commit": "abc123", "dirty": False}))
    assert mod.code_record(tmp_path) == {"commit": "abc123", "dirty": False}  # kept, not rewritten
    fresh = mod.code_record(tmp_path / "new")
    assert set(fresh) == {"commit", "dirty"} and json.loads((tmp_path / "new" / "code.json").read_text()) == fresh
