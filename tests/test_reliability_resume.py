"""No data lost (issue 9 §5a): a campaign killed with SIGKILL and resumed with ``--resume`` ends with
files byte-identical to an uninterrupted run.

Kills land (1) at chosen points inside the writer (driven by a small wrapper that SIGKILLs the
process from within: after the encounter set but before ``campaign.json``, with half a chunk file in
its temporary, between a chunk's two files, between its tables and its checksum file, and just
before the final status) and (2) at seeded
random times. After the last resume every file under the campaign directory -- the encounter set,
every chunk's Parquet tables, ``campaign.json`` -- must equal the uninterrupted run's byte for
byte, and so must the merged tables the report reads.
"""

from __future__ import annotations

import io
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from daa_sil.study.campaign.files import read_results
from daa_sil.cli import main

#: wraps ``daa-sil``; argv[1] names the point at which the process SIGKILLs itself
DRIVER = r"""
import os, signal, sys
from pathlib import Path
point, argv = sys.argv[1], sys.argv[2:]
import pyarrow.parquet as pq
import daa_sil.study.campaign.run as camp

def die():
    os.kill(os.getpid(), signal.SIGKILL)

if point in ("before-campaign-json", "before-complete"):
    real_json = camp.atomic_write_json
    def write_json(path, obj, **kw):
        if Path(path).name == "campaign.json" and (point == "before-campaign-json" or obj.get("status") == "complete"):
            die()
        return real_json(path, obj, **kw)
    camp.atomic_write_json = write_json
elif point == "mid-chunk-write":
    real_write = Path.write_bytes
    def write_bytes(self, data):
        if self.name.startswith(".decisions-"):  # the chunk writer's temporary
            real_write(self, data[: len(data) // 2])  # half of the file is on disk ...
            die()                                     # ... when the process dies
        return real_write(self, data)
    Path.write_bytes = write_bytes
elif point == "between-chunk-files":
    real_replace = os.replace
    def replace(src, dst):
        real_replace(src, dst)
        if Path(dst).name.startswith("decisions-"):
            die()
    os.replace = replace
elif point == "before-checksums":
    real_replace = os.replace
    def replace(src, dst):
        if Path(dst).name.startswith("chunk-"):
            die()
        real_replace(src, dst)
    os.replace = replace
elif point != "none":
    raise SystemExit(f"unknown point {point}")
from daa_sil.cli import main
sys.exit(main(argv))
"""

LIMIT_S = 300.0  # bound on any one process, so a hang fails instead of blocking CI


def _argv(out: Path, groups: str, n: int, chunk: int, duration: "float | None", seed: int = 3) -> list[str]:
    argv = ["campaign", "run", "--groups", groups, "--encounters", str(n), "--chunk-size", str(chunk),
            "--seed", str(seed), "--out", str(out), "--no-progress"]
    return argv + (["--duration", f"{duration:g}"] if duration else [])


def _start(point: str, argv: list[str]) -> subprocess.Popen:
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    return subprocess.Popen([sys.executable, "-c", DRIVER, point, *argv], stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True, env=env, start_new_session=True)


def _wait(proc: subprocess.Popen) -> int:
    try:
        proc.wait(timeout=LIMIT_S)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    return proc.returncode


def snapshot(d: Path) -> dict:
    return {str(p.relative_to(d)): p.read_bytes() for p in sorted(d.rglob("*")) if p.is_file()}


def _chunks_done(d: Path) -> int:
    return len(list(d.rglob("chunk-*.sha256")))  # the checksum file is written last


def _merged_bytes(d: Path, kind: str) -> bytes:
    buf = io.BytesIO()
    pq.write_table(read_results(d, kind), buf, compression="zstd")
    return buf.getvalue()


def _kill_resume_cycle(tmp_path: Path, groups: str, n: int, chunk: int, duration: "float | None",
                       n_random: int, seed: int) -> dict:
    """Run the scripted kill points, then ``n_random`` seeded random-time kills, then a final resume;
    compare with an uninterrupted run. Returns the figures (kills, chunks recomputed, ...)."""
    killed, ref = tmp_path / "killed", tmp_path / "reference"
    n_chunks = len(groups.split(",")) * -(-n // chunk)
    figures = {"scripted_kills": 0, "random_kills": 0, "random_finished_first": 0, "resumes": 0}

    # 1. scripted points, each on the directory the previous one left behind
    argv = _argv(killed, groups, n, chunk, duration)
    assert _wait(_start("before-campaign-json", argv)) == -signal.SIGKILL
    assert (killed / "encounters.parquet").is_file() and not (killed / "campaign.json").exists()
    figures["scripted_kills"] += 1
    for point in ("mid-chunk-write", "between-chunk-files", "before-checksums"):
        before = _chunks_done(killed)
        assert _wait(_start(point, argv + ["--resume"])) == -signal.SIGKILL, point
        figures["scripted_kills"] += 1
        figures["resumes"] += 1
        if point == "mid-chunk-write":  # the half-written temporary is there, never a final file
            tmps = [p for p in killed.rglob(".decisions-*.tmp")]
            assert len(tmps) == 1 and tmps[0].stat().st_size > 0
        elif point == "between-chunk-files":  # a chunk with its decisions file but not its encounters file
            assert len(list(killed.rglob("decisions-*.parquet"))) == _chunks_done(killed) + 1
        else:  # a chunk with both tables but no checksum file (= not done)
            assert len(list(killed.rglob("encounters-*.parquet"))) == _chunks_done(killed) + 1
        assert _chunks_done(killed) == before

    # 2. seeded random kill times
    rng = np.random.default_rng(seed)
    for _ in range(n_random):
        before = _chunks_done(killed)
        proc = _start("none", argv + ["--resume"])
        figures["resumes"] += 1
        # the random instant is counted from the first chunk this process completes, so it lands
        # while chunks are being computed and written, not during interpreter start-up
        end = time.monotonic() + LIMIT_S
        while _chunks_done(killed) == before and proc.poll() is None and time.monotonic() < end:
            time.sleep(0.01)
        deadline = time.monotonic() + float(rng.uniform(0.0, 1.0))
        while time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.01)
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            figures["random_kills"] += 1
        else:
            figures["random_finished_first"] += 1
        _wait(proc)

    # 3. the status write itself, on a directory of its own: a random kill above may come after the
    #    run finished the campaign (more likely the faster the simulation), whose status is then written
    at_status = tmp_path / "killed-at-status"
    proc = _start("before-complete", _argv(at_status, groups, n, chunk, duration))
    assert _wait(proc) == -signal.SIGKILL
    figures["scripted_kills"] += 1
    assert _chunks_done(at_status) == n_chunks
    assert b'"status": "running"' in (at_status / "campaign.json").read_bytes()
    proc = _start("none", ["campaign", "run", "--out", str(at_status), "--resume", "--no-progress"])
    figures["resumes"] += 1
    assert _wait(proc) == 0, proc.stderr.read()

    # 4. the last resume: only --out and --resume (the stored settings are used)
    proc = _start("none", ["campaign", "run", "--out", str(killed), "--resume", "--no-progress"])
    figures["resumes"] += 1
    assert _wait(proc) == 0, proc.stderr.read()

    # the uninterrupted run, same options
    rc = main(_argv(ref, groups, n, chunk, duration))
    assert rc == 0
    b = snapshot(ref)
    for d in (killed, at_status):
        a = snapshot(d)
        assert sorted(a) == sorted(b)  # same files (no temporary left behind) ...
        for name in b:
            assert a[name] == b[name], f"{d.name}: {name} differs after kill + resume"  # ... byte for byte
    for kind in ("encounters", "decisions"):
        assert _merged_bytes(killed, kind) == _merged_bytes(ref, kind)
    enc = read_results(ref, "encounters")
    assert enc.num_rows == len(groups.split(",")) * n
    figures.update(chunks=n_chunks, files_compared=len(b), encounter_rows=enc.num_rows,
                   decision_rows=read_results(ref, "decisions").num_rows)
    print(f"\nkill/resume figures: {figures}")
    return figures


def test_sigkill_at_scripted_and_random_points_then_resume_is_byte_identical(tmp_path):
    f = _kill_resume_cycle(tmp_path, "B-2,ID-2", n=16, chunk=4, duration=120.0, n_random=2, seed=2024)
    assert f["scripted_kills"] == 5 and f["random_kills"] + f["random_finished_first"] == 2
    assert f["chunks"] == 8 and f["files_compared"] == 2 + 3 * 8  # two tables and a checksum file per chunk
    assert f["decision_rows"] > 0


@pytest.mark.slow
def test_paper_length_campaign_killed_many_times(tmp_path):
    """2 groups x 60 encounters of the paper's 240 s, 20 chunks, 6 random kills."""
    f = _kill_resume_cycle(tmp_path, "B-2,ID-2", n=60, chunk=6, duration=None, n_random=6, seed=7)
    assert f["chunks"] == 20 and f["random_kills"] >= 3 and f["encounter_rows"] == 120


def test_resume_recomputes_a_damaged_chunk_and_clears_stale_temporaries(tmp_path):
    out = tmp_path / "c"
    argv = _argv(out, "B-1", 6, 3, 30.0)
    assert main(argv) == 0
    ref = snapshot(out)
    chunk = out / "B-1" / "encounters-00001.parquet"
    chunk.write_bytes(chunk.read_bytes()[:200])  # damaged outside our control
    stale = out / "B-1" / ".decisions-00000.parquet.abc123.tmp"
    stale.write_bytes(b"left by a killed writer")
    assert main(argv + ["--resume", "--json"]) == 0
    assert snapshot(out) == ref  # the chunk is back, byte for byte, and the temporary is gone


def _console(name: str) -> str:
    """The installed console script ``name`` next to this interpreter (what a user runs)."""
    path = Path(sys.executable).parent / name
    assert path.is_file(), f"{path} is not installed (pip install -e .)"
    return str(path)


def _zero_64_bytes(path: Path, silent: bool) -> int:
    """Zero 64 bytes of ``path``'s body (between the 4-byte magic and the footer); with ``silent``
    at the first offset where the file still reads as Parquet but with other values, otherwise at
    the first offset where it no longer reads. Returns the offset."""
    data = path.read_bytes()
    body_end = len(data) - 8 - int.from_bytes(data[-8:-4], "little")
    good = pq.read_table(io.BytesIO(data))
    for off in range(4, body_end - 64):
        bad = data[:off] + bytes(64) + data[off + 64:]
        if bad == data:
            continue
        try:
            table = pq.read_table(io.BytesIO(bad))
            reads, same = True, table.equals(good)
        except Exception:  # noqa: BLE001 -- any decoding error
            reads, same = False, False
        if (silent and reads and not same) or (not silent and not reads):
            path.write_bytes(bad)
            return off
    raise AssertionError(f"no offset in {path} gives that kind of damage")


def test_resume_recomputes_chunks_with_zeroed_bytes_and_names_them(tmp_path):
    """Issue 20 item 3: 64 zeroed bytes in a chunk's body used to pass the resume check (only the
    footer was read): "0 chunks run", and the report then failed, or, where the bytes still decode,
    read wrong numbers. Now each chunk is checked against its SHA-256 checksum file: the resume names
    a damaged chunk and computes it again (the directory ends byte-identical to the undamaged run),
    and the report refuses a damaged chunk with one line instead of reading it."""
    out = tmp_path / "c"
    argv = _argv(out, "B-1,B-2", 8, 4, 120.0)
    daa_sil = _console("daa-sil")
    env = dict(os.environ, PYTHONDONTWRITEBYTECODE="1")

    def run(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run([daa_sil, *args], capture_output=True, text=True, env=env, timeout=LIMIT_S)

    first = run(*argv)
    assert first.returncode == 0, first.stderr
    ref = snapshot(out)
    # one damage that still decodes (wrong values, no error) and one that does not decode
    _zero_64_bytes(out / "B-1" / "decisions-00000.parquet", silent=True)
    _zero_64_bytes(out / "B-2" / "encounters-00001.parquet", silent=False)

    resumed = run(*argv, "--resume")
    assert resumed.returncode == 0, resumed.stderr
    assert "2 chunks run (2 of them damaged on disk), 2 skipped" in resumed.stderr, resumed.stderr
    warnings = [ln for ln in resumed.stderr.splitlines() if ": warning: " in ln]
    assert len(warnings) == 2, resumed.stderr
    assert any("chunk 0 of group B-1" in w and "decisions-00000.parquet" in w for w in warnings), warnings
    assert any("chunk 1 of group B-2" in w and "encounters-00001.parquet" in w for w in warnings), warnings
    assert snapshot(out) == ref  # both chunks are back, byte for byte
    report = run("campaign", "report", str(out), "--out", str(tmp_path / "r"))
    assert report.returncode == 0, report.stderr

    # the report itself does not read a damaged chunk's numbers
    _zero_64_bytes(out / "B-1" / "decisions-00000.parquet", silent=True)
    report = run("campaign", "report", str(out), "--out", str(tmp_path / "r2"))
    assert report.returncode == 2, report.stderr
    (line,) = report.stderr.strip().splitlines()
    assert line.startswith("daa-sil: error: ") and "chunk 0 of group B-1" in line and "--resume" in line, line
    assert not (tmp_path / "r2").exists()
