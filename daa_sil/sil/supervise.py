"""Process supervision for ``daa-sil run``: children in their own process groups, readiness, a
monitor that notices a dead process within a poll interval and names it, and scheduled faults.

:class:`ProcessGroup` starts children (stdout+stderr to ``logs/<name>.log``, each in its own
session, through :func:`daa_sil.sil.children.spawn`: each dies with this process, even on SIGKILL,
and is called ``daa-<name>`` in ps/pgrep) and stops them all (SIGINT, SIGTERM, SIGKILL, each with a
timeout; also on Ctrl-C, SIGTERM and SIGHUP).
:class:`RunMonitor` waits for the vehicle to finish while polling every other child every
``POLL_S``: a shim or GCS that exits on its own stops the run at once, and the failure names it,
its exit status or signal, when it died (wall seconds into the play and the vehicle's sim time)
and its last output line -- so a dead shim is never blamed on the GCS, nor reported only when the
vehicle finishes. It also carries out a scenario's ``faults`` (kill the GCS at a vehicle sim time,
restart it on the same port), timing them from the vehicle's ``CLOCK t0_monotonic=...`` line
(``time.monotonic`` is one clock for every process on the machine).
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

from daa_sil.errors import DaaSilError
from daa_sil.sil.children import spawn
from daa_sil.runtime.spawned import signals_ignored
import socket

#: wall-clock limits (s)
READY_TIMEOUT_S = 60.0  # start-up guard: 20 runs starting together on 2 cores take a while
STOP_GRACE_S = 5.0
STOP_TERM_S = 3.0
#: how often the monitor looks at every child (s)
POLL_S = 0.1
#: output lines whose latest copy each child keeps (vehicle: clock start, progress)
WATCHED_PREFIXES = ("CLOCK ", "t=")


# --------------------------------------------------------------------------------------------
# process management

@dataclass
class Child:
    """One child process with its own process group and a log file."""

    name: str
    proc: subprocess.Popen
    log_path: Path
    ready: dict = field(default_factory=dict)
    ready_event: threading.Event = field(default_factory=threading.Event)
    reader: "threading.Thread | None" = None
    tail: list = field(default_factory=list)
    parser: "Callable[[str], dict | None]" = lambda line: None
    #: the latest output line starting with each of these prefixes (e.g. the vehicle's "CLOCK " / "t=")
    latest: dict = field(default_factory=dict)
    started: float = field(default_factory=time.monotonic)

    def alive(self) -> bool:
        return self.proc.poll() is None


class ProcessGroup:
    """Start children in their own process groups; :meth:`stop_all` leaves none behind.

    Use as a context manager: leaving the block (normally, by exception or by Ctrl-C) stops every
    child that is still running: SIGINT (lets the vehicle flush its step log), then SIGTERM, then
    SIGKILL, each after a timeout.
    """

    def __init__(self, log_dir: Path):
        self.log_dir = Path(log_dir)
        self.children: list[Child] = []

    def __enter__(self) -> "ProcessGroup":
        return self

    def __exit__(self, *exc) -> None:
        self.stop_all()

    def start(self, name: str, argv: Sequence[str], env: "dict | None" = None,
              ready_parser: "Callable[[str], dict | None] | None" = None,
              process_name: "str | None" = None) -> Child:
        """Start ``argv`` (stdin closed, stdout+stderr to ``logs/<name>.log``) with
        :func:`daa_sil.sil.children.spawn`: it dies with this process and is called ``process_name``
        (default ``daa-<name>``) in ps/pgrep.

        Readiness: the first output line for which ``ready_parser(line)`` returns a dict (default:
        a ``READY key=value ...`` line).
        """
        self.log_dir.mkdir(parents=True, exist_ok=True)
        log_path = self.log_dir / f"{name}.log"
        full_env = dict(os.environ)
        full_env["PYTHONUNBUFFERED"] = "1"
        full_env.update(env or {})
        proc = spawn(list(argv), process_name or f"daa-{name}", env=full_env, stdin=subprocess.DEVNULL,
                     stdout=subprocess.PIPE, stderr=subprocess.STDOUT, start_new_session=True,
                     text=True, errors="replace", bufsize=1)
        child = Child(name, proc, log_path, parser=ready_parser or parse_ready_line)
        child.reader = threading.Thread(target=self._pump, args=(child,), daemon=True, name=f"log-{name}")
        child.reader.start()
        self.children.append(child)
        return child

    @staticmethod
    def _pump(child: Child) -> None:
        with open(child.log_path, "w", encoding="utf-8") as log:
            for line in child.proc.stdout:  # type: ignore[union-attr]
                log.write(line)
                log.flush()
                child.tail = (child.tail + [line.rstrip()])[-20:]
                for prefix in WATCHED_PREFIXES:
                    if line.startswith(prefix):
                        child.latest[prefix] = line.rstrip()
                if not child.ready_event.is_set():
                    info = child.parser(line)
                    if info is not None:
                        child.ready = info
                        child.ready_event.set()
        child.ready_event.set()  # EOF: unblock waiters (the process died)

    def wait_ready(self, child: Child, timeout: float = READY_TIMEOUT_S) -> dict:
        """Block until ``child`` printed READY; raise DaaSilError if it died or timed out."""
        if not child.ready_event.wait(timeout):
            raise DaaSilError(f"{child.name} did not become ready within {timeout:g} s (log: {child.log_path})")
        if not child.ready:
            child.proc.wait(timeout=5)
            raise DaaSilError(f"{child.name} exited with status {child.proc.returncode} before it was ready: "
                              f"{last_error_line(child)} (log: {child.log_path})")
        return child.ready

    @staticmethod
    def _signal_group(child: Child, sig: int) -> None:
        try:
            os.killpg(child.proc.pid, sig)
        except (ProcessLookupError, PermissionError):
            pass

    def stop(self, child: Child, grace: float = STOP_GRACE_S, term: float = STOP_TERM_S) -> int:
        """Stop one child: SIGINT, wait ``grace``; SIGTERM, wait ``term``; SIGKILL. Returns its status."""
        for sig, wait in ((signal.SIGINT, grace), (signal.SIGTERM, term), (signal.SIGKILL, 5.0)):
            if child.proc.poll() is not None:
                break
            self._signal_group(child, sig)
            try:
                child.proc.wait(timeout=wait)
            except subprocess.TimeoutExpired:
                continue
        # the group may still hold grandchildren: make sure nothing survives
        self._signal_group(child, signal.SIGKILL)
        if child.reader is not None:
            child.reader.join(timeout=2.0)
        return child.proc.returncode if child.proc.returncode is not None else -9

    def stop_all(self) -> None:
        """Stop every child (last started first); Ctrl-C, SIGTERM and SIGHUP during this are ignored
        until done."""
        with signals_ignored():
            # escalate for all children together (SIGINT, SIGTERM, SIGKILL), so stopping takes one
            # grace period, not one per child
            for sig, wait in ((signal.SIGINT, STOP_GRACE_S), (signal.SIGTERM, STOP_TERM_S), (signal.SIGKILL, 5.0)):
                alive = [c for c in self.children if c.proc.poll() is None]
                if not alive:
                    break
                for c in alive:
                    self._signal_group(c, sig)
                end = time.monotonic() + wait
                for c in alive:
                    try:
                        c.proc.wait(timeout=max(0.0, end - time.monotonic()))
                    except subprocess.TimeoutExpired:
                        pass
            for child in self.children:
                self.stop(child)  # reaps, kills any leftover group member, joins the log reader


def parse_ready_line(line: str) -> "dict | None":
    """``READY key=value ...`` -> ``{key: value}``; None for any other line."""
    if not line.startswith("READY"):
        return None
    return dict(kv.split("=", 1) for kv in line.split()[1:] if "=" in kv) or {"ready": "1"}


_SHIM_READY = re.compile(r"vehicle side (udp:\S+?),? gcs side (udp:\S+?),")


def parse_shim_ready(line: str) -> "dict | None":
    """The ``daa-sil shim`` ready line (``... vehicle side udp:H:P, gcs side udp:H:P, ...``)."""
    m = _SHIM_READY.search(line)
    return {"vehicle_side": m.group(1), "gcs_side": m.group(2)} if m else None


def free_udp_ports(n: int) -> list[int]:
    """``n`` distinct UDP ports on 127.0.0.1 that were free a moment ago (bound together, then released)."""

    socks = []
    try:
        for _ in range(n):
            sk = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            sk.bind(("127.0.0.1", 0))
            socks.append(sk)
        return [sk.getsockname()[1] for sk in socks]
    finally:
        for sk in socks:
            sk.close()


def last_error_line(child: Child) -> str:
    """The most informative line of a child's output tail (an ``error:`` line if there is one)."""
    for line in reversed(child.tail):
        if "error" in line.lower():
            return line.strip()
    return child.tail[-1].strip() if child.tail else "(no output)"


def python_module_argv(module: str) -> list[str]:
    """``[python, -m, module]`` with the running interpreter (works before console scripts exist)."""
    return [sys.executable, "-m", module]


def describe_exit(child: Child) -> str:
    """``"exited with status 2"`` / ``"was killed by signal 9 (SIGKILL)"``."""
    rc = child.proc.returncode
    if rc is None:
        return "is still running"
    if rc < 0:
        try:
            name = signal.Signals(-rc).name
        except ValueError:
            name = f"signal {-rc}"
        return f"was killed by signal {-rc} ({name})"
    return f"exited with status {rc}"


_CLOCK = re.compile(r"^CLOCK t0_monotonic=([0-9.]+) speed=([0-9.eE+-]+)")
_PROGRESS = re.compile(r"^t=\s*([0-9.]+)s")


def vehicle_sim_time(vehicle: Child) -> "float | None":
    """The vehicle's sim time now (s): from its CLOCK line in realtime, else its last progress line."""
    m = _CLOCK.match(vehicle.latest.get("CLOCK ", ""))
    if m:
        return max(0.0, (time.monotonic() - float(m.group(1))) * float(m.group(2)))
    m = _PROGRESS.match(vehicle.latest.get("t=", ""))
    return float(m.group(1)) if m else None


@dataclass
class FaultRecord:
    """What became of one scheduled fault (sim times in s, from the vehicle's clock)."""

    fault: str
    process: str
    signal: str
    at_s: float
    restart_s: "float | None"
    killed_at_t_s: "float | None" = None
    restarted_at_t_s: "float | None" = None
    restart_ready_at_t_s: "float | None" = None
    restart_name: "str | None" = None
    executed: bool = False
    problem: "str | None" = None


class RunMonitor:
    """Wait for the vehicle; stop the run as soon as another child dies; carry out scheduled faults.

    ``children``: name -> Child of every process of the run except the vehicle. ``restart(fault,
    n)`` starts the ``n``-th replacement of ``fault.process`` and returns its Child. ``progress``
    (a :class:`daa_sil.sil.summary.ProgressLine`) gets the vehicle's latest progress line each poll.
    """

    def __init__(self, vehicle: Child, children: dict, faults=(), restart=None, poll_s: float = POLL_S,
                 progress=None):
        self.vehicle = vehicle
        self.progress = progress
        self.children = dict(children)
        self.poll_s = float(poll_s)
        self.restart = restart
        self.faults = [FaultRecord(f.describe(), f.process, f.signal, f.at_s, f.restart_s) for f in faults]
        self._fault_specs = list(faults)
        self._expected_dead: set = set()
        self._pending_ready: list = []
        self.t_play = time.monotonic()
        self.death: "dict | None" = None

    def wait(self) -> "str | None":
        """Block until the vehicle exits or another child dies; returns a failure line or None."""
        while True:
            rc = self.vehicle.proc.poll()
            if rc is not None:
                break
            failure = self._check_children()
            if failure:
                return failure
            self._run_faults()
            if self.progress is not None:
                self.progress.update(self.vehicle.latest.get("t="))
            try:  # like sleeping poll_s, but back within a few ms of the vehicle's exit
                self.vehicle.proc.wait(timeout=self.poll_s)
            except subprocess.TimeoutExpired:
                pass
        if rc != 0:
            return self._died(self.vehicle)
        # the vehicle finished: a child that died meanwhile is still a failure
        return self._check_children() or self._unexecuted()

    def _check_children(self) -> "str | None":
        for name, child in self.children.items():
            if child.alive() or name in self._expected_dead:
                continue
            return self._died(child)
        for child, rec in list(self._pending_ready):
            if child.ready_event.is_set() and child.ready:
                rec.restart_ready_at_t_s = _round(vehicle_sim_time(self.vehicle))
                self._pending_ready.remove((child, rec))
        return None

    def _died(self, child: Child) -> str:
        t = vehicle_sim_time(self.vehicle)
        wall = time.monotonic() - self.t_play
        self.death = {"process": child.name, "pid": child.proc.pid, "returncode": child.proc.returncode,
                      "wall_s": round(wall, 3), "vehicle_t_s": _round(t)}
        when = f"{wall:.1f} s into the run" + (f" (vehicle at t = {t:.0f} s)" if t is not None else "")
        said = [x.strip() for x in child.tail if "error" in x.lower() or "traceback" in x.lower()]
        return (f"the {child.name} (pid {child.proc.pid}) {describe_exit(child)} {when}"
                + (f": {said[-1]}" if said else "") + f" (log: {child.log_path})")

    def _run_faults(self) -> None:
        if not self.faults:
            return
        t = vehicle_sim_time(self.vehicle) if _CLOCK.match(self.vehicle.latest.get("CLOCK ", "")) else None
        if t is None:
            return
        for n, (rec, spec) in enumerate(zip(self.faults, self._fault_specs)):
            if rec.problem:
                continue
            if rec.killed_at_t_s is None and t >= spec.at_s:
                victim = self.children.get(rec.process)
                if victim is None or not victim.alive():
                    rec.problem = f"{rec.process} was not running at t = {t:.1f} s"
                    continue
                self._expected_dead.add(rec.process)
                try:
                    os.killpg(victim.proc.pid, getattr(signal, f"SIG{spec.signal}"))
                except (ProcessLookupError, PermissionError) as exc:
                    rec.problem = f"could not signal {rec.process}: {exc}"
                    continue
                rec.killed_at_t_s = _round(t)
                rec.executed = spec.restart_s is None
            elif (rec.killed_at_t_s is not None and spec.restart_s is not None and rec.restarted_at_t_s is None
                  and t >= spec.restart_s):
                old = self.children[rec.process]
                try:
                    old.proc.wait(timeout=2.0)
                except subprocess.TimeoutExpired:
                    rec.problem = f"{rec.process} did not die after SIG{spec.signal}"
                    continue
                child = self.restart(spec, n + 1)
                rec.restart_name = child.name
                self.children.pop(rec.process)
                self._expected_dead.discard(rec.process)
                self.children[rec.process] = child
                rec.restarted_at_t_s = _round(t)
                rec.executed = True
                self._pending_ready.append((child, rec))

    def _unexecuted(self) -> "str | None":
        bad = [f"{r.fault}: {r.problem or 'not carried out (the run ended first)'}" for r in self.faults
               if not r.executed or r.problem]
        return ("scheduled fault not carried out: " + "; ".join(bad)) if bad else None

    def fault_report(self) -> list:
        return [dict(r.__dict__) for r in self.faults]


def _round(x: "float | None", nd: int = 3) -> "float | None":
    return None if x is None else round(float(x), nd)
