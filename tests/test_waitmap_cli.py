"""`daa-sil waitmap` through the installed console script."""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

# the console script of the environment running the tests (its bin directory need not be on PATH)
EXE = shutil.which("daa-sil", path=str(Path(sys.executable).parent)) or shutil.which("daa-sil")


def run(*args, cwd=None):
    return subprocess.run([EXE, "waitmap", *args], capture_output=True, text=True, cwd=cwd, timeout=300)


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    out = tmp_path_factory.mktemp("maps")
    r = run("build", "--grid", "paper", "--out", str(out))
    assert r.returncode == 0, r.stderr
    return out, r


def test_build_writes_one_map_per_turn_rate(built):
    out, r = built
    paths = r.stdout.split()
    files = sorted(p.name for p in out.glob("waitmap_turn*.npz"))
    assert files == sorted(["waitmap_turn-5.0.npz", "waitmap_turn-2.5.npz", "waitmap_turn+0.0.npz",
                            "waitmap_turn+2.5.npz", "waitmap_turn+5.0.npz"])
    assert all(any(p.endswith(f) for p in paths) for f in files)
    assert (out / "family.json").is_file()


def test_build_refuses_to_overwrite(built):
    out, _ = built
    r = run("build", "--grid", "paper,dx=4,dy=4", "--out", str(out))
    assert r.returncode == 1 and "refusing to overwrite" in r.stderr and len(r.stderr.strip().splitlines()) == 1


def test_show_json(built):
    out, _ = built
    r = run("show", str(out / "waitmap_turn+0.0.npz"), "--dx", "-1400", "--dy", "1400", "--dh", "200",
            "--vi", "70", "--vh", "0", "--theta", "90", "--json")
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["action"] in ("wait", "evade") and 0 <= d["wait_s"] <= 60 and 0 <= d["p_lowc"] <= 1
    assert d["in_grid"] is True and d["preset"] == "paper"
    far = json.loads(run("show", str(out), "--turn-rate", "4", "--dx", "-5000", "--dy", "0", "--dh", "0",
                         "--vi", "100", "--vh", "0", "--theta", "180", "--json").stdout)
    assert far["in_grid"] is False and far["wait_s"] == 60 and far["action"] == "wait" and far["turn_rate_deg"] == 5.0


def test_plot_writes_pngs(built, tmp_path):
    out, _ = built
    r = run("plot", str(out), "--out", str(tmp_path / "figs"))
    assert r.returncode == 0, r.stderr
    pngs = sorted((tmp_path / "figs").glob("*.png"))
    assert {p.name for p in pngs} == {"slices_geometries.png", "mirror_pair.png", "histogram.png", "map_3d.png"}
    for p in pngs:
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and p.stat().st_size > 5000


@pytest.mark.parametrize("args", [
    ["build", "--grid", "paper,dx=1"],
    ["build", "--preset", "faa"],
    ["build", "--gamma", "1.5"],
    ["build", "--turn-rates", "a,b"],
    ["show", "nonexistent.npz", "--dx", "0", "--dy", "0", "--dh", "0", "--vi", "100", "--vh", "0", "--theta", "0"],
    ["show", "x.npz", "--dx", "nan", "--dy", "0", "--dh", "0", "--vi", "100", "--vh", "0", "--theta", "0"],
    ["show", "x.npz", "--dx", "0"],
    ["frobnicate"],
])
def test_bad_arguments_exit_2_with_one_line(args, tmp_path):
    r = run(*args, cwd=tmp_path)
    assert r.returncode == 2, (r.returncode, r.stderr)
    assert len(r.stderr.strip().splitlines()) == 1 and "error" in r.stderr and "Traceback" not in r.stderr


def test_corrupt_map_is_a_one_line_error(tmp_path):
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"PK\x03\x04 truncated")
    r = run("show", str(bad), "--dx", "0", "--dy", "0", "--dh", "0", "--vi", "100", "--vh", "0", "--theta", "0")
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "bad.npz" in r.stderr


def test_help_has_examples():
    for verb in ("build", "show", "plot"):
        r = run(verb, "--help")
        assert r.returncode == 0 and "examples:" in r.stdout


def test_check_prints_the_papers_properties(built):
    out, _ = built
    r = run("check", str(out))
    assert r.returncode == 0, r.stderr
    assert "head-on waits < overtaking at equal range: holds" in r.stdout
    assert "the paper's Fig. 3 shape (min about 1 s (<= 2 s); max about 40 s (35-45 s); most states within " \
        "5-10 s (> 50 %); left skewed (quartile skewness < 0)): no, fails: most states within 5-10 s" in r.stdout
    j = run("check", str(out), "--json")
    rep = json.loads(j.stdout)
    assert rep["ok"] and rep["head_on_vs_overtaking"]["n"] > 0 and not rep["paper_shape"]
    assert rep["shape_checks"]["min about 1 s (<= 2 s)"] and not rep["shape_checks"]["most states within 5-10 s (> 50 %)"]


def test_build_options_reach_the_map_metadata(tmp_path):
    r = run("build", "--grid", "paper,dx=4,dy=4,dh=2,vi=2,vh=2,theta=4", "--turn-rates", "0",
            "--definition", "until_evade", "--p-min", "0.01", "--out", str(tmp_path / "m"), "--json")
    assert r.returncode == 0, r.stderr
    from daa_sil import waitmap

    fam = waitmap.load_family(tmp_path / "m")
    assert fam.params.wait_definition == "until_evade" and fam.params.p_min == 0.01 and fam.params.horizon == 60.0


def test_the_console_script_is_installed():
    assert EXE is not None, "the daa-sil console script is missing: install the package (pip install -e .)"
