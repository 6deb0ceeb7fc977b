"""Rerun visualisation of encounters from step-log records (live viewer, ``.rrd`` file, web viewer).

Everything is fed from step-log rows (``docs/architecture.md`` "Step log schema",
:mod:`daa_sil.steplog`), so the SIL vehicle and fast-time produce the same picture.

API
---
``SinkOptions(rrd=None, spawn=False, connect=None, serve_web=False, ...)``
    Where the data goes. Any combination; none = visualisation off (Rerun is never called).
``EncounterLogger(sinks, preset=None, encounter_id=None, wait_lookup=None)``
    One recording per encounter; also a context manager.

    * ``.log_step(record)`` -- one step-log row as a dict of column name -> value (scalars, lists,
      or N = 1 arrays such as a :class:`~daa_sil.steplog.StepLogBuilder` step dict). O(1): the row
      is queued and a background thread batches the queue into ``send_columns`` calls, so the
      control loop is never blocked. Call it from one thread.
    * ``.log_table(table)`` -- a whole step log of one encounter (``pyarrow.Table`` / ``RecordBatch``),
      logged synchronously with ``send_columns`` (a 240-step encounter takes milliseconds).
    * ``.close()`` -- drain, flush, disconnect, move the ``.rrd`` into place (atomic rename) and stop
      the web server (``close(keep_serving=True)`` leaves it running; :meth:`stop_serving` stops it).
``log_steplog(table, sinks, encounter_id=None, preset=None) -> Path | None``
    Convert a step log (one encounter, or pick one with ``encounter_id``) into the sinks. ``preset``: the
    well-clear volume drawn (None: the run preset, ``paper``, :data:`daa_sil.config.settings.PRESET`).
:class:`daa_sil.viz.recorder.BackgroundRecorder`
    What ``daa-sil run --rrd/--spawn-viewer`` uses: the same logging, done by a helper process
    prepared while the SIL plays, so that the run is not slowed.
``log_waitmap(rec, waitmap, vi=, vh=, theta=)``
    A wait-map slice as a 3-D point cloud over (dX, dY, d_h) coloured by wait time.
``blueprint(...)``
    The default layout: 3-D view, ownship-centred top-down view, decisions log, plots, state lanes.

A missing viewer, no display for ``spawn``, an unreachable ``connect`` URL, ``RERUN=off`` or a
logging failure are :class:`VizWarning` warnings, never exceptions: visualisation must not break
the control loop. Only an explicit ``.rrd`` path that cannot be written (or would be overwritten
without ``overwrite=True``) raises :class:`~daa_sil.errors.OutputError`, when the logger opens.

Entities: see :mod:`daa_sil.viz.emitter`.

Rerun facts used (rerun-sdk 0.41): ``RecordingStream.set_sinks(FileSink, GrpcSink, default_blueprint=)``;
``send_columns`` with ``TimeColumn(name, duration=|sequence=)`` and ``Archetype.columns(...).partition``;
``spawn`` needs a display (headless it returns normally and the data is lost), so it is skipped
without ``DISPLAY``/``WAYLAND_DISPLAY``; the SDK's own servers bind 0.0.0.0, so the web viewer is the
``rerun`` binary started with ``--serve-web --bind 127.0.0.1``; an ``.rrd`` gets its footer on
``disconnect``.

Modules
-------
``records`` (step rows -> :class:`StepColumns`), ``draw`` (geometry and decision text), ``style``
(colours, lengths), ``emitter`` (columns -> ``send_columns``, the entity list), ``layout`` (blueprint),
``sinks`` (:class:`SinkOptions`, :class:`Recording`, :class:`WebServer`), ``logger``
(:class:`EncounterLogger`), ``steplog`` (whole step logs), ``waitmap`` (wait-map views), ``warning``
(:class:`VizWarning`). Every name is re-exported here, so ``daa_sil.viz.X`` keeps working.
"""

from __future__ import annotations

from ..errors import OutputError, UsageError
from daa_sil.geometry.thresholds import Thresholds, get_thresholds
from .draw import DECISION_LEVEL, track_arc, fmt_value, track_unit_enu, decision_text
from .emitter import StepEmitter, rerun_module
from .layout import blueprint
from .logger import EncounterLogger
from .records import BANDS, PER_INTRUDER, STRINGS, StepColumns, bands_from_lists, normalise_row, pad_lists
from .sinks import (APP_ID, SPAWN_PORT, WEB_GRPC_PORT, WEB_HTTP_PORT, Recording, SinkOptions, WebServer, port_open,
                    url_host_port, check_rrd_path, has_display, rerun_binary)
from .replay import focus, log_steplog, predicted_focus, select_encounter
from .style import (ALERT_COLORS, BAND_RADIUS_FACTOR, DAA_COLOR, EXEC_COLOR, LEAD_S, OWN_COLOR, PILOT_COLOR,
                    REGION_COLORS, REGION_WIDTH, TRAIL_S, WC_OK, WC_VIOLATED)
from .waitmap import log_waitmap, log_waitmap_points, wait_colors, waitmap_slice, write_waitmap
from .warning import VizWarning, warn_viz
