"""Bad files and arguments across every command (issue 9 §4).

Every case must give exactly one line ``daa-sil...: error: ...`` on stderr naming what is wrong,
the documented exit code (2 = bad input, 1 = an output could not be written), no traceback, and
leave no half-written file: the output directory holds exactly what it held before (or does not
exist), and no ``.<name>.<random>.tmp`` temporary survives.

Most cases run in-process (``daa_sil.cli.main``); disk-full (``RLIMIT_FSIZE``, so writes fail with
EFBIG) and unwritable/unreadable paths (as an unprivileged user: root ignores file modes) run the
real command in a subprocess.
"""

from __future__ import annotations

import contextlib
import errno
import io
import json
import os
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

from daa_sil.cli import main
from daa_sil.files import is_temp_file

ROOT = Path(__file__).resolve().parents[1]
HEAD_ON = ROOT / "scenarios" / "head_on.yaml"
SMALL_GRID = "paper,dx=6,dy=6,dh=3,vi=3,vh=3,theta=4"
STATE = ["--dx", "0", "--dy", "0", "--dh", "0", "--vi", "100", "--vh", "0", "--theta", "0"]
NOBODY = 65534


# --- helpers ------------------------------------------------------------------------------------
def cli(argv: list[str]) -> tuple[int, str, str]:
    """Run ``daa-sil argv`` in-process; returns (exit code, stdout, stderr)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            rc = main([str(a) for a in argv])
        except SystemExit as exc:  # argparse errors
            rc = exc.code
    return int(rc), out.getvalue(), err.getvalue()


def sub(argv: list, cwd: Path, fsize: "int | None" = None, demote: bool = False) -> subprocess.CompletedProcess:
    """Run ``python -m daa_sil.cli argv`` in a subprocess, optionally with a file-size limit of
    ``fsize`` bytes (writes beyond it fail with EFBIG) and as an unprivileged user."""

    def pre():
        if fsize is not None:
            signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
            resource.setrlimit(resource.RLIMIT_FSIZE, (fsize, fsize))
        if demote:
            os.setgid(NOBODY)
            os.setuid(NOBODY)

    env = dict(os.environ, PYTHONDONTWRITEBYTECODE="1", DAA_SIL_CACHE=str(cwd / "cache"))
    if demote:  # the unprivileged user cannot use root's home (matplotlib's font cache lives there)
        env.update(HOME=str(cwd), MPLCONFIGDIR=str(cwd / "mpl"))
    return subprocess.run([sys.executable, "-m", "daa_sil.cli", *map(str, argv)], capture_output=True, text=True,
                          cwd=cwd, env=env, timeout=300, preexec_fn=pre)


def snapshot(d: Path) -> dict:
    """Every file under ``d`` (hidden ones too) -> its bytes; {} if ``d`` does not exist."""
    if not d.exists():
        return {}
    return {str(p.relative_to(d)): p.read_bytes() for p in sorted(d.rglob("*")) if p.is_file()}


def assert_one_line_error(rc: int, err: str, code: int, *needles: str) -> None:
    assert rc == code, (rc, err)
    assert "Traceback" not in err, err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("daa-sil") and ": error: " in lines[0], lines[0]
    for n in needles:
        assert n in lines[0], (n, lines[0])


def temps(d: Path) -> list[Path]:
    return [p for p in d.rglob("*") if is_temp_file(p)] if d.exists() else []


# --- fixtures -----------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def work(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("reliability")


@pytest.fixture(scope="module")
def maps(work) -> Path:
    """A small two-map family (turn rates 0 and +5 deg/s) on a 3,888-state grid."""
    from daa_sil import waitmap

    fam = waitmap.build_family(waitmap.resolve_grid(SMALL_GRID), waitmap.MdpParams(), (0.0, 5.0))
    d = work / "maps"
    waitmap.save_family(fam, d)
    return d


@pytest.fixture(scope="module")
def camp(work) -> Path:
    """A finished one-group campaign (3 encounters, 60 s)."""
    from daa_sil.study.campaign.run import run_campaign
    from daa_sil.study.campaign.config import CampaignConfig

    d = work / "camp"
    run_campaign(CampaignConfig(groups=("B-1",), n_encounters=3, chunk_size=3, seed=5, duration_s=60.0), d,
                 progress=False)
    return d


@pytest.fixture(scope="module")
def blocker(work) -> Path:
    """A regular file: any output path below it cannot be created (ENOTDIR, even for root)."""
    f = work / "a-file"
    f.write_text("not a directory\n")
    return f


# --- scenario YAML ------------------------------------------------------------------------------
BASE = HEAD_ON.read_text()
SCENARIOS = {
    # id: (file content, needles in the message)
    "syntax": ("name: x\nownship: {alt_m: 1000, gs_mps: 55\n", [":3:", "not valid YAML"]),
    "unknown-key": (BASE.replace("seed: 11\n", "seed: 11\ncolour: red\n"), [":7:", "colour: unknown key", "allowed:"]),
    "wrong-type": (BASE.replace("gs_mps: 55,", "gs_mps: fast,"), [":9:", "ownship.gs_mps", "must be a number", "'fast'"]),
    "missing-field": (BASE.replace("gs_mps: 55, ", ""), [":9:", "ownship.gs_mps", "missing required field"]),
    "out-of-range": (BASE.replace("hmd_m: 150", "hmd_m: 9000"),
                     [":12:", "intruders[0].cpa.hmd_m", "within [-5000, 5000]", "9000"]),
    "bad-choice": (BASE.replace("group: ID-1", "group: ID-7"), ["allocation.group", "one of B-1", "'ID-7'"]),
    "duplicate-key": (BASE.replace("duration_s: 180\n", "duration_s: 180\nduration_s: 200\n"),
                      [":8:", "duration_s: duplicate key"]),
    "bad-delay": (BASE.replace('up: "const:4"', 'up: "const:-4"'), ["link.up", "within [0.1, 10]"]),
    "no-intruders": ("name: x\nownship: {alt_m: 1000, gs_mps: 55, track_deg: 0}\nintruders: []\n",
                     [":3:", "intruders: must have 1..8 items, got 0"]),
    "empty": ("", ["empty scenario file"]),
    "not-a-mapping": ("- a\n- b\n", [":1:", "must be a mapping"]),
    "binary": (b"\xff\xfe\x00garbage", ["cannot read scenario"]),
}


@pytest.mark.parametrize("case", list(SCENARIOS), ids=list(SCENARIOS))
def test_malformed_scenario_is_one_line_exit_2_and_nothing_starts(case, tmp_path):
    content, needles = SCENARIOS[case]
    path = tmp_path / f"{case}.yaml"
    path.write_bytes(content if isinstance(content, bytes) else content.encode())
    out = tmp_path / "out"
    rc, _, err = cli(["run", path, "--out", out])
    assert_one_line_error(rc, err, 2, f"{path}", *needles)
    assert not out.exists()  # no process started, no output directory


def test_missing_and_directory_scenario(tmp_path):
    rc, _, err = cli(["run", tmp_path / "nope.yaml", "--out", tmp_path / "o"])
    assert_one_line_error(rc, err, 2, "nope.yaml", "not found")
    (tmp_path / "d.yaml").mkdir()
    rc, _, err = cli(["run", tmp_path / "d.yaml", "--out", tmp_path / "o"])
    assert_one_line_error(rc, err, 2, "d.yaml", "cannot read scenario")
    assert not (tmp_path / "o").exists()


# --- wait maps ----------------------------------------------------------------------------------
def _rewrite(src: Path, dst: Path, edit, rehash: bool) -> Path:
    """Copy the map ``src`` to ``dst`` with ``edit(meta, arrays)`` applied (hash recomputed or not)."""
    from daa_sil.waitmap.store import _content_hash

    with np.load(src) as z:
        d = {k: z[k] for k in z.files}
    meta = json.loads(str(d["meta_json"]))
    edit(meta, d)
    if rehash:
        meta["content_hash"] = _content_hash(meta, d)
    d["meta_json"] = np.array(json.dumps(meta, sort_keys=True))
    with open(dst, "wb") as fh:
        np.savez(fh, **d)
    return dst


def _set(name, idx, value):
    def edit(meta, d):
        d[name] = d[name].copy()
        d[name].flat[idx] = value
    return edit


def _make_map(kind: str, maps: Path, d: Path) -> Path:
    good = maps / "waitmap_turn+0.0.npz"
    raw = good.read_bytes()
    if kind == "truncated":
        (d / "m.npz").write_bytes(raw[: len(raw) // 2])
    elif kind == "empty":
        (d / "m.npz").write_bytes(b"")
    elif kind == "garbage":
        (d / "m.npz").write_bytes(b"hello, not a map\n" * 10)
    elif kind == "wrong-version":
        _rewrite(good, d / "m.npz", lambda m, a: m.update(format="daa-sil-waitmap/0"), rehash=True)
    elif kind == "checksum-mismatch":
        _rewrite(good, d / "m.npz", _set("wait_s", 5, 7.25), rehash=False)
    elif kind == "nan-values":  # hash matches, values impossible
        _rewrite(good, d / "m.npz", _set("wait_s", 5, np.nan), rehash=True)
    elif kind == "probability-above-1":
        _rewrite(good, d / "m.npz", _set("p_lowc", 9, 1.5), rehash=True)
    elif kind == "shape-mismatch":
        def cut(meta, a):
            for k in ("wait_s", "p_lowc", "t_lowc", "q_wait", "lowc"):
                a[k] = a[k][:2]
        _rewrite(good, d / "m.npz", cut, rehash=True)
    elif kind == "no-metadata":
        with open(d / "m.npz", "wb") as fh:
            np.savez(fh, wait_s=np.zeros(3))
    elif kind == "pickled-object":
        with open(d / "m.npz", "wb") as fh:
            np.savez(fh, meta_json=np.array([{"format": 1}], dtype=object))
    elif kind == "family-index-broken":
        shutil.copytree(maps, d / "fam")
        (d / "fam" / "family.json").write_text("{broken")
        return d / "fam"
    elif kind == "family-member-truncated":
        shutil.copytree(maps, d / "fam")
        (d / "fam" / "waitmap_turn+5.0.npz").write_bytes(raw[:1000])
        return d / "fam"
    elif kind == "family-member-missing":
        shutil.copytree(maps, d / "fam")
        (d / "fam" / "waitmap_turn+5.0.npz").unlink()
        return d / "fam"
    elif kind in ("family-entry-removed", "family-entry-duplicated"):
        shutil.copytree(maps, d / "fam")
        info = json.loads((d / "fam" / "family.json").read_text())
        info["maps"] = info["maps"][:1] if kind == "family-entry-removed" else [info["maps"][0]] * 2
        (d / "fam" / "family.json").write_text(json.dumps(info))
        return d / "fam"
    elif kind == "empty-directory":
        (d / "fam").mkdir()
        return d / "fam"
    elif kind == "missing":
        pass
    else:  # pragma: no cover
        raise AssertionError(kind)
    return d / "m.npz"


MAP_CASES = {
    "truncated": (2, ["not a readable wait-map .npz"]),
    "empty": (2, ["not a daa-sil wait map", "empty file"]),
    "garbage": (2, ["not a daa-sil wait map", "not a zip archive"]),
    "wrong-version": (2, ["unsupported wait-map format 'daa-sil-waitmap/0'", "reads 'daa-sil-waitmap/2'"]),
    "checksum-mismatch": (2, ["content hash mismatch"]),
    "nan-values": (2, ["values of wait_s outside [0, 60]"]),
    "probability-above-1": (2, ["values of p_lowc outside [0, 1]"]),
    "shape-mismatch": (2, ["array shapes do not match the grid"]),
    "no-metadata": (2, ["no meta_json entry"]),
    "pickled-object": (2, ["not a readable wait-map .npz"]),
    "family-index-broken": (2, ["family.json", "not a valid wait-map family index"]),
    "family-member-truncated": (2, ["waitmap_turn+5.0.npz", "1000 bytes, family.json records"]),
    "family-member-missing": (2, ["waitmap_turn+5.0.npz", "does not exist"]),
    "family-entry-removed": (2, ["family.json", "lists the maps +0 deg/s, but its family hash covers +0, +5"]),
    "family-entry-duplicated": (2, ["family.json", "lists the map waitmap_turn+0.0.npz more than once"]),
    "empty-directory": (2, ["no wait maps found"]),
    "missing": (2, ["m.npz", "does not exist"]),
}


@pytest.mark.parametrize("kind", list(MAP_CASES), ids=list(MAP_CASES))
def test_bad_wait_map_show_and_plot(kind, maps, tmp_path):
    code, needles = MAP_CASES[kind]
    path = _make_map(kind, maps, tmp_path)
    rc, out, err = cli(["waitmap", "show", path, *STATE])
    assert_one_line_error(rc, err, code, str(path.name), *needles)
    assert out == ""
    figs = tmp_path / "figs"
    rc, _, err = cli(["waitmap", "plot", path, "--out", figs])
    assert_one_line_error(rc, err, code, *needles)
    assert not figs.exists()


def test_good_map_still_loads(maps):
    """The oracle for the cases above: the untouched family answers."""
    rc, out, err = cli(["waitmap", "show", maps, *STATE, "--json"])
    assert rc == 0, err
    ans = json.loads(out)
    assert 0.0 <= ans["wait_s"] <= 60.0 and 0.0 <= ans["p_lowc"] <= 1.0


# --- waitmap build ------------------------------------------------------------------------------
def test_waitmap_build_bad_arguments(tmp_path, blocker):
    (tmp_path / "bad_range.yaml").write_text("base: paper\ndx: {min: 5, max: -5, n: 4}\n")
    (tmp_path / "bad_syntax.yaml").write_text("base: paper\ndx: {min: -5, max: 5, n: 4\n")
    (tmp_path / "bad_axis.yaml").write_text("base: paper\ndxx: {n: 4}\n")
    out = tmp_path / "maps"
    cases = [
        (["--grid", tmp_path / "bad_range.yaml"], 2, ["grid axis 'dx'", "min < max"]),
        (["--grid", tmp_path / "bad_syntax.yaml"], 2, ["cannot read grid file", "bad_syntax.yaml"]),
        (["--grid", tmp_path / "bad_axis.yaml"], 2, ["unknown grid axis 'dxx'", "allowed: dx, dy"]),
        (["--grid", tmp_path / "none.yaml"], 2, ["grid file", "does not exist"]),
        (["--grid", "paper,dx=a"], 2, ["grid spec item 'dx=a'"]),
        (["--grid", "paper,dx=1"], 2, []),
        (["--turn-rates", "0,0"], 2, ["--turn-rates 0 and 0 both give the file waitmap_turn+0.0.npz"]),
        (["--turn-rates", "2.51,2.54"], 2, ["both give the file waitmap_turn+2.5.npz"]),
        (["--turn-rates", "0,-0"], 2, ["both give the file waitmap_turn+0.0.npz"]),
        (["--turn-rates", "a,b"], 2, ["--turn-rates must be comma-separated numbers"]),
        (["--turn-rates", "45"], 2, ["within [-30, 30]"]),
        (["--preset", "faa"], 2, ["unknown --preset 'faa'"]),
        (["--gamma", "1.5"], 2, ["--gamma must be within"]),
    ]
    for extra, code, needles in cases:
        rc, _, err = cli(["waitmap", "build", "--grid", SMALL_GRID, "--out", out, *extra])
        assert_one_line_error(rc, err, code, *needles)
        assert not out.exists(), extra
    rc, _, err = cli(["waitmap", "build", "--grid", SMALL_GRID, "--turn-rates", "0", "--out", blocker / "m"])
    assert_one_line_error(rc, err, 1, "cannot create output directory", "Not a directory")


def test_waitmap_build_refuses_to_overwrite_and_keeps_the_old_maps(maps, tmp_path):
    d = tmp_path / "maps"
    shutil.copytree(maps, d)
    before = snapshot(d)
    rc, _, err = cli(["waitmap", "build", "--grid", SMALL_GRID, "--turn-rates", "0,5", "--out", d])
    assert_one_line_error(rc, err, 1, "refusing to overwrite", "--force")
    assert snapshot(d) == before


# --- campaign run / report ----------------------------------------------------------------------
RUN = ["campaign", "run", "--groups", "B-1", "--encounters", "3", "--chunk-size", "3", "--seed", "5",
       "--no-progress"]


def _campaign_copy(camp: Path, d: Path, damage: "str | None") -> Path:
    c = d / "c"
    shutil.copytree(camp, c)
    if damage == "json-broken":
        (c / "campaign.json").write_text("{oops")
    elif damage == "json-wrong-format":
        meta = json.loads((c / "campaign.json").read_text())
        meta["format"] = 99
        (c / "campaign.json").write_text(json.dumps(meta))
    elif damage == "json-bad-field":
        meta = json.loads((c / "campaign.json").read_text())
        meta["config"]["n_encounters"] = "many"
        (c / "campaign.json").write_text(json.dumps(meta))
    elif damage == "encounters-corrupt":
        (c / "encounters.parquet").write_bytes(b"PAR1 garbage")
    elif damage == "encounters-missing":
        (c / "encounters.parquet").unlink()
    return c


CAMPAIGN_CASES = {
    # id: (damage to a copy of a finished campaign or None = fresh dir, extra argv, code, needles)
    "workers-0": (None, ["--workers", "0"], 2, ["--workers must be within [1, ", "got 0"]),
    "workers-text": (None, ["--workers", "two"], 2, ["--workers must be an integer, got 'two'"]),
    "encounters-0": (None, ["--encounters", "0"], 2, ["--encounters must be an integer within [1, 10,000,000]"]),
    "bad-group": (None, ["--groups", "B-1,B-9"], 2, ["unknown group 'B-9'", "allowed: B-1"]),
    "scheduler-empty": (None, ["--scheduler", ""], 2, ["--scheduler must be an address"]),
    "scheduler-malformed": (None, ["--scheduler", "bogus"], 2, ["--scheduler must be an address", "'bogus'"]),
    "workers-with-remote-scheduler": (None, ["--scheduler", "tcp://127.0.0.1:8786", "--workers", "2"], 2,
                                      ["--workers applies to local runs"]),
    "resume-different-seed": ("copy", ["--resume", "--seed", "6"], 2,
                              ["--resume", "different settings (seed)"]),
    "resume-different-groups": ("copy", ["--resume", "--groups", "B-2"], 2, ["different settings (groups)"]),
    "not-empty-without-resume": ("copy", [], 2, ["is not empty; pass --resume"]),
    "resume-json-broken": ("json-broken", ["--resume"], 2, ["campaign.json is not readable JSON"]),
    "resume-json-wrong-format": ("json-wrong-format", ["--resume"], 2, ["not a daa-sil campaign file"]),
    "resume-json-bad-field": ("json-bad-field", ["--resume"], 2, ["campaign.json: bad or missing config field"]),
    "resume-encounters-corrupt": ("encounters-corrupt", ["--resume"], 2,
                                  ["encounters.parquet is not a readable Parquet file"]),
    "resume-encounters-missing": ("encounters-missing", ["--resume"], 2,
                                  ["encounters.parquet is missing; cannot resume"]),
}


@pytest.mark.parametrize("case", list(CAMPAIGN_CASES), ids=list(CAMPAIGN_CASES))
def test_campaign_run_bad_arguments_and_files(case, camp, tmp_path):
    damage, extra, code, needles = CAMPAIGN_CASES[case]
    out = _campaign_copy(camp, tmp_path, damage) if damage else tmp_path / "c"
    before = snapshot(out)
    argv = RUN + ["--out", out] + extra
    if "--seed" in extra or "--groups" in extra:  # the override replaces the base value
        argv = ["campaign", "run", "--encounters", "3", "--chunk-size", "3", "--no-progress", "--out", out] + extra
        if "--groups" not in extra:
            argv += ["--groups", "B-1"]
        if "--seed" not in extra:
            argv += ["--seed", "5"]
    rc, _, err = cli(argv)
    assert_one_line_error(rc, err, code, *needles)
    assert snapshot(out) == before  # nothing written, nothing changed


def test_scheduler_without_dask_writes_nothing(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "dask.distributed", None)  # import fails as if not installed
    out = tmp_path / "c"
    rc, _, err = cli(RUN + ["--out", out, "--scheduler", "local-dask"])
    assert_one_line_error(rc, err, 2, "--scheduler needs dask.distributed", "pip install")
    assert not out.exists()


def test_campaign_out_is_a_file_or_below_one(blocker, tmp_path):
    rc, _, err = cli(RUN + ["--out", blocker])
    assert_one_line_error(rc, err, 2, "exists and is not a directory")
    rc, _, err = cli(RUN + ["--out", blocker / "sub"])
    assert_one_line_error(rc, err, 2, "cannot create output directory", "Not a directory")
    assert blocker.read_text() == "not a directory\n"


def test_campaign_report_and_replay_bad_inputs(camp, tmp_path, blocker):
    bad = _campaign_copy(camp, tmp_path, None)
    chunk = bad / "B-1" / "encounters-00000.parquet"
    chunk.write_bytes(chunk.read_bytes()[:100])
    cases = [
        (["campaign", "report", tmp_path / "nothere"], 2, ["is not a campaign directory"]),
        (["campaign", "report", bad, "--out", tmp_path / "rep"], 2,
         ["chunk 0 of group B-1 is damaged", "encounters-00000.parquet", "--resume"]),
        (["campaign", "report", camp, "--out", blocker / "rep"], 1, ["cannot create output directory"]),
        (["viz", "replay", tmp_path / "nothere", "--group", "B-1", "--encounter", "0", "--rrd", tmp_path / "x.rrd"],
         2, ["not a campaign directory"]),
        (["viz", "replay", camp, "--group", "B-9", "--encounter", "0", "--rrd", tmp_path / "x.rrd"], 2,
         ["group B-9 is not in the campaign", "(it ran B-1)"]),
        (["viz", "replay", camp, "--group", "B-1", "--encounter", "99", "--rrd", tmp_path / "x.rrd"], 2,
         ["encounter 99 has no result"]),
        (["viz", "replay", camp, "--group", "B-1", "--encounter", "0"], 2, ["choose an output"]),
        (["viz", "replay", camp, "--group", "B-1", "--encounter", "0", "--rrd", blocker / "x.rrd"], 1,
         ["cannot write", "x.rrd"]),
        (["viz", "replay", bad, "--group", "B-1", "--worst", "--rrd", tmp_path / "x.rrd"], 2,
         ["chunk 0 of group B-1 is damaged"]),
    ]
    for argv, code, needles in cases:
        rc, _, err = cli(argv)
        assert_one_line_error(rc, err, code, *needles)
    assert not (tmp_path / "rep").exists() and not (tmp_path / "x.rrd").exists()
    assert temps(tmp_path) == []


def test_steplog_bad_files(camp, tmp_path):
    junk = tmp_path / "junk.parquet"
    junk.write_bytes(b"junk")
    for path, needles in ((junk, ["step log", "not a readable Parquet file"]),
                          (camp / "B-1" / "encounters-00000.parquet", ["not a daa-sil step log", "'step'"]),
                          (tmp_path / "none.parquet", ["does not exist"])):
        rc, _, err = cli(["viz", "steplog", path, "--rrd", tmp_path / "z.rrd"])
        assert_one_line_error(rc, err, 2, *needles)
    assert not (tmp_path / "z.rrd").exists()


# --- geometry, daa, shim, run: arguments --------------------------------------------------------
OWN, INTR = "0,0,1000,0,55,0", "0,6000,1000,0,-100,0"
ARG_CASES = {
    "geometry-short-vector": (["geometry", "--own", "0,0,0", "--intruder", INTR], ["needs 6 comma-separated"]),
    "geometry-nan": (["geometry", "--own", "0,0,0,0,nan,0", "--intruder", INTR], ["component 5 must be finite"]),
    "geometry-huge": (["geometry", "--own", OWN, "--intruder", "1e300,0,0,0,0,0"],
                      ["--intruder x must be within [-1e+07, 1e+07] m"]),
    "geometry-preset": (["geometry", "--own", OWN, "--intruder", INTR, "--preset", "x"], ["unknown --preset 'x'"]),
    "geometry-lookahead": (["geometry", "--own", OWN, "--intruder", INTR, "--lookahead", "-1"],
                           ["--lookahead must be within"]),
    "geometry-missing-flag": (["geometry", "--own", OWN], ["required: --intruder"]),
    "daa-not-a-number": (["daa", "--own", OWN, "--intruder", "a,0,0,0,0,0"], ["component 1 is not a number"]),
    "daa-zero-speed": (["daa", "--own", "0,0,0,0,0,0", "--intruder", INTR], ["non-zero horizontal velocity"]),
    "daa-huge-speed": (["daa", "--own", "0,0,0,0,1e300,0", "--intruder", INTR],  # crashed the band search before
                       ["--own vy must be within [-1000, 1000] m/s"]),
    "run-speed-0": (["run", HEAD_ON, "--speed", "0"], ["--speed must be within [0.01, 1000]"]),
    "run-speed-nan": (["run", HEAD_ON, "--speed", "nan"], ["--speed must be within"]),
    "run-missing-key": (["run", HEAD_ON, "--key", "/nonexistent/key"], ["key file", "does not exist"]),
    "run-bad-tap": (["run", HEAD_ON, "--tap", "udp:x"], ["--tap"]),
    "run-bad-clock": (["run", HEAD_ON, "--clock", "fast"], ["invalid choice: 'fast'"]),
    "unknown-command": (["frobnicate"], ["invalid choice"]),
}


@pytest.mark.parametrize("case", list(ARG_CASES), ids=list(ARG_CASES))
def test_bad_arguments_are_one_line_exit_2(case, tmp_path, monkeypatch):
    argv, needles = ARG_CASES[case]
    monkeypatch.chdir(tmp_path)
    rc, out, err = cli(argv + (["--out", tmp_path / "o"] if argv[0] == "run" else []))
    assert_one_line_error(rc, err, 2, *needles)
    assert out == "" and list(tmp_path.iterdir()) == []


def test_run_output_below_a_file_starts_nothing(blocker, tmp_path):
    rc, _, err = cli(["run", HEAD_ON, "--out", blocker / "o"])
    assert_one_line_error(rc, err, 1, "cannot create output directory", "Not a directory")


SHIM_CASES = {
    "delay": (["--delay", "const:-1"], ["const"]),
    "loss": (["--loss", "1.5"], ["--loss"]),
    "outage": (["--outage", "5:3"], ["--outage"]),
    "address": (["--vehicle", "udp:nothere"], ["udp:nothere"]),
    "reorder-with-signing-key-missing": (["--reorder", "0.1", "--key", "/nonexistent/key"], []),
}


@pytest.mark.parametrize("case", list(SHIM_CASES), ids=list(SHIM_CASES))
def test_shim_bad_arguments_exit_2_before_binding(case):
    """Each fails before the shim binds a port (``--duration 1`` bounds a shim that wrongly starts)."""
    extra, needles = SHIM_CASES[case]
    base = [] if "--delay" in extra else ["--delay", "const:1"]
    rc, out, err = cli(["shim", *base, *extra, "--duration", "1"])
    assert_one_line_error(rc, err, 2, *needles)
    assert out == ""


# --- disk full: RLIMIT_FSIZE in a subprocess (writes fail with EFBIG) -------------------------------
def _assert_no_partial(d: Path, limit: int) -> None:
    assert temps(d) == [], temps(d)
    for p in d.rglob("*"):
        if p.is_file():
            assert p.stat().st_size <= limit, p  # nothing cut off at the limit survived
            if p.suffix == ".png":
                assert p.read_bytes()[-8:-4] == b"IEND", p  # a complete PNG
            if p.suffix == ".parquet":
                assert p.read_bytes()[-4:] == b"PAR1", p


def test_disk_full_waitmap_build(tmp_path):
    out = tmp_path / "maps"
    cp = sub(["waitmap", "build", "--grid", SMALL_GRID, "--turn-rates", "0,5", "--out", out], tmp_path,
             fsize=20_000)  # one map is ~170 kB
    assert_one_line_error(cp.returncode, cp.stderr, 1, "file size limit reached while writing", "waitmap_turn",
                          "nothing was written")
    assert sorted(p.name for p in out.iterdir()) == []  # no map, no index, no temporary


def test_disk_full_waitmap_plot(maps, tmp_path):
    figs = tmp_path / "figs"
    cp = sub(["waitmap", "plot", maps, "--out", figs], tmp_path, fsize=5_000)
    assert_one_line_error(cp.returncode, cp.stderr, 1, "file size limit reached while writing", ".png")
    _assert_no_partial(figs, 5_000)


def test_disk_full_campaign_run_then_resume_completes(tmp_path):
    out = tmp_path / "c"
    cp = sub(RUN + ["--out", out], tmp_path, fsize=10_000)  # the encounter set alone is ~15 kB
    assert_one_line_error(cp.returncode, cp.stderr, 1, "file size limit reached while writing",
                          "encounters.parquet")
    _assert_no_partial(out, 10_000)
    assert not (out / "encounters.parquet").exists() and not (out / "campaign.json").exists()
    # with room again, --resume finishes the campaign
    rc, _, err = cli(RUN + ["--out", out, "--resume"])
    assert rc == 0, err
    assert json.loads((out / "campaign.json").read_text())["status"] == "complete"


def test_disk_full_campaign_report(camp, tmp_path):
    rep = tmp_path / "rep"
    cp = sub(["campaign", "report", camp, "--out", rep], tmp_path, fsize=8_000)
    assert_one_line_error(cp.returncode, cp.stderr, 1, "file size limit reached while writing")
    _assert_no_partial(rep, 8_000)


def test_enospc_mid_chunk_write_leaves_no_chunk_file(tmp_path, monkeypatch):
    """A real ENOSPC in the middle of a chunk table's write (half the bytes, then the error)."""
    real = Path.write_bytes
    calls = []

    def full_on_decisions(self, data):
        calls.append(self.name)
        if not self.name.startswith(".decisions-"):
            return real(self, data)
        real(self, data[: len(data) // 2])  # a partial file ...
        raise OSError(errno.ENOSPC, "No space left on device")  # ... then the disk is full

    monkeypatch.setattr(Path, "write_bytes", full_on_decisions)
    out = tmp_path / "c"
    rc, _, err = cli(RUN + ["--out", out])
    assert_one_line_error(rc, err, 1, "disk full while writing", "decisions-00000.parquet", "nothing was written")
    assert any(c.startswith(".decisions-00000.parquet.") for c in calls)
    assert sorted(p.name for p in (out / "B-1").iterdir()) == []  # no chunk file, no temporary
    assert json.loads((out / "campaign.json").read_text())["status"] == "running"


# --- unwritable directories and unreadable inputs ----------------------------------------------
def _kernel_readonly_dir() -> "Path | None":
    """A directory the kernel refuses to create files in even for root (sysfs), or None."""
    d = Path("/sys/kernel")
    try:
        fd, name = tempfile.mkstemp(dir=d)
    except OSError:
        return d if d.is_dir() else None
    os.close(fd)  # pragma: no cover - writable after all
    os.unlink(name)
    return None


@pytest.fixture
def readonly_dir(tmp_path):
    """An existing directory this process cannot write into: mode 0555 for a normal user; as root
    (file modes are not enforced) sysfs, where even root cannot create files."""
    if os.geteuid() != 0:
        d = tmp_path / "readonly"
        d.mkdir()
        d.chmod(0o555)
        yield d
        d.chmod(0o755)
        return
    d = _kernel_readonly_dir()
    if d is None:
        pytest.skip("root without a read-only directory: file modes are not enforced")
    yield d


def _denied(err: str) -> None:
    assert "not writable" in err or "Permission denied" in err, err


def test_unwritable_output_directories(readonly_dir, maps, camp, tmp_path):
    before = sorted(p.name for p in readonly_dir.iterdir())
    cases = [
        (["waitmap", "build", "--grid", SMALL_GRID, "--turn-rates", "0", "--out", readonly_dir], 1),
        (["waitmap", "plot", maps, "--out", readonly_dir], 1),
        (["campaign", "report", camp, "--out", readonly_dir], 1),
        (["run", HEAD_ON, "--out", readonly_dir], 1),
        (["viz", "steplog", tmp_path / "none.parquet", "--rrd", readonly_dir / "x.rrd"], 2),  # input checked first
    ]
    for argv, code in cases:
        rc, _, err = cli(argv)
        assert_one_line_error(rc, err, code)
        if code == 1:
            _denied(err)
    rc, _, err = cli(RUN + ["--out", readonly_dir / "campaign"])  # a new directory below it
    assert rc in (1, 2) and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert "cannot" in err or "not writable" in err
    assert sorted(p.name for p in readonly_dir.iterdir()) == before  # nothing appeared


@pytest.mark.skipif(os.geteuid() == 0, reason="root reads files whatever their mode")
def test_unreadable_inputs(tmp_path, maps):
    secret_map = tmp_path / "secret.npz"
    shutil.copy(maps / "waitmap_turn+0.0.npz", secret_map)
    secret_yaml = tmp_path / "secret.yaml"
    shutil.copy(HEAD_ON, secret_yaml)
    for p in (secret_map, secret_yaml):
        p.chmod(0o000)
    rc, _, err = cli(["waitmap", "show", secret_map, *STATE])
    assert_one_line_error(rc, err, 2, "secret.npz", "Permission denied")
    rc, _, err = cli(["run", secret_yaml, "--out", tmp_path / "o"])
    assert_one_line_error(rc, err, 2, "secret.yaml", "Permission denied")
    assert not (tmp_path / "o").exists()


def test_corrupt_cached_wait_maps_are_rebuilt(tmp_path, monkeypatch):
    """The vehicle and the campaign load maps through the cache: a corrupt entry is rebuilt, not used."""
    from daa_sil import waitmap

    monkeypatch.setenv("DAA_SIL_CACHE", str(tmp_path))
    kw = dict(grid="paper,dx=4,dy=4,dh=2,vi=2,vh=2,theta=4", turn_rates=(0.0,))
    first = waitmap.default_family("paper", **kw)
    (entry,) = list((tmp_path / "waitmaps").iterdir())
    f = entry / "waitmap_turn+0.0.npz"
    f.write_bytes(f.read_bytes()[:500])  # truncated on disk
    again = waitmap.default_family("paper", **kw)
    assert again.maps[0].wait_s.tobytes() == first.maps[0].wait_s.tobytes()
    assert waitmap.load(f).wait_s.tobytes() == first.maps[0].wait_s.tobytes()  # the file is whole again
