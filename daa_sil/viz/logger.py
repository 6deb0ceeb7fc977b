""":class:`EncounterLogger`: one recording per encounter, fed row by row (background thread) or a whole
table at a time; intervals in s."""

from __future__ import annotations

import collections
import threading
import time
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping

import numpy as np
import pyarrow as pa

from daa_sil.geometry.thresholds import Thresholds, get_thresholds
from .emitter import StepEmitter
from .layout import blueprint
from .records import StepColumns
from .sinks import Recording, SinkOptions, WebServer
from .warning import warn_viz
import json

def intruder_names(table) -> "list[str]":
    """The intruders' callsigns of a step log, by index (its ``intruders`` metadata, written by the SIL
    vehicle: scenario and injected intruders); [] without it (fast-time step logs)."""

    meta = getattr(getattr(table, "schema", None), "metadata", None) or {}
    raw = meta.get(b"intruders")
    try:
        return [str(i.get("callsign") or "") for i in json.loads(raw)] if raw else []
    except (ValueError, AttributeError, TypeError):
        return []


class EncounterLogger:
    """One Rerun recording of one encounter; see the :mod:`daa_sil.viz` docstring."""

    def __init__(self, sinks: "SinkOptions | None" = None, preset: "str | Thresholds | None" = None,
                 encounter_id: "int | str | None" = None, wait_lookup: "Callable[[np.ndarray], np.ndarray] | None" = None,
                 center: "Iterable[float] | None" = None, extent_m: float = 6000.0, flush_interval_s: float = 0.25,
                 defer_blueprint: bool = False, names: "list[str] | None" = None):
        self.th = get_thresholds(preset)
        self.encounter_id = encounter_id
        self.flush_interval_s = flush_interval_s
        self._emitter: "StepEmitter | None" = None
        self._queue: collections.deque = collections.deque()
        self._wake = threading.Event()
        self._stop = False
        self._thread: "threading.Thread | None" = None
        self._failed = False
        self._closed = False
        self._aborted = False
        self._lock = threading.Lock()
        #: (time.monotonic(), steps logged so far) after each batch of :meth:`log_step` rows was sent
        self.emit_times: list[tuple[float, int]] = []
        bp = None
        if sinks is not None and sinks.enabled and not defer_blueprint:
            bp = blueprint(center, extent_m)
        rid = f"encounter-{encounter_id}" if encounter_id is not None else None
        self._recording = Recording(sinks, rid, bp)
        if self._recording.rec is not None:
            try:
                self._emitter = StepEmitter(self._recording.rec, self.th, wait_lookup, names=names)
            except Exception as exc:
                self._disable(f"Rerun logging disabled: {type(exc).__name__}: {exc}")

    @property
    def rec(self):
        """The underlying ``rerun.RecordingStream`` (None when disabled)."""
        return self._recording.rec

    @property
    def web(self) -> "WebServer | None":
        return self._recording.web

    @property
    def rrd_path(self) -> "Path | None":
        return self._recording.rrd_path

    @property
    def enabled(self) -> bool:
        """True while a sink is attached and nothing has failed."""
        return self.rec is not None and not self._failed

    def _disable(self, msg: str) -> None:
        if not self._failed:
            warn_viz(msg)
        self._failed = True

    # incremental ----------------------------------------------------------------------------
    def log_step(self, record: Mapping[str, Any]) -> None:
        """Queue one step-log row (O(1), never blocks, never raises)."""
        if self.rec is None or self._failed or self._closed:
            return
        self._queue.append({k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in record.items()})
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="daa-sil-viz", daemon=True)
            self._thread.start()
        if len(self._queue) >= 64:
            self._wake.set()

    def _run(self) -> None:
        while True:
            self._wake.wait(self.flush_interval_s)
            self._wake.clear()
            self._drain()
            if self._stop and not self._queue:
                return

    def _drain(self) -> None:
        with self._lock:  # pop and emit together: batches from two threads never interleave
            batch = []
            while self._queue:
                batch.append(self._queue.popleft())
            if not batch or self._failed:
                return
            try:
                self._emitter.emit(StepColumns.from_records(batch))
            except Exception as exc:
                self._disable(f"Rerun logging stopped after an error: {type(exc).__name__}: {exc}")
                return
            self.emit_times.append((time.monotonic(), self._emitter.steps_logged))

    def flush_queue(self) -> None:
        """Log the rows queued by :meth:`log_step` now, in the calling thread (they keep their order)."""
        if self._thread is not None:
            self._drain()

    # batch ----------------------------------------------------------------------------------
    def log_table(self, table: "pa.Table | pa.RecordBatch") -> None:
        """Log a whole step log of one encounter (rows in step order) with ``send_columns``."""
        if self.rec is None or self._failed:
            return
        names = intruder_names(table)
        if names and not self._emitter.names:
            self._emitter.names = names
        try:
            with self._lock:
                self._emitter.emit(StepColumns.from_table(table))
        except Exception as exc:
            self._disable(f"Rerun logging stopped after an error: {type(exc).__name__}: {exc}")

    def send_blueprint(self, center: "Iterable[float] | None" = None, extent_m: float = 6000.0) -> None:
        """Send the default layout now (for a logger opened with ``defer_blueprint=True``, e.g. once the
        closest approach, the camera target, is known)."""
        if self.rec is None or self._failed:
            return
        try:
            with self._lock:
                self.rec.send_blueprint(blueprint(center, extent_m), make_active=True, make_default=True)
        except Exception as exc:
            self._disable(f"Rerun logging stopped after an error: {type(exc).__name__}: {exc}")

    @property
    def steps_logged(self) -> int:
        return 0 if self._emitter is None else self._emitter.steps_logged

    # closing ----------------------------------------------------------------------------------
    def close(self, keep_serving: bool = False, commit: bool = True) -> "Path | None":
        """Drain the queue, flush and disconnect; move the .rrd into place (not with ``commit=False``:
        then the temporary file is removed); return its path (None if not written)."""
        if not self._closed:
            self._closed = True
            self._stop = True
            self._wake.set()
            if self._thread is not None:
                self._thread.join()
        return self._recording.close(keep_serving=keep_serving, commit=commit and not self._aborted)

    def stop_serving(self) -> None:
        """Stop the web viewer started by this logger (if any)."""
        if self.web is not None:
            self.web.stop()

    def wait_serving(self, announce: "Callable[[], None] | None" = None) -> None:
        """Call ``announce`` (e.g. print the viewer's URL), then block until Ctrl-C while the web viewer
        runs, then stop it. The announcement is inside the Ctrl-C guard: whoever reads it may stop the
        server at once, and that is still a clean stop."""
        try:
            if announce is not None:
                announce()
            while self.web is not None and self.web.alive():
                time.sleep(0.5)
        except KeyboardInterrupt:
            pass
        finally:
            self.stop_serving()

    def abort(self) -> None:
        """Stop without writing the .rrd (e.g. the run failed)."""
        self._queue.clear()
        self._aborted = True
        self.close()

    def __enter__(self) -> "EncounterLogger":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is not None and not issubclass(exc_type, (KeyboardInterrupt,)):
            self.abort()
        else:
            self.close()
