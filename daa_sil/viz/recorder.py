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
its temporary file; if the orchestrator dies, the helper reads EOF and does the same. So the final
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
import select
import signal
import socket
import subprocess
import sys
import threading
import time
import warnings
from dataclasses import replace
from pathlib import Path
from typing import IO

from daa_sil.geometry.thresholds import PRESETS, Thresholds, get_thresholds
from . import (EncounterLogger, SinkOptions, VizWarning, _url_host_port, _warn, check_rrd_path, focus,
    log_steplog, predicted_focus, select_encounter)

#: fallback priority (nice) where SCHED_IDLE is not available
RECORDER_NICE = 10
#: how long :meth:`BackgroundRecorder.finish` waits for the helper, s
RECORDER_FINISH_TIMEOUT_S = 120.0
#: how long :meth:`BackgroundRecorder.abort` waits after SIGTERM before SIGKILL, s
RECORDER_TERM_S = 3.0
#: receive buffer asked for the live feed's socket (the kernel may grant less); holds the rows that
#: arrive while the helper is still importing Rerun
LIVE_RCVBUF = 8 << 20
#: how often the live helper hands queued rows to Rerun, s
LIVE_FLUSH_S = 0.1


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
                 nice: int = RECORDER_NICE, live: bool = False):
        self.sinks = sinks
        self.rrd_path = check_rrd_path(sinks.rrd, sinks.overwrite) if sinks.rrd else None
        if sinks.connect:
            _url_host_port(sinks.connect)
        self.tmp_path: "Path | None" = None
        if self.rrd_path is not None:
            self.tmp_path = self.rrd_path.parent / f".{self.rrd_path.name}.{os.getpid()}.{os.urandom(4).hex()}.tmp"
        cfg = {k: (str(v) if isinstance(v, os.PathLike) else v) for k, v in vars(sinks).items()}
        cfg.update(overwrite=True, rrd_tmp=str(self.tmp_path) if self.tmp_path else None)
        th = get_thresholds(preset)
        self._args = {"sinks": cfg, "preset": th.name if th.name in PRESETS else None,
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
        proc = subprocess.Popen(
            [sys.executable, "-c", "from daa_sil.viz.recorder import main; raise SystemExit(main())",
             json.dumps(self._args)],
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
        pid = os.fork()
        if pid == 0:  # the helper: never returns into the caller's code
            status = 1
            try:
                os.setsid()
                os.close(req_w)
                os.close(rep_r)
                _set_idle_priority(0, self._args["nice"])
                status = _serve(self._args, os.fdopen(req_r, "r"), os.fdopen(rep_w, "w"))
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
                    _warn(f"the Rerun recorder did not finish within {timeout_s:g} s; no recording written")
                    break
                if line is None:
                    _warn("the Rerun recorder stopped without writing the recording")
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


class _Lines:
    """Request lines read straight from a file descriptor (so ``select`` sees every unread byte)."""

    def __init__(self, fh: IO[str]):
        self.fd = fh.fileno()
        self.buf = b""
        self.eof = False

    def ready(self) -> bool:
        return b"\n" in self.buf or self.eof

    def fill(self) -> None:
        data = os.read(self.fd, 65536)
        self.eof = self.eof or not data
        self.buf += data

    def readline(self) -> str:
        """The next line ("" at EOF); blocks until it is complete."""
        while not self.ready():
            self.fill()
        if b"\n" in self.buf:
            line, self.buf = self.buf.split(b"\n", 1)
            return line.decode(errors="replace") + "\n"
        line, self.buf = self.buf, b""
        return line.decode(errors="replace")


class _LiveIn:
    """The helper's end of the live feed: datagrams -> :class:`~daa_sil.sil.live.LiveFeed` -> ``log_step``."""

    def __init__(self, fd: int):
        from daa_sil.sil.live import LiveFeed

        self.sock = socket.socket(fileno=fd)
        self.sock.setblocking(False)
        self.feed = LiveFeed()
        self.blueprint_sent = False

    def take(self, logger: EncounterLogger, limit: int = 10_000) -> None:
        """Log every datagram waiting now (at most ``limit``)."""
        for _ in range(limit):
            try:
                data = self.sock.recv(65536)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                return
            row = self.feed.feed(data)
            if row is None:
                continue
            if not self.blueprint_sent:  # camera on the predicted closest approach, before the first row
                self.blueprint_sent = True
                logger.send_blueprint(*predicted_focus(row))
            logger.log_step(row)

    def finish(self, logger: EncounterLogger, table, sinks: SinkOptions, args: dict,
               vehicle_exit: "float | None") -> tuple["Path | None", dict]:
        """Log what is left, backfill what never came, close the viewer sinks; write the .rrd from the
        step log (the deferred path)."""
        self.take(logger)  # the vehicle has exited: everything it sent is in the socket buffer
        logger.flush_queue()
        before = [(t, n) for t, n in logger.emit_times if vehicle_exit is not None and t <= vehicle_exit]
        missing = self.feed.missing(table)
        if missing:  # lost, refused or different rows: the viewer gets them from the step log
            if not self.blueprint_sent:
                logger.send_blueprint(*focus(table))
            logger.log_table(table.take(missing))
        info = dict(self.feed.counters(), backfilled=len(missing), viewer=logger.rec is not None,
                    before_exit=before[-1][1] if before else 0,
                    first_logged_before_exit_s=(round(vehicle_exit - logger.emit_times[0][0], 3)
                                                if before else None))
        logger.close()
        if not sinks.rrd:
            return None, info
        file_only = replace(sinks, spawn=False, connect=None, serve_web=False)
        path, _ = log_steplog(table, file_only, encounter_id=args.get("encounter_id"), preset=args.get("preset"))
        return path, info

    def close(self) -> None:
        self.sock.close()


def _serve(args: dict, requests: IO[str], replies: IO[str]) -> int:
    """The helper's work (see the module docstring); returns its exit status. Never raises."""
    sinks = SinkOptions(**args["sinks"])
    tmp = Path(sinks.rrd_tmp) if sinks.rrd_tmp else None

    def on_term(signum, frame):
        if tmp is not None:
            tmp.unlink(missing_ok=True)
        os._exit(128 + signum)

    signal.signal(signal.SIGTERM, on_term)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the owner decides (it aborts with SIGTERM)

    def show(message, category, filename, lineno, file=None, line=None):
        print(f"daa-sil: warning: {message}", file=sys.stderr, flush=True)

    warnings.showwarning = show
    warnings.simplefilter("always", VizWarning)
    logger: "EncounterLogger | None" = None
    live = _LiveIn(args["live_fd"]) if args.get("live_fd") is not None else None
    lines = _Lines(requests)
    status = 1
    try:
        from daa_sil.steplog import read_steplog

        while True:
            if live is not None and logger is not None and not lines.ready():
                readable, _, _ = select.select([lines.fd, live.sock], [], [], 1.0)
                if live.sock in readable:
                    live.take(logger)
                if lines.fd not in readable:
                    continue
                lines.fill()
                if not lines.ready():
                    continue
            line = lines.readline()
            if line.strip() == "prepare" and logger is not None:
                continue
            if logger is None and line.strip():  # prepare (or a step log before any prepare)
                # live: the rows go to the viewer sinks; the .rrd is made from the step log at the end
                opened = replace(sinks, rrd=None, rrd_tmp=None) if live is not None else sinks
                logger = EncounterLogger(opened, preset=args.get("preset"), encounter_id=args.get("encounter_id"),
                                         defer_blueprint=True, flush_interval_s=LIVE_FLUSH_S)
                print("READY", file=replies, flush=True)
                if line.strip() == "prepare":
                    continue
            if not line.strip():  # EOF: the owner went away or aborted
                if logger is not None:
                    logger.abort()
                break
            req = json.loads(line)
            table, _ = select_encounter(read_steplog(req["steplog"]))  # the only encounter
            info = None
            if live is not None:
                path, info = live.finish(logger, table, sinks, args, req.get("vehicle_exit"))  # type: ignore[arg-type]
            else:
                center, extent = focus(table)
                logger.send_blueprint(center, extent)  # type: ignore[union-attr]
                logger.log_table(table)  # type: ignore[union-attr]
                path = logger.close()  # type: ignore[union-attr]
            done = {"rrd": str(path) if path else None, "steps": table.num_rows if info else logger.steps_logged,  # type: ignore[union-attr]
                    "live": info}
            print("DONE " + json.dumps(done), file=replies, flush=True)
            break
        status = 0
    except Exception as exc:
        _warn(f"Rerun recording failed: {type(exc).__name__}: {exc}")
    finally:
        if live is not None:
            live.close()
        if tmp is not None and status != 0:
            tmp.unlink(missing_ok=True)
        try:
            replies.flush()
            sys.stderr.flush()
        except OSError:
            pass
    return status


def main(argv: "list[str] | None" = None) -> int:
    """Entry point of the ``mode="exec"`` helper: the JSON arguments in ``argv[0]``, stdin/stdout pipes."""
    args = json.loads((sys.argv[1:] if argv is None else argv)[0])
    status = _serve(args, sys.stdin, sys.stdout)
    os._exit(status)  # skip Rerun's atexit work: everything is flushed and the file is in place
