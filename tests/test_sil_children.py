"""No orphans (issue 20 §2): every process ``daa-sil run`` starts dies with it, has a name a user can
find, and SIGTERM / SIGHUP stop a run as Ctrl-C does.

* the driver killed with SIGKILL mid-run (lockstep and realtime; with ``PR_SET_PDEATHSIG`` and with
  the portable parent-polling fallback forced by ``DAA_SIL_PARENT_WATCH=poll``): no vehicle, shim
  or GCS is alive 5 s later, and the vehicle still wrote the steps it flew;
* SIGTERM (``timeout``, a CI cancel) and SIGHUP (a closed terminal): exit 128 + signal, one line
  saying what was cut short and that the expectation was not checked, every child gone, the
  partial step log and ``result.json`` (``interrupted_by``) written;
* the children are called ``daa-vehicle``, ``daa-shim`` and ``daa-gcs`` (``pgrep daa-gcs`` finds
  the run's GCS), the recorder helper ``daa-recorder``;
* the progress line of a realtime run says what the step log says, at a bounded rate; ``--quiet``
  silences it;
* the helper itself: names cut to 15 bytes, a child whose parent is gone exits, and children are
  started from the main thread only.

Bounded: every wait has a deadline; processes are found by pid (children of the driver) and
killed in ``finally`` blocks.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from daa_sil.steplog import read_steplog, steplog_metadata
from sil_helpers import wait_for_vehicle_time

ROOT = Path(__file__).resolve().parents[1]
HEAD_ON = ROOT / "scenarios" / "head_on.yaml"
RUN = [sys.executable, "-m", "daa_sil.cli", "run"]
WAIT_S = 120.0  # bound on each wait, so a hang fails instead of blocking CI
ORPHAN_DEADLINE_S = 5.0  # the bound: no child alive 5 s after the driver died
NAMES = {"vehicle": "daa-vehicle", "shim": "daa-shim", "gcs": "daa-gcs"}
WATCH_ENV = "DAA_SIL_PARENT_WATCH"  # daa_sil.sil.children.WATCH_ENV (spelled out: the defect tests run on bba2fd8)

pytestmark = pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="needs Linux /proc")


def _comm(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/comm").read_text().strip()
    except OSError:
        return ""


def _alive(pid: int, started: float) -> bool:
    """``pid`` runs (not a zombie) and is the process we saw (same start time, so not a reused pid)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return False
    return fields[0] != "Z" and float(fields[19]) == started


def _start_time(pid: int) -> float:
    return float(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[19])


def _children_of(pid: int) -> dict[int, float]:
    """Direct children of ``pid`` -> their start times."""
    out: dict[int, float] = {}
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            for c in (task / "children").read_text().split():
                out[int(c)] = _start_time(int(c))
        except (OSError, IndexError):
            continue
    return out


def _role(pid: int) -> str:
    cmd = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
    # daa-sil run starts its shim as python -m daa_sil.commands.shim (daa-sil shim by hand)
    shim = " shim " in cmd or "-m daa_sil.commands.shim" in cmd
    return "shim" if shim else "gcs" if "-m gcs" in cmd else "vehicle" if "-m vehicle" in cmd else cmd


def _wait_gone(pids: dict[int, float], deadline_s: float) -> dict[int, float]:
    """Poll until none of ``pids`` is alive or ``deadline_s`` passed; the ones still alive."""
    end = time.monotonic() + deadline_s
    while time.monotonic() < end:
        alive = {p: s for p, s in pids.items() if _alive(p, s)}
        if not alive:
            return {}
        time.sleep(0.05)
    return {p: s for p, s in pids.items() if _alive(p, s)}


def _start_run(out: Path, clock: str, env_extra: "dict | None" = None, *extra: str) -> subprocess.Popen:
    env = dict(os.environ, **(env_extra or {}))
    clock_args = ["--clock", clock] + (["--speed", "10"] if clock == "realtime" else [])
    return subprocess.Popen(RUN + [str(HEAD_ON), "--out", str(out), *clock_args, *extra], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, cwd=ROOT, env=env, start_new_session=True)


def _running_children(proc: subprocess.Popen, out: Path, t_s: int) -> dict[int, float]:
    """Once the vehicle flew ``t_s`` s: the driver's three SIL children (pid -> start time)."""
    wait_for_vehicle_time(out, t_s, proc, WAIT_S)
    kids = {p: s for p, s in _children_of(proc.pid).items() if _role(p) in NAMES}
    assert sorted(_role(p) for p in kids) == ["gcs", "shim", "vehicle"], {p: _role(p) for p in kids}
    return kids


def _cleanup(proc: subprocess.Popen, kids: dict[int, float]) -> None:
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    for p, s in kids.items():  # never leave anything behind, even if the test fails
        if _alive(p, s):
            os.kill(p, signal.SIGKILL)


def _check_partial_steplog(out: Path, t_min: int) -> int:
    """The vehicle wrote the steps it flew (0..n-1, contiguous, marked incomplete); returns n."""
    table = read_steplog(out / "steplog.parquet")
    n = table.num_rows
    assert t_min <= n < 180
    assert table.column("step").to_pylist() == list(range(n))
    assert steplog_metadata(out / "steplog.parquet")["complete"] == "false"
    return n


# ------------------------------------------------------------------------------------------------
# SIGKILL of the driver

@pytest.mark.parametrize("clock, watch", [("lockstep", "prctl"), ("realtime", "prctl"), ("realtime", "poll")])
def test_sigkill_of_the_driver_leaves_no_child_alive(tmp_path, clock, watch):
    """The issue's case: ``kill -9`` of ``daa-sil run`` left the shim running indefinitely (and, in
    lockstep, the GCS 60 s and more). Now each child gets SIGTERM when the driver dies (the kernel's
    ``PR_SET_PDEATHSIG``, or the child's own watch of its parent where that is not available) and
    is gone within 5 s, having written what it had (the vehicle's step log)."""
    out = tmp_path / "run"
    proc = _start_run(out, clock, {WATCH_ENV: watch})
    kids: dict[int, float] = {}
    try:
        kids = _running_children(proc, out, 20)
        os.kill(proc.pid, signal.SIGKILL)  # the driver only: its children are in their own sessions
        proc.wait(timeout=WAIT_S)
        t_kill = time.monotonic()
        left = _wait_gone(kids, ORPHAN_DEADLINE_S)
        gone_after = time.monotonic() - t_kill
    finally:
        _cleanup(proc, kids)
    assert left == {}, f"alive {ORPHAN_DEADLINE_S} s after SIGKILL: {[_comm(p) for p in left]}"
    n = _check_partial_steplog(out, 20)
    print(f"\nSIGKILL ({clock}, {watch}): vehicle, shim, GCS gone {gone_after:.2f} s after the driver died; "
          f"step log {n} steps")


# ------------------------------------------------------------------------------------------------
# SIGTERM and SIGHUP behave like Ctrl-C

@pytest.mark.parametrize("sig, clock, extra", [(signal.SIGTERM, "lockstep", ("--quiet",)),
                                               (signal.SIGHUP, "realtime", ())],
                         ids=["SIGTERM-lockstep-quiet", "SIGHUP-realtime"])
def test_sigterm_and_sighup_stop_the_run_like_ctrl_c(tmp_path, sig, clock, extra):
    out = tmp_path / "run"
    proc = _start_run(out, clock, None, *extra)
    kids: dict[int, float] = {}
    try:
        # realtime at 10x: 80 s of sim time is 8 s of play, so progress lines (every >= 5 s) came
        kids = _running_children(proc, out, 80 if clock == "realtime" else 20)
        t_sig = time.monotonic()
        os.kill(proc.pid, sig)
        _, err = proc.communicate(timeout=WAIT_S)
        stopped_s = time.monotonic() - t_sig
        left = _wait_gone(kids, ORPHAN_DEADLINE_S)
    finally:
        _cleanup(proc, kids)
    name = signal.Signals(sig).name
    assert proc.returncode == 128 + sig, err
    assert left == {}, f"alive after {name}: {left}"
    assert "Traceback" not in err, err
    last = err.strip().splitlines()[-1]
    assert re.fullmatch(rf"daa-sil: interrupted by {name} at t = \d+ s of 180 s; the expected outcome was not "
                        rf"checked; \d+ steps in .*steplog\.parquet, summary in .*result\.json", last), last
    n = _check_partial_steplog(out, 20)
    res = json.loads((out / "result.json").read_text())
    assert res["interrupted"] is True and res["interrupted_by"] == name and res["steps"] == n
    assert res["expectation"]["checked"] is False and res["expectation"]["ok"] is None
    assert res["expectation"]["reason"] == f"interrupted by {name} at t = {n} s of 180 s"
    progress = [x for x in err.splitlines() if re.match(r"daa-sil: t = \d+ s of 180 s", x)]
    if "--quiet" in extra:
        assert progress == [] and "playing" not in err, err
    else:
        _check_progress_lines(progress, out)
    print(f"\n{name} ({clock}): exit {proc.returncode} {stopped_s:.2f} s after the signal, children gone, "
          f"step log {n} steps, progress lines {len(progress)}; {last}")


def _check_progress_lines(lines: list[str], out: Path) -> None:
    """Each progress line says what the step log says at its sim time (authority, decision, range)."""
    assert lines, "no progress line in a realtime run of 8 s and more"
    rows = {r["t"]: r for r in read_steplog(out / "steplog.parquet").to_pylist()}
    for line in lines:
        m = re.fullmatch(r"daa-sil: t = (\d+) s of 180 s: authority (\S+), decision (\S+), nearest intruder "
                         r"(\d+) m", line)
        assert m, line
        r = rows[float(m.group(1))]
        assert (m.group(2), m.group(3)) == (r["authority"], r["decision"]), (line, r["authority"], r["decision"])
        assert int(m.group(4)) == round(min(r["range_m"])), (line, min(r["range_m"]))
    times = [int(re.search(r"t = (\d+)", x).group(1)) for x in lines]
    assert times == sorted(set(times))


# ------------------------------------------------------------------------------------------------
# names

def test_children_have_names_a_user_can_find(tmp_path):
    """``ps``/``pgrep`` show ``daa-vehicle``, ``daa-shim``, ``daa-gcs`` (was: ``python3`` for all three),
    and ``daa-recorder`` for the Rerun recorder helper of ``--rrd``."""
    out = tmp_path / "run"
    proc = _start_run(out, "realtime", None, "--rrd", str(tmp_path / "run.rrd"))
    kids: dict[int, float] = {}
    try:
        wait_for_vehicle_time(out, 10, proc, WAIT_S)
        kids = _children_of(proc.pid)
        names = {_comm(p): p for p in kids}
        roles = {name: _role(p) for name, p in names.items()}
        found = subprocess.run(["pgrep", "-x", "daa-gcs"], capture_output=True, text=True).stdout.split()
        os.kill(proc.pid, signal.SIGINT)
        proc.communicate(timeout=WAIT_S)
        left = _wait_gone(kids, ORPHAN_DEADLINE_S)
    finally:
        _cleanup(proc, kids)
    assert set(names) == {"daa-vehicle", "daa-shim", "daa-gcs", "daa-recorder"}, names
    assert {roles[name]: name for name in NAMES.values()} == NAMES
    assert str(names["daa-gcs"]) in found, (found, names)
    assert left == {}


# ------------------------------------------------------------------------------------------------
# the helper

def test_process_name_is_cut_to_the_kernel_limit():
    code = ("from daa_sil.sil.children import set_process_name; import sys; "
            "ok = set_process_name('daa-a-very-long-process-name'); "
            "print(ok, open('/proc/self/comm').read().strip())")
    got = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60).stdout.split()
    assert got == ["True", "daa-a-very-long"]  # 15 bytes


@pytest.mark.parametrize("watch", ["prctl", "poll"])
def test_a_spawned_python_child_is_named_and_dies_with_its_parent(tmp_path, watch):
    """A middle process spawns a Python child (``adopt`` in it) and is SIGKILLed: the child, named by
    ``spawn``, gets SIGTERM and runs its handler (it writes a file), in both watch modes."""
    flag = tmp_path / "child-got-sigterm"
    child_code = ("import signal, sys, time, pathlib\n"
                  "from daa_sil.sil.children import adopt\n"
                  "adopt()\n"
                  f"signal.signal(signal.SIGTERM, lambda s, f: (pathlib.Path({str(flag)!r}).write_text('x'), "
                  "sys.exit(0)))\n"
                  "print(open('/proc/self/comm').read().strip(), flush=True)\n"
                  "time.sleep(120)\n")
    middle_code = ("import subprocess, sys, time\n"
                   "from daa_sil.sil.children import spawn\n"
                   f"p = spawn([sys.executable, '-c', {child_code!r}], 'daa-test-kid', start_new_session=True)\n"
                   "print(p.pid, flush=True)\n"
                   "time.sleep(120)\n")
    middle = subprocess.Popen([sys.executable, "-c", middle_code], stdout=subprocess.PIPE, text=True,
                              env=dict(os.environ, **{WATCH_ENV: watch}), start_new_session=True)
    kid = None
    try:
        kid = int(middle.stdout.readline())
        started = _start_time(kid)
        name = middle.stdout.readline().strip()  # the child prints its name once adopt() ran
        os.kill(middle.pid, signal.SIGKILL)
        middle.wait(timeout=WAIT_S)
        left = _wait_gone({kid: started}, ORPHAN_DEADLINE_S)
    finally:
        if middle.poll() is None:
            middle.kill()
        if kid is not None:
            try:
                os.kill(kid, signal.SIGKILL)
            except ProcessLookupError:
                pass
    assert name == "daa-test-kid"
    assert left == {} and flag.read_text() == "x"


def test_spawn_refuses_a_thread_other_than_main():
    """PR_SET_PDEATHSIG fires when the forking *thread* exits: a child started from a worker thread
    would be killed when that thread ends, so spawn() refuses."""
    from daa_sil.sil import children

    got: list = []

    def worker():
        try:
            children.spawn([sys.executable, "-c", "pass"], "x")
        except RuntimeError as exc:
            got.append(str(exc))

    t = threading.Thread(target=worker)
    t.start()
    t.join(30)
    assert got and "main thread" in got[0]


def test_a_binary_child_in_poll_mode_runs_under_a_watchdog(tmp_path):
    """Where the kernel cannot signal it, a non-Python child (the rerun binary) is started under
    ``python -m daa_sil.sil.children watch``: when the parent dies, the watchdog stops it."""
    middle_code = ("import time\n"
                   "from daa_sil.sil.children import spawn\n"
                   "p = spawn(['sleep', '120'], 'sleeper', start_new_session=True)\n"
                   "print(p.pid, flush=True)\n"
                   "time.sleep(120)\n")
    middle = subprocess.Popen([sys.executable, "-c", middle_code], stdout=subprocess.PIPE, text=True,
                              env=dict(os.environ, **{WATCH_ENV: "poll"}), start_new_session=True)
    procs: dict[int, float] = {}
    try:
        watchdog = int(middle.stdout.readline())
        end = time.monotonic() + WAIT_S
        while time.monotonic() < end and not _children_of(watchdog):
            time.sleep(0.05)
        procs = {watchdog: _start_time(watchdog), **_children_of(watchdog)}
        comms = sorted(_comm(p) for p in procs)
        os.kill(middle.pid, signal.SIGKILL)
        middle.wait(timeout=WAIT_S)
        left = _wait_gone(procs, ORPHAN_DEADLINE_S)
    finally:
        if middle.poll() is None:
            middle.kill()
        for p in procs:
            try:
                os.kill(p, signal.SIGKILL)
            except ProcessLookupError:
                pass
    assert comms == ["sleep", "sleeper-watch"]
    assert left == {}


@pytest.mark.slow  # starts compiling a cold kernel cache (killed after its helper appears, ~10 s)
@pytest.mark.skipif((os.cpu_count() or 1) < 2, reason="the helper runs on two cores or more")
def test_the_kernel_compile_helper_dies_with_its_parent(tmp_path):
    """A cold kernel cache is compiled with a helper process (daa_sil.daa.kernels.compile_part), named
    ``daa-kernels``; SIGKILL of the process that started it takes the helper too."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba"))
    parent = subprocess.Popen([sys.executable, "-m", "daa_sil.daa.kernels"], env=env, stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL)
    helpers: dict[int, float] = {}
    try:
        end = time.monotonic() + WAIT_S
        while not helpers and time.monotonic() < end and parent.poll() is None:
            helpers = {p: s for p, s in _children_of(parent.pid).items() if _comm(p) == "daa-kernels"}
            time.sleep(0.05)
        assert helpers, "no daa-kernels helper started"
        parent.kill()
        parent.wait(timeout=WAIT_S)
        assert _wait_gone(helpers, ORPHAN_DEADLINE_S) == {}
    finally:
        if parent.poll() is None:
            parent.kill()
            parent.wait()
        for pid, started in helpers.items():  # (only if the test failed: a helper left compiling into tmp_path)
            if _alive(pid, started):
                os.kill(pid, signal.SIGKILL)
