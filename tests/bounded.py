"""Running a command that may allocate or spawn too much, so that it can never take the machine:
its own session (every process it starts can be signalled and killed as a group), an address-space
limit (``RLIMIT_AS``), a CPU-time limit, a bounded wait, and a teardown that kills whatever is left.

``RLIMIT_NPROC`` is set too, but the kernel does not enforce it for root; tests that could start
processes without bound (``--workers 1000``) therefore stop the pool before it starts (a fake
``ProcessPoolExecutor``), never by the limit alone.
"""

from __future__ import annotations

import os
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import psutil

ROOT = Path(__file__).resolve().parents[1]
#: address space of each process of a bounded command (numba reserves ~1 GB of it at start-up)
MEM_LIMIT = 3 * 2**30
#: CPU seconds of each process of a bounded command
CPU_LIMIT_S = 600
#: processes of the user (not enforced for root; see the module docstring)
NPROC_LIMIT = 4096


def limits(mem: int = MEM_LIMIT, cpu_s: int = CPU_LIMIT_S, drop_dac: bool = False):
    """A ``preexec_fn``: the limits above; ``drop_dac``: no CAP_DAC_OVERRIDE / CAP_DAC_READ_SEARCH
    from here on (a root process then obeys file modes, so a 0555 directory is read-only to it)."""

    def pre() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (mem, mem))
        resource.setrlimit(resource.RLIMIT_CPU, (cpu_s, cpu_s))
        try:
            resource.setrlimit(resource.RLIMIT_NPROC, (NPROC_LIMIT, NPROC_LIMIT))
        except (ValueError, OSError):
            pass
        if drop_dac:
            import ctypes

            libc = ctypes.CDLL(None, use_errno=True)
            for cap in (1, 2):  # CAP_DAC_OVERRIDE, CAP_DAC_READ_SEARCH
                if libc.prctl(24, cap, 0, 0, 0) != 0:  # PR_CAPBSET_DROP
                    os._exit(97)

    return pre


def cli_argv(*args) -> list[str]:
    """``python -m daa_sil.cli ARGS`` with this interpreter."""
    return [sys.executable, "-m", "daa_sil.cli", *map(str, args)]


def start(argv: list, cwd: Path, env: "dict | None" = None, drop_dac: bool = False, mem: int = MEM_LIMIT,
          stdout=subprocess.PIPE) -> subprocess.Popen:
    """Start ``argv`` bounded (module docstring) in its own session."""
    return subprocess.Popen([str(a) for a in argv], cwd=cwd, env={**os.environ, **(env or {})}, stdout=stdout,
                            stderr=subprocess.PIPE, text=True, start_new_session=True,
                            preexec_fn=limits(mem=mem, drop_dac=drop_dac))


def run(argv: list, cwd: Path, timeout: float = 300.0, **kw) -> subprocess.CompletedProcess:
    """Run ``argv`` bounded; kill its whole session if it has not ended after ``timeout`` s (then the
    result's ``returncode`` is ``None``)."""
    proc = start(argv, cwd, **kw)
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        kill_session(proc)
        out, err = proc.communicate()
        return subprocess.CompletedProcess(proc.args, None, out, err)
    return subprocess.CompletedProcess(proc.args, proc.returncode, out, err)


def descendants(pid: int) -> list[psutil.Process]:
    try:
        return psutil.Process(pid).children(recursive=True)
    except psutil.NoSuchProcess:
        return []


def alive(procs) -> list[psutil.Process]:
    """The processes of ``procs`` still running (zombies count as gone)."""
    out = []
    for p in procs:
        try:
            if p.is_running() and p.status() != psutil.STATUS_ZOMBIE:
                out.append(p)
        except psutil.NoSuchProcess:
            pass
    return out


def wait_gone(procs, timeout: float) -> list[psutil.Process]:
    """Wait up to ``timeout`` s for ``procs`` to end; the ones still alive."""
    end = time.monotonic() + timeout
    left = alive(procs)
    while left and time.monotonic() < end:
        time.sleep(0.05)
        left = alive(left)
    return left


def kill_session(proc: subprocess.Popen, extra=()) -> None:
    """SIGKILL ``proc``'s session and every process in ``extra`` (teardown: nothing survives a test)."""
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass
    for p in alive(extra):
        try:
            p.kill()
        except psutil.NoSuchProcess:
            pass


def one_error_line(err: str, *needles: str) -> str:
    """The single line of ``err`` (asserting there is exactly one, with no traceback) after checking it
    holds every needle."""
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert "Traceback" not in err, err
    assert len(lines) == 1, err
    for n in needles:
        assert n in lines[0], (n, lines[0])
    return lines[0]
