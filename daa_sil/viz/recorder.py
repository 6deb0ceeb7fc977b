"""Record a SIL run to Rerun without slowing it: a helper process prepared while the run plays.

``daa-sil run --rrd FILE`` / ``--spawn-viewer`` use :class:`BackgroundRecorder`:

1. at launch, before the SIL processes start, the orchestrator forks the helper (``mode="fork"``:
   it inherits the already imported numpy/pyarrow/:mod:`daa_sil.viz`, so it costs no interpreter
   start-up; ``mode="exec"`` starts a fresh interpreter where fork is unavailable, other threads
   run or Rerun is already imported).
   The helper waits, blocked, and is scheduled ``SCHED_IDLE`` (``nice`` +10 where that fails);
2. :meth:`BackgroundRecorder.prepare`, called once the SIL processes are ready (their start-up is
   CPU-bound; the lockstep play leaves a core idle), makes it import Rerun, open the sinks (file,
   spawned viewer) and log the static entities;
3. :meth:`BackgroundRecorder.submit`, called the moment the vehicle exits (its step log is then
   complete), raises the helper back to normal priority and hands it the step log; it logs every
   step with ``send_columns`` (the same :class:`daa_sil.viz.EncounterLogger` as ``log_steplog``, so
   the same entities and steps), sends the blueprint (camera on the closest approach) and moves the
   ``.rrd`` into place atomically, while the orchestrator stops the shim and the GCS;
4. :meth:`BackgroundRecorder.finish` waits for that (usually not at all) and returns the path.

:meth:`BackgroundRecorder.abort` (errors, a second Ctrl-C, a timeout) kills the helper and removes
its temporary file; if the orchestrator dies, the helper reads EOF, or (blocked elsewhere, or the
orchestrator SIGKILLed) gets SIGTERM from :func:`daa_sil.sil.children.die_with_parent`, and does
the same. The helper is called ``daa-recorder`` in ps/pgrep. So the final
path holds a complete recording or nothing. A helper that fails is a
:class:`~daa_sil.viz.VizWarning` and ``finish`` returns None; only a bad explicit ``.rrd`` path
raises (:class:`~daa_sil.errors.OutputError`), in the constructor.

**Live mode** (``live=True``; ``daa-sil run`` uses it for ``--clock realtime`` runs with a viewer
sink, ``--spawn-viewer`` / ``--connect``, or with ``--viz-live on``): the constructor also binds a UDP
socket on 127.0.0.1 (:attr:`BackgroundRecorder.live_address`, passed to ``daa-vehicle --live``),
which the helper inherits. Once prepared, the helper logs every step row the vehicle sends there
(:mod:`daa_sil.sil.live`) to the viewer sinks as it arrives, with
:meth:`~daa_sil.viz.EncounterLogger.log_step`: the same entities, timelines and values as the
deferred path; the blueprint goes out with the first row (camera on the predicted closest
approach). Garbage and out-of-order datagrams are counted and ignored. When the step log comes, the
helper logs what is still queued and backfills every step-log row that did not arrive (or arrived
different). The ``.rrd`` is not streamed: it is written from the step log by the deferred path at
the end, so it is always complete, identical in content to a lockstep run's and compact (a file
streamed row by row holds one chunk per entity per row: 6 MB instead of 0.4 MB for 180 s). The
lockstep default keeps deferred logging: any CPU used next to a ~3 s lockstep run slows it.

Helper protocol (one line each): requests ``prepare`` and ``{"steplog": PATH, "vehicle_exit": T}``
(EOF = abort; ``T`` is ``time.monotonic()`` when the vehicle exited, or null); replies ``READY`` and
``DONE {"rrd": PATH | null, "steps": N, "live": null | {...}}``; ``live`` holds the feed's counters
(``received``, ``logged``, ``bad``, ``stale``), ``backfilled`` (rows taken from the step log),
``viewer`` (a viewer sink was attached), ``before_exit`` (steps in the viewer sinks before the
vehicle exited) and ``first_logged_before_exit_s``.
"""

from __future__ import annotations

import json
import os
import queue
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import IO

from daa_sil.geometry.thresholds import PRESETS, Thresholds, get_thresholds
from . import (SinkOptions, url_host_port, warn_viz, check_rrd_path)
from daa_sil.sil.children import die_with_parent, set_process_name, spawn
from daa_sil.viz.recorder_helper import serve_requests

#: the helper's process name (ps/pgrep)
RECORDER_NAME = "daa-recorder"
#: fallback priority (nice) where SCHED_IDLE is not available
RECORDER_NICE = 10
#: how long :meth:`BackgroundRecorder.finish` waits for the helper, s
RECORDER_FINISH_TIMEOUT_S = 120.0
#: how long :meth:`BackgroundRecorder.abort` waits after SIGTERM before SIGKILL, s
RECORDER_TERM_S = 3.0
#: receive buffer asked for the live feed's socket (the kernel may grant less); holds the rows that
#: arrive while the helper is still importing Rerun
LIVE_RCVBUF = 8 << 20


class _Forked:
    """The few ``subprocess.Popen`` methods :class:`BackgroundRecorder` needs, for a forked child."""

    def __init__(self, pid: int, stdin: IO[str], stdout: IO[str]):
        self.pid, self.stdin, self.stdout = pid, stdin, stdout
        self.returncode: "int | None" = None

    def poll(self) -> "int | None":
        if self.returncode is None:
            try:
                pid, status = os.waitpid(self.pid, os.WNOHANG)
            except ChildProcessError:
                self.returncode = -1
                return self.returncode
            if pid:
                self.returncode = os.waitstatus_to_exitcode(status)
        return self.returncode

    def wait(self, timeout: "float | None" = None) -> int:
        end = None if timeout is None else time.monotonic() + timeout
        while self.poll() is None:
            if end is not None and time.monotonic() >= end:
                raise subprocess.TimeoutExpired(f"recorder pid {self.pid}", timeout)
            time.sleep(0.005)
        return self.returncode  # type: ignore[return-value]


class BackgroundRecorder:
    """A Rerun recording of one SIL run, made by a helper process; see the module docstring.

    ``mode``: ``"auto"`` (fork if possible: POSIX and no other Python thread running, else exec),
    ``"fork"`` or ``"exec"``. ``prepare_now`` sends :meth:`prepare` at once. ``live``: also log the
    step rows sent to :attr:`live_address` as they arrive (module docstring).
    """

    def __init__(self, sinks: SinkOptions, preset: "str | Thresholds | None" = None,
                 encounter_id: "int | None" = None, mode: str = "auto", prepare_now: bool = False,
                 nice: int = RECORDER_NICE, live: bool = False, names: "list[str] | None" = None):
        self.sinks = sinks
        self.rrd_path = check_rrd_path(sinks.rrd, sinks.overwrite) if sinks.rrd else None
        if sinks.connect:
            url_host_port(sinks.connect)
        self.tmp_path: "Path | None" = None
        if self.rrd_path is not None:
            self.tmp_path = self.rrd_path.parent / f".{self.rrd_path.name}.{os.getpid()}.{os.urandom(4).hex()}.tmp"
        cfg = {k: (str(v) if isinstance(v, os.PathLike) else v) for k, v in vars(sinks).items()}
        cfg.update(overwrite=True, rrd_tmp=str(self.tmp_path) if self.tmp_path else None)
        th = get_thresholds(preset)
        self._args = {"sinks": cfg, "preset": th.name if th.name in PRESETS else None, "names": list(names or []),
                      "encounter_id": encounter_id, "nice": nice}
        #: set once the helper is prepared. After :meth:`finish`: ``prepared_in_time`` (it was prepared
        #: when the step log came), ``finish_s`` (step log handed over -> DONE, s), ``wait_s`` (how long
        #: ``finish`` itself blocked, s)
        self.ready = threading.Event()
        self.prepared_in_time: "bool | None" = None
        self.finish_s: "float | None" = None
        self.wait_s: "float | None" = None
        self.result: "dict | None" = None
        self._lines: "queue.Queue[str | None]" = queue.Queue()
        self._prepared = False
        self._submitted_at: "float | None" = None
        self._done = False
        if mode == "auto":  # fork only a clean process: no other thread, Rerun not yet initialised
            mode = ("fork" if hasattr(os, "fork") and threading.active_count() == 1 and "rerun" not in sys.modules
                    else "exec")
        if mode not in ("fork", "exec"):
            raise ValueError(f"mode must be auto, fork or exec, got {mode!r}")
        self.mode = mode
        #: ``udp:127.0.0.1:PORT`` of the live feed (None without ``live``)
        self.live_address: "str | None" = None
        live_sock = None
        if live:
            live_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            try:
                live_sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, LIVE_RCVBUF)
            except OSError:
                pass
            live_sock.bind(("127.0.0.1", 0))
            self.live_address = f"udp:127.0.0.1:{live_sock.getsockname()[1]}"
            self._args["live_fd"] = live_sock.fileno()
        try:
            self.proc = self._fork() if mode == "fork" else self._exec()
        finally:
            if live_sock is not None:
                live_sock.close()  # the helper holds its own copy
        self._reader = threading.Thread(target=self._pump, name="daa-sil-recorder", daemon=True)
        self._reader.start()
        if prepare_now:
            self.prepare()

    # starting the helper --------------------------------------------------------------------
    def _exec(self) -> subprocess.Popen:
        proc = spawn(
            [sys.executable, "-c", "from daa_sil.viz.recorder_helper import main; raise SystemExit(main())",
             json.dumps(self._args)], RECORDER_NAME, python=True,
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=None, text=True, bufsize=1,
            start_new_session=True,  # own group: a terminal Ctrl-C reaches the caller, which decides
            pass_fds=(self._args["live_fd"],) if self._args.get("live_fd") is not None else ())
        _set_idle_priority(proc.pid, self._args["nice"])
        return proc

    def _fork(self) -> _Forked:
        req_r, req_w = os.pipe()
        rep_r, rep_w = os.pipe()
        for stream in (sys.stdout, sys.stderr):
            stream.flush()  # or the child would write the parent's buffered output again
        parent = os.getpid()
        pid = os.fork()
        if pid == 0:  # the helper: never returns into the caller's code
            status = 1
            try:
                die_with_parent(parent)  # also if the orchestrator is SIGKILLed
                set_process_name(RECORDER_NAME)
                os.setsid()
                os.close(req_w)
                os.close(rep_r)
                _set_idle_priority(0, self._args["nice"])
                status = serve_requests(self._args, os.fdopen(req_r, "r"), os.fdopen(rep_w, "w"))
            finally:
                os._exit(status)
        os.close(req_r)
        os.close(rep_w)
        return _Forked(pid, os.fdopen(req_w, "w"), os.fdopen(rep_r, "r"))

    def _pump(self) -> None:
        for line in self.proc.stdout:  # type: ignore[union-attr]
            if line.startswith("READY"):
                self.ready.set()
            self._lines.put(line.rstrip("\n"))
        self._lines.put(None)

    def _send(self, line: str) -> None:
        try:
            self.proc.stdin.write(line + "\n")  # type: ignore[union-attr]
            self.proc.stdin.flush()  # type: ignore[union-attr]
        except (BrokenPipeError, OSError, ValueError):
            pass

    # the run's milestones ---------------------------------------------------------------------
    def prepare(self) -> None:
        """Let the helper import Rerun, open the sinks and log the static parts now (at idle priority)."""
        if not self._prepared and not self._done:
            self._prepared = True
            self._send("prepare")

    def submit(self, steplog: "str | os.PathLike", vehicle_exit: "float | None" = None) -> None:
        """Hand the helper the complete step log now and return at once; :meth:`finish` waits.

        Call it as soon as the step log is written (e.g. when the vehicle exits, ``vehicle_exit`` =
        that ``time.monotonic()``), so the helper's work overlaps with stopping the other processes.
        Only the first call counts.
        """
        if self._submitted_at is not None or self._done:
            return
        self._submitted_at = time.monotonic()
        self.prepared_in_time = self.ready.is_set()
        _set_normal_priority(self.proc.pid)  # the run is over: the helper is on the critical path now
        self._send(json.dumps({"steplog": str(steplog), "vehicle_exit": vehicle_exit}))
        try:
            self.proc.stdin.close()  # type: ignore[union-attr]
        except OSError:
            pass

    def finish(self, steplog: "str | os.PathLike", timeout_s: float = RECORDER_FINISH_TIMEOUT_S) -> "Path | None":
        """Log ``steplog`` (Parquet, one encounter; unless :meth:`submit` already sent one), close the
        sinks and return the .rrd path (None if not written).

        Blocks until the helper is done. Ctrl-C while waiting aborts the helper (no .rrd) and propagates.
        """
        if self._done:
            return Path(self.result["rrd"]) if self.result and self.result.get("rrd") else None
        t_wait = time.monotonic()
        try:
            self.submit(steplog)
            deadline = time.monotonic() + timeout_s
            while True:
                try:
                    line = self._lines.get(timeout=max(0.01, deadline - time.monotonic()))
                except queue.Empty:
                    warn_viz(f"the Rerun recorder did not finish within {timeout_s:g} s; no recording written")
                    break
                if line is None:
                    warn_viz("the Rerun recorder stopped without writing the recording")
                    break
                if line.startswith("DONE "):
                    self.result = json.loads(line[5:])
                    break
        except BaseException:
            self.abort()
            raise
        self._done = True
        self.wait_s = time.monotonic() - t_wait
        self.finish_s = time.monotonic() - self._submitted_at  # type: ignore[operator]
        try:
            self.proc.wait(timeout=5.0)
        except subprocess.TimeoutExpired:
            pass
        self.abort()  # reaps; removes a leftover temporary file
        return Path(self.result["rrd"]) if self.result and self.result.get("rrd") else None

    def abort(self) -> None:
        """Stop the helper (SIGTERM, then SIGKILL) and remove its temporary file; no .rrd is written."""
        self._done = True
        if self.proc.poll() is None:
            for sig, wait in ((signal.SIGTERM, RECORDER_TERM_S), (signal.SIGKILL, 5.0)):
                _kill_group(self.proc.pid, sig)
                try:
                    self.proc.wait(timeout=wait)
                    break
                except subprocess.TimeoutExpired:
                    continue
        for fh in (self.proc.stdin, self.proc.stdout):
            try:
                if fh is not None:
                    fh.close()
            except OSError:
                pass
        if self.tmp_path is not None:
            self.tmp_path.unlink(missing_ok=True)


def _kill_group(pid: int, sig: int) -> None:
    """Signal the helper's process group (it may not have called setsid yet: then the process)."""
    try:
        os.killpg(pid, sig)
        return
    except (ProcessLookupError, PermissionError):
        pass
    try:
        os.kill(pid, sig)
    except (ProcessLookupError, PermissionError):
        pass


def _set_idle_priority(pid: int, nice: int) -> None:
    """Run ``pid`` (0 = this process) only on cycles nothing else wants: SCHED_IDLE (a waking SIL
    process preempts it at once), else ``nice``."""
    try:
        os.sched_setscheduler(pid, os.SCHED_IDLE, os.sched_param(0))
        return
    except (OSError, AttributeError):
        pass
    try:
        os.setpriority(os.PRIO_PROCESS, pid, nice)
    except (OSError, AttributeError):
        pass


def _set_normal_priority(pid: int) -> None:
    """Back to SCHED_OTHER (without privileges only where RLIMIT_NICE allows it; else it stays idle)."""
    try:
        if os.sched_getscheduler(pid) == os.SCHED_IDLE:
            os.sched_setscheduler(pid, os.SCHED_OTHER, os.sched_param(0))
    except (OSError, AttributeError):
        pass


# --------------------------------------------------------------------------------------------
# the helper


