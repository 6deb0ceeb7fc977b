"""``daa-sil geometry`` through the installed console script."""

import json
import math
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

# the console script of the environment running the tests (its bin directory need not be on PATH)
EXE = shutil.which("daa-sil", path=str(Path(sys.executable).parent)) or shutil.which("daa-sil")


def run(*args):
    return subprocess.run([EXE, *args], capture_output=True, text=True, timeout=60)


def test_json_head_on():
    r = run("geometry", "--own", "0,0,1000,0,55,0", "--intruder", "0,6000,1000,0,-100,0", "--json")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    for key in ("range_m", "hmd_m", "t_cpa_s", "tau_mod_s", "dh_m", "wcv_now", "violation_interval_s",
                "nmac_now", "preset"):
        assert key in out
    assert out["preset"] == "do365"
    assert out["range_m"] == pytest.approx(6000)
    assert out["t_cpa_s"] == pytest.approx(6000 / 155)
    D = 1219.2
    r_in = (35 * 155 + math.sqrt((35 * 155) ** 2 + 4 * D * D)) / 2
    assert out["violation_interval_s"][0] == pytest.approx((6000 - r_in) / 155, abs=1e-6)
    assert out["wcv_now"] is False and out["nmac_now"] is False


def test_json_null_where_undefined_and_paper_preset():
    r = run("geometry", "--own", "0,0,0,0,55,0", "--intruder", "0,-5000,0,0,-100,0", "--json", "--preset", "paper")
    out = json.loads(r.stdout)
    assert out["preset"] == "paper"
    assert out["tau_mod_s"] is None and out["violation_interval_s"] is None


def test_human_output_mentions_violation():
    r = run("geometry", "--own", "0,0,1000,0,55,0", "--intruder", "0,6000,1000,0,-100,0")
    assert r.returncode == 0
    assert "violation" in r.stdout and "tau_mod" in r.stdout


@pytest.mark.parametrize("args,needle", [
    (["--own", "0,0,0,0,55", "--intruder", "0,0,0,0,0,0"], "needs 6"),
    (["--own", "0,0,nan,0,55,0", "--intruder", "0,0,0,0,0,0"], "finite"),
    (["--own", "0,0,0,0,55,0", "--intruder", "0,0,x,0,0,0"], "not a number"),
    (["--own", "0,0,0,0,55,0", "--intruder", "0,0,0,0,0,0", "--preset", "icao"], "allowed: do365, paper"),
    (["--own", "0,0,0,0,55,0", "--intruder", "0,0,0,0,0,0", "--lookahead", "-3"], "--lookahead"),
])
def test_bad_input_one_line_exit_2(args, needle):
    r = run("geometry", *args)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0]
    assert "Traceback" not in r.stderr


def test_the_console_script_is_installed():
    assert EXE is not None, "the daa-sil console script is missing: install the package (pip install -e .)"
