"""The wait-map cache and the parallel family build (issue 20 item 4, issue 21 item 6).

* A cache entry is used only after it has been checked against what the family must be: a
  ``family.json`` with entries removed, duplicated or edited, a missing, truncated, replaced or
  damaged member is repaired with one warning line (maps that still prove whole are kept), never
  loaded as it is and never a usage error.
* The check that runs on every start reads no array: a damaged array is caught by the zip CRC-32
  when the map is read (shown for every array of a map).
* Ctrl-C during a first build keeps the finished maps; the next run builds only the rest.
* The maps built in parallel processes are bit-identical to the serial build.
* A builder process dies with its parent, even on SIGKILL.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest

from daa_sil import waitmap
from daa_sil.errors import FileFormatError
from daa_sil.waitmap.build import build_members
from daa_sil.waitmap.source import map_params
from daa_sil.waitmap.family_files import check_family
from daa_sil.waitmap.store import ARRAYS, load, map_filename

SMALL = "paper,dx=6,dy=6,dh=3,vi=3,vh=3,theta=4"  # 3,888 states: a map in well under a second
RATES = waitmap.PAPER_TURN_RATES
#: solver statistics that are wall-clock timings (everything else must be identical)
TIMINGS = {"build_s", "seconds", "wait_time_s", "total_s"}
LIMIT_S = 300.0  # bound on any one process, so a hang fails instead of blocking CI


def _arrays(wm) -> dict:
    return {n: np.ascontiguousarray(getattr(wm, n)) for n in ARRAYS}


def _same_map(a, b) -> bool:
    """Bit-identical arrays, same condition, same solver statistics apart from timings."""
    return (a.turn_rate_deg == b.turn_rate_deg
            and all(x.dtype == y.dtype and x.shape == y.shape and x.tobytes() == y.tobytes()
                    for x, y in zip(_arrays(a).values(), _arrays(b).values()))
            and {k: v for k, v in a.stats.items() if k not in TIMINGS}
            == {k: v for k, v in b.stats.items() if k not in TIMINGS})


@pytest.fixture(scope="module")
def good_cache(tmp_path_factory) -> Path:
    """A cache root holding one good entry of the small family (all five turn rates)."""
    root = tmp_path_factory.mktemp("cache")
    old = os.environ.get("DAA_SIL_CACHE")
    os.environ["DAA_SIL_CACHE"] = str(root)
    try:
        waitmap.default_family("paper", grid=SMALL)
    finally:
        if old is None:
            os.environ.pop("DAA_SIL_CACHE")
        else:
            os.environ["DAA_SIL_CACHE"] = old
    return root


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The small family built serially in memory: the oracle every repaired entry must equal."""
    g, p = map_params(SMALL)
    return waitmap.build_family(g, p, RATES)


def _entry(root: Path) -> Path:
    (entry,) = [d for d in (root / "waitmaps").iterdir() if d.is_dir()]
    return entry


def _index(entry: Path) -> dict:
    return json.loads((entry / "family.json").read_text())


def _edit_index(entry: Path, change) -> None:
    info = _index(entry)
    change(info)
    (entry / "family.json").write_text(json.dumps(info))


def _data_offset(path: Path, member: str) -> tuple[int, int]:
    """(offset, size) of a stored (uncompressed) zip member's bytes in ``path``."""
    with zipfile.ZipFile(path) as zf:
        info = zf.getinfo(member)
    with open(path, "rb") as fh:
        fh.seek(info.header_offset)
        head = fh.read(30)
    name_len, extra_len = int.from_bytes(head[26:28], "little"), int.from_bytes(head[28:30], "little")
    return info.header_offset + 30 + name_len + extra_len, info.file_size


def _flip_middle_byte(path: Path, member: str) -> None:
    off, size = _data_offset(path, member)
    data = bytearray(path.read_bytes())
    data[off + size // 2] ^= 0xFF
    path.write_bytes(bytes(data))


def _damage(kind: str, entry: Path) -> None:
    if kind == "entries-removed":  # only the -5 and -2.5 deg/s maps left in the index
        _edit_index(entry, lambda i: i.update(maps=i["maps"][:2]))
    elif kind == "entry-duplicated":  # the -5 deg/s map five times
        _edit_index(entry, lambda i: i.update(maps=[i["maps"][0]] * 5))
    elif kind == "entry-hash-edited":
        _edit_index(entry, lambda i: i["maps"][2].update(content_hash="0" * 64))
    elif kind == "family-hash-edited":
        _edit_index(entry, lambda i: i.update(family_hash="f" * 64))
    elif kind == "turn-rates-edited":
        _edit_index(entry, lambda i: i.update(turn_rates_deg=[-5.0, -2.5, 0.0, 2.5, 4.0]))
    elif kind == "index-garbage":
        (entry / "family.json").write_text("{broken")
    elif kind == "index-missing":  # as a build interrupted before its index leaves it
        (entry / "family.json").unlink()
    elif kind == "member-missing":
        (entry / map_filename(2.5)).unlink()
    elif kind == "member-truncated":
        f = entry / map_filename(0.0)
        f.write_bytes(f.read_bytes()[:1000])
    elif kind == "member-replaced":  # the +5 map's file under the -5 map's name
        shutil.copyfile(entry / map_filename(5.0), entry / map_filename(-5.0))
    elif kind == "member-array-damaged":  # one byte of wait_s, same size: only the CRC sees it
        _flip_middle_byte(entry / map_filename(-2.5), "wait_s.npy")
    else:  # pragma: no cover
        raise AssertionError(kind)


#: kind -> the maps that must be built again (the others are kept, byte for byte)
DAMAGE = {
    "entries-removed": set(), "entry-duplicated": set(), "entry-hash-edited": set(),
    "family-hash-edited": set(), "turn-rates-edited": set(), "index-garbage": set(),
    "index-missing": set(), "member-missing": {2.5}, "member-truncated": {0.0},
    "member-replaced": {-5.0}, "member-array-damaged": {-2.5},
}


@pytest.mark.parametrize("kind", list(DAMAGE), ids=list(DAMAGE))
def test_a_damaged_cache_entry_is_repaired_with_one_warning(kind, good_cache, reference, tmp_path, monkeypatch,
                                                            capsys):
    """Issue 20 item 4: bba2fd8 loaded an index with entries removed or duplicated silently (a run
    then read the -5 and -2.5 maps only, or the -5 map five times) and raised a usage error for a
    missing member. Every damage now gives one warning line, the entry is repaired (whole maps
    kept, the rest rebuilt), the family has its five maps, and the next load is silent."""
    root = tmp_path / "cache"
    shutil.copytree(good_cache, root)
    monkeypatch.setenv("DAA_SIL_CACHE", str(root))
    entry = _entry(root)
    before = {r: (entry / map_filename(r)).read_bytes() for r in RATES}
    _damage(kind, entry)
    capsys.readouterr()

    fam = waitmap.default_family("paper", grid=SMALL)

    err = capsys.readouterr().err
    warnings = [ln for ln in err.splitlines() if ln.strip()]
    assert len(warnings) == 1 and warnings[0].startswith("daa-sil: warning: wait-map cache entry"), err
    rebuilt = DAMAGE[kind]
    assert f"rebuilding {len(rebuilt)} of 5 maps" in warnings[0] or (kind == "index-missing" and
                                                                     "keeping its 5 finished maps" in warnings[0])
    assert [m.turn_rate_deg for m in fam.maps] == list(RATES)
    assert all(_same_map(a, b) for a, b in zip(fam.maps, reference.maps))
    for r in RATES:  # whole maps were kept as they were, not rebuilt
        if r not in rebuilt:
            assert (entry / map_filename(r)).read_bytes() == before[r], r
    check_family(entry, RATES)  # the repaired index passes the check
    again = waitmap.default_family("paper", grid=SMALL)
    assert capsys.readouterr().err == ""
    assert [m.content_hash for m in again.maps] == [m.content_hash for m in fam.maps]


@pytest.mark.parametrize("member", ["meta_json.npy", *[f"{a}.npy" for a in ARRAYS]])
def test_the_cheap_check_plus_the_crc_catch_one_flipped_byte_in_any_array(member, good_cache, tmp_path):
    """The start-up check reads no array and trusts the content hashes in family.json; a byte
    flipped inside any array of a map (size unchanged) must still be caught when the map is read:
    by the zip CRC-32 zipfile checks at the end of each member."""
    d = tmp_path / "fam"
    shutil.copytree(_entry(good_cache), d)
    f = d / map_filename(2.5)
    _flip_middle_byte(f, member)
    with pytest.raises(FileFormatError, match=r"waitmap_turn\+2\.5\.npz"):
        waitmap.load_family(d, RATES)


def test_the_cheap_check_reads_no_array(good_cache, tmp_path, monkeypatch):
    """check_family opens each map's zip directory and its small meta_json member only."""
    opened = []
    real_open = zipfile.ZipFile.open

    def spy(self, name, *a, **kw):
        opened.append(name if isinstance(name, str) else name.filename)
        return real_open(self, name, *a, **kw)

    monkeypatch.setattr(zipfile.ZipFile, "open", spy)
    idx = check_family(_entry(good_cache), RATES)
    assert len(idx.maps) == 5 and set(opened) == {"meta_json.npy"}


def test_parallel_build_is_bit_identical_to_the_serial_build(tmp_path):
    """Issue 21 item 6: the five maps built in parallel processes equal the serial build's, array
    for array, bit for bit (and every solver statistic but the timings)."""
    g, p = map_params(SMALL)
    serial, parallel = tmp_path / "serial", tmp_path / "parallel"
    serial.mkdir()
    parallel.mkdir()
    build_members(g, p, RATES, serial, workers=1)
    done = []
    build_members(g, p, RATES, parallel, workers=2, progress=done.append)
    assert sorted(done) == sorted(RATES)
    for r in RATES:
        a, b = load(serial / map_filename(r)), load(parallel / map_filename(r))
        assert _same_map(a, b), r
    assert not [f for f in parallel.iterdir() if f.name.startswith(".")]  # no temporary left


def _stat(pid: int) -> "list[str] | None":
    """Fields of /proc/PID/stat after the command name (state first), or None if there is none."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return stat[stat.rindex(")") + 2:].split()


def _children(pid: int) -> dict[int, str]:
    """The live processes whose parent is ``pid`` (Linux /proc): pid -> start time (which tells a
    process from a later one that reuses its pid)."""
    out = {}
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            f = _stat(int(d.name))
            if f is not None and int(f[1]) == pid and f[0] != "Z":
                out[int(d.name)] = f[19]
    return out


def _named_children(pid: int, name: str = "daa-sil-waitmap") -> list[int]:
    out = []
    for p in _children(pid):
        try:
            if Path(f"/proc/{p}/comm").read_text().strip() == name:
                out.append(p)
        except OSError:
            pass
    return out


def _wait_gone(procs: dict, limit_s: float) -> None:
    end = time.monotonic() + limit_s
    while any(_alive(p, t) for p, t in procs.items()) and time.monotonic() < end:
        time.sleep(0.05)


def _alive(pid: int, start: str) -> bool:
    f = _stat(pid)
    return f is not None and f[19] == start and f[0] != "Z"


def _console(name: str) -> str:
    path = Path(sys.executable).parent / name
    assert path.is_file(), f"{path} is not installed (pip install -e .)"
    return str(path)


#: ~200,000 states: a map takes a few seconds, long enough to interrupt a build mid-way
SLOW = "paper,dx=16,dy=16,theta=8"


def _campaign(cache: Path, out: Path) -> subprocess.Popen:
    env = dict(os.environ, DAA_SIL_CACHE=str(cache), PYTHONDONTWRITEBYTECODE="1")
    return subprocess.Popen([_console("daa-sil"), "campaign", "run", "--groups", "ID-2", "--encounters", "2",
                             "--duration", "30", "--waitmap", SLOW, "--out", str(out), "--no-progress"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
                            start_new_session=True)


def _wait_for(cond, proc: subprocess.Popen, what: str) -> None:
    end = time.monotonic() + LIMIT_S
    while not cond():
        assert proc.poll() is None, f"ended before {what}: {proc.communicate()}"
        assert time.monotonic() < end, f"no {what} within {LIMIT_S} s"
        time.sleep(0.02)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_ctrl_c_during_a_first_build_keeps_the_finished_maps(tmp_path):
    """Issue 20 item 4: Ctrl-C (SIGINT to the process group, as a terminal sends it) while a campaign
    builds its maps into an empty cache: exit 130, the finished maps stay, no builder process and no
    temporary is left; the next run keeps them (same bytes) and builds only the rest."""
    cache = tmp_path / "cache"
    proc = _campaign(cache, tmp_path / "run1")
    try:
        maps = lambda: list(cache.glob("waitmaps/*/waitmap_turn*.npz"))  # noqa: E731
        _wait_for(lambda: len(maps()) >= 1, proc, "the first finished map")
        children = _children(proc.pid)  # the builders, and multiprocessing's resource tracker
        os.killpg(proc.pid, signal.SIGINT)
        out, err = proc.communicate(timeout=LIMIT_S)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert proc.returncode == 130, err
    assert "Traceback" not in err, err
    entry = _entry(cache)
    kept = {f.name: (f.stat().st_ino, f.read_bytes()) for f in entry.glob("waitmap_turn*.npz")}
    assert 1 <= len(kept) < 5, sorted(kept)
    assert not (entry / "family.json").exists()
    _wait_gone(children, 5.0)
    assert not [p for p, t in children.items() if _alive(p, t)], "a process it started outlived the build by 5 s"
    assert not list(entry.glob(".*.tmp"))
    for name in kept:
        load(entry / name)  # each finished map is whole

    proc = _campaign(cache, tmp_path / "run2")
    out, err = proc.communicate(timeout=LIMIT_S)
    assert proc.returncode == 0, err
    (line,) = [ln for ln in err.splitlines() if ": warning: " in ln]
    assert f"keeping its {len(kept)} finished maps, building the other {5 - len(kept)}" in line, line
    for name, (ino, data) in kept.items():  # not rebuilt: the same file, the same bytes
        f = entry / name
        assert f.stat().st_ino == ino and f.read_bytes() == data, name
    assert len(check_family(entry, RATES).maps) == 5
    print(f"\nCtrl-C figures: {len(kept)} of 5 maps kept after the interrupt, {5 - len(kept)} built by the next run")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG and /proc are Linux")
def test_builder_processes_die_with_their_parent_even_on_sigkill(tmp_path):
    cache = tmp_path / "cache"
    proc = _campaign(cache, tmp_path / "run")
    try:
        # two builders at work, each named so that pgrep finds it
        _wait_for(lambda: len(_named_children(proc.pid)) >= 2, proc, "two builder processes named daa-sil-waitmap")
        children = _children(proc.pid)  # the builders, and multiprocessing's resource tracker
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=LIMIT_S)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    _wait_gone(children, 5.0)
    assert not [p for p, t in children.items() if _alive(p, t)], "processes it started outlived their parent by 5 s"


@pytest.mark.parametrize("how", ["script", "stdin"])
def test_a_script_without_a_main_guard_builds_in_parallel(how, tmp_path):
    """The builders are spawned without re-running the caller's main script: a script that builds
    a family at top level (no ``if __name__ == "__main__"``) would otherwise run again in every
    builder and wait there for the cache lock its parent holds; ``python - < script`` has no file
    to re-run at all."""
    script = tmp_path / "build.py"
    script.write_text(f"from daa_sil import waitmap\n"
                      f"fam = waitmap.default_family('paper', grid={SMALL!r}, workers=2)\n"
                      f"print(len(fam.maps))\n")
    env = dict(os.environ, DAA_SIL_CACHE=str(tmp_path / "cache"))
    argv = [sys.executable, str(script)] if how == "script" else [sys.executable, "-"]
    stdin = None if how == "script" else open(script)
    try:
        res = subprocess.run(argv, stdin=stdin, capture_output=True, text=True, env=env, timeout=120)
    finally:
        if stdin is not None:
            stdin.close()
    assert res.returncode == 0 and res.stdout.strip() == "5", res.stderr[-2000:]
