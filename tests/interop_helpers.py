"""Shared helpers for the interop tests: a real ``daa-vehicle`` process on loopback, bounded waits."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def free_ports(n: int) -> list[int]:
    """``n`` distinct OS-chosen free UDP ports on 127.0.0.1."""
    from daa_sil.sil.supervise import free_udp_ports

    return free_udp_ports(n)


def start(args: list, log: Path, **kw) -> subprocess.Popen:
    """Start ``python -m ARGS`` in its own process group with stdout+stderr to ``log``."""
    fh = open(log, "w")
    return subprocess.Popen([sys.executable, "-m", *map(str, args)], stdout=fh, stderr=subprocess.STDOUT, text=True,
                            cwd=ROOT, start_new_session=True, **kw)


def stop(proc: subprocess.Popen, sig=signal.SIGINT, timeout: float = 15.0) -> int:
    """Signal ``proc``'s process group, wait, escalate to SIGKILL; returns the exit code."""
    if proc.poll() is None:
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            pass
        try:
            proc.wait(timeout)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(10)
    return proc.returncode


def wait_for_text(path: Path, text: str, timeout: float, proc: "subprocess.Popen | None" = None) -> str:
    """Wait until file ``path`` contains ``text`` (bounded); returns the file's content. Raises AssertionError."""
    end = time.monotonic() + timeout
    content = ""
    while time.monotonic() < end:
        content = path.read_text() if path.exists() else ""
        if text in content:
            return content
        if proc is not None and proc.poll() is not None:
            break
        time.sleep(0.05)
    raise AssertionError(f"{text!r} not in {path.name} within {timeout} s; it holds:\n{content[-3000:]}")


def recv_until(conn, pred, timeout: float) -> list:
    """Messages from a mavutil connection until ``pred(msg)`` is true (inclusive) or ``timeout`` s."""
    out, end = [], time.monotonic() + timeout
    while time.monotonic() < end:
        m = conn.recv_match(blocking=True, timeout=0.1)
        if m is None or m.get_type() == "BAD_DATA":
            continue
        out.append(m)
        if pred(m):
            return out
    return out


def corrective_reading(tmp: Path) -> list:
    """``--config`` arguments that make a vehicle fly the ``extended`` reading (the agent decides from the
    corrective alert, the alerting-region maps): the interop tests check the MAVLink protocol with a stock
    ground station that sends no pilot commands, which under the default reading (``paper``: the agent
    decides from the start of the encounter) would leave the agent waiting (CRUISE) from t = 0."""
    path = Path(tmp) / "extended.yaml"
    path.write_text("reading: {name: extended}\n")
    return ["--config", str(path)]
