"""The recorder's helper process (forked, or exec'd with ``mode="exec"``): it reads requests from a
pipe (prepare, submit, finish), logs the live step feed and then the whole step log into the Rerun
sinks, and replies one JSON line per request."""

from __future__ import annotations

import json
import os
import select
import signal
import socket
import sys
import warnings
from dataclasses import replace
from pathlib import Path
from typing import IO

from daa_sil.viz import (
    EncounterLogger,
    SinkOptions,
    VizWarning,
    warn_viz,
    focus,
    log_steplog,
    predicted_focus,
    select_encounter,
)
from daa_sil.steplog import read_steplog
from daa_sil.sil.children import adopt

#: how often the live helper hands queued rows to Rerun, s
LIVE_FLUSH_S = 0.1


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
        from daa_sil.sil.live import LiveFeed  # lazy: start-up time

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


def serve_requests(args: dict, requests: IO[str], replies: IO[str]) -> int:
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
                                         defer_blueprint=True, flush_interval_s=LIVE_FLUSH_S,
                                         names=args.get("names"))
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
        warn_viz(f"Rerun recording failed: {type(exc).__name__}: {exc}")
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

    adopt()  # the name and the parent watch spawn() handed over
    args = json.loads((sys.argv[1:] if argv is None else argv)[0])
    status = serve_requests(args, sys.stdin, sys.stdout)
    os._exit(status)  # skip Rerun's atexit work: everything is flushed and the file is in place
