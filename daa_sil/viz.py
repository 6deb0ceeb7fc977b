"""Rerun visualisation of encounters from step-log records (live viewer, ``.rrd`` file, web viewer).

Everything is fed from step-log rows (``docs/architecture.md`` "Step log schema",
:mod:`daa_sil.steplog`), so the SIL vehicle and fast-time produce the same picture.

API
---
``SinkOptions(rrd=None, spawn=False, connect=None, serve_web=False, ...)``
    Where the data goes. Any combination; none = visualisation off (Rerun is never called).
``EncounterLogger(sinks, preset="do365", encounter_id=None, wait_lookup=None)``
    One recording per encounter; also a context manager.

    * ``.log_step(record)`` -- one step-log row as a dict of column name -> value (scalars, lists,
      or N = 1 arrays such as a :class:`~daa_sil.steplog.StepLogBuilder` step dict). O(1): the row
      is queued and a background thread batches the queue into ``send_columns`` calls, so the
      control loop is never blocked. Call it from one thread.
    * ``.log_table(table)`` -- a whole step log of one encounter (``pyarrow.Table`` / ``RecordBatch``),
      logged synchronously with ``send_columns`` (a 240-step encounter takes milliseconds).
    * ``.close()`` -- drain, flush, disconnect, move the ``.rrd`` into place (atomic rename) and stop
      the web server (``close(keep_serving=True)`` leaves it running; :meth:`stop_serving` stops it).
``log_steplog(table, sinks, encounter_id=None, preset="do365") -> Path | None``
    Convert a step log (one encounter, or pick one with ``encounter_id``) into the sinks.
:class:`daa_sil.viz_recorder.BackgroundRecorder`
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

Entities (ENU, ``rr.ViewCoordinates.RIGHT_HAND_Z_UP``; timelines ``sim_time`` (duration) and ``step``)
-------------------------------------------------------------------------------------------------
``world/ownship`` (Transform3D; children move with it): ``body`` (point, label = authority),
``velocity``, ``well_clear`` (cylinder radius DTHR, height 2 ZTHR; red while any intruder is in
violation), ``cmd/pilot``, ``cmd/daa``, ``cmd/exec`` (commanded tracks as arrows), ``bands``
(track bands as coloured arcs: near red, mid orange, far yellow, recovery cyan, none green).
``world/ownship_trail``, ``world/intruders/<id>`` (+ ``/trail``, ``/velocity``); ``<id>`` is the
intruder's index in the step log's list columns. ``decisions`` (text log: one line per decision with
its reason, plus LoWC/NMAC events). ``status/decision``, ``status/authority`` (state lanes).
``plots/range/<id>``, ``plots/hmd/<id>``, ``plots/dh/<id>``, ``plots/tau_mod/<id>``,
``plots/alert/<id>``, ``plots/wait/wait_s`` (wait-map value used), ``plots/wait/map/<id>`` (with
``wait_lookup``), ``plots/delay/up``, ``plots/delay/down``, ``plots/sm/pilot``, ``plots/sm/exec``.

Rerun facts used (rerun-sdk 0.41): ``RecordingStream.set_sinks(FileSink, GrpcSink, default_blueprint=)``;
``send_columns`` with ``TimeColumn(name, duration=|sequence=)`` and ``Archetype.columns(...).partition``;
``spawn`` needs a display (headless it returns normally and the data is lost), so it is skipped
without ``DISPLAY``/``WAYLAND_DISPLAY``; the SDK's own servers bind 0.0.0.0, so the web viewer is the
``rerun`` binary started with ``--serve-web --bind 127.0.0.1``; an ``.rrd`` gets its footer on
``disconnect``.
"""

from __future__ import annotations

import atexit
import collections
import os
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
import urllib.parse
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping

import numpy as np
import pyarrow as pa

from .errors import OutputError, UsageError
from .thresholds import Thresholds, get_thresholds

APP_ID = "daa_sil"
#: default ports: spawned native viewer (Rerun's default), web viewer's gRPC proxy, web viewer HTTP
SPAWN_PORT, WEB_GRPC_PORT, WEB_HTTP_PORT = 9876, 9877, 9090

TRAIL_S = 60.0  #: trail length, s of sim time
LEAD_S = 30.0  #: velocity arrows show 30 s of flight
BAND_RADIUS_FACTOR = 1.5  #: band arcs at 1.5 x DTHR around the ownship

REGION_COLORS = {"near": (230, 30, 30, 255), "mid": (255, 140, 0, 255), "far": (255, 215, 0, 255),
                 "recovery": (0, 200, 255, 255), "none": (60, 200, 60, 200)}
REGION_WIDTH = {"near": -4.0, "mid": -4.0, "far": -3.0, "recovery": -3.0, "none": -1.5}  # ui points
ALERT_COLORS = np.array([(200, 200, 200, 255), (255, 215, 0, 255), (255, 140, 0, 255), (230, 30, 30, 255)],
                        np.uint8)
OWN_COLOR, PILOT_COLOR, DAA_COLOR, EXEC_COLOR = (40, 200, 60), (60, 140, 255), (230, 60, 230), (255, 255, 255)
WC_OK, WC_VIOLATED = (40, 200, 60, 35), (230, 30, 30, 60)

DECISION_LEVEL = {"wait": "INFO", "pilot": "INFO", "blend": "INFO", "no_wait": "WARN", "daa": "WARN",
                  "daa_override": "WARN", "stale": "ERROR", "link_lost": "ERROR"}

PER_INTRUDER = ("intr_x", "intr_y", "intr_z", "intr_gs", "intr_trk_deg", "intr_vs", "range_m", "hmd_m",
                "dh_m", "tau_mod_s", "alert_level", "wcv")
BANDS = ("bands_trk_lo_deg", "bands_trk_hi_deg", "bands_trk_region")
STRINGS = ("decision", "rule", "authority", "pilot_axis", "pilot_dir", "exec_axis", "exec_dir")


class VizWarning(UserWarning):
    """Visualisation problem that does not stop the simulation (no viewer, no display, ...)."""


def _warn(msg: str) -> None:
    warnings.warn(msg, VizWarning, stacklevel=3)


# --------------------------------------------------------------------------------------------
# step rows -> columns


class StepColumns:
    """Step-log rows of one encounter as numpy columns: scalars ``(n,)``, intruders ``(n, M)``, bands ragged."""

    def __init__(self, scalars: dict[str, np.ndarray], intruders: dict[str, np.ndarray],
                 bands: list[list[tuple[float, float, str]]]):
        self.scalars, self.intruders, self.bands = scalars, intruders, bands
        self.n = len(bands)
        self.m = max((a.shape[1] for a in intruders.values()), default=0)

    def f(self, name: str) -> np.ndarray:
        """Float column (nan where missing)."""
        a = self.scalars.get(name)
        if a is None:
            return np.full(self.n, np.nan)
        return np.asarray(a, float)

    def s(self, name: str, default: str = "none") -> list[str]:
        """String column (``default`` where missing)."""
        a = self.scalars.get(name)
        return [default] * self.n if a is None else [default if v is None else str(v) for v in a]

    def b(self, name: str) -> np.ndarray:
        """Bool column (False where missing)."""
        a = self.scalars.get(name)
        return np.zeros(self.n, bool) if a is None else np.array([bool(v) if v is not None else False for v in a])

    def i(self, name: str) -> np.ndarray:
        """Per-intruder float column ``(n, M)`` (nan padded)."""
        a = self.intruders.get(name)
        return np.full((self.n, self.m), np.nan) if a is None else a

    @classmethod
    def from_table(cls, table: "pa.Table | pa.RecordBatch") -> "StepColumns":
        """Columns of a step-log table (rows in step order)."""
        if isinstance(table, pa.RecordBatch):
            table = pa.Table.from_batches([table])
        n = table.num_rows
        scalars: dict[str, np.ndarray] = {}
        intruders: dict[str, np.ndarray] = {}
        for name in table.column_names:
            col = table.column(name).combine_chunks()
            if name in BANDS:
                continue
            if pa.types.is_list(col.type) or pa.types.is_large_list(col.type):
                if name in PER_INTRUDER:
                    intruders[name] = _pad_lists(col, n)
                continue
            if pa.types.is_string(col.type) or pa.types.is_large_string(col.type) or pa.types.is_dictionary(col.type):
                scalars[name] = np.array(col.to_pylist(), dtype=object)
            elif pa.types.is_boolean(col.type):
                scalars[name] = np.array(col.fill_null(False).to_numpy(zero_copy_only=False), bool)
            else:
                scalars[name] = np.asarray(col.cast(pa.float64()).fill_null(np.nan).to_numpy(zero_copy_only=False))
        bands = _bands_from_lists(*(table.column(b).to_pylist() if b in table.column_names else [[]] * n
                                    for b in BANDS))
        return cls(scalars, intruders, bands)

    @classmethod
    def from_records(cls, records: "list[Mapping[str, Any]]") -> "StepColumns":
        """Columns of step-log row dicts (values: scalars, lists, or N = 1 arrays)."""
        rows = [_normalise(r) for r in records]
        n = len(rows)
        keys: dict[str, None] = {}
        for r in rows:
            keys.update(dict.fromkeys(r))
        scalars: dict[str, np.ndarray] = {}
        intruders: dict[str, np.ndarray] = {}
        for name in keys:
            if name in BANDS or name == "bands_count":
                continue
            vals = [r.get(name) for r in rows]
            if name in PER_INTRUDER:
                m = max((len(v) for v in vals if v is not None), default=0)
                out = np.full((n, m), np.nan)
                for k, v in enumerate(vals):
                    if v is not None and len(v):
                        out[k, :len(v)] = np.asarray(v, float)
                intruders[name] = out
            elif any(isinstance(v, str) for v in vals):
                scalars[name] = np.array(vals, dtype=object)
            else:
                scalars[name] = np.array([np.nan if v is None else float(v) for v in vals])
        bands = _bands_from_lists(*([r.get(b, []) for r in rows] for b in BANDS))
        return cls(scalars, intruders, bands)


def _pad_lists(col: pa.Array, n: int) -> np.ndarray:
    """A list column as an ``(n, M)`` float array padded with nan."""
    lens = np.asarray(col.value_lengths().fill_null(0).to_numpy(zero_copy_only=False), np.int64)
    m = int(lens.max(initial=0))
    out = np.full((n, m), np.nan)
    if m == 0:
        return out
    flat = col.flatten()
    vals = np.asarray(flat.cast(pa.float64()).fill_null(np.nan).to_numpy(zero_copy_only=False))
    rows = np.repeat(np.arange(n), lens)
    starts = np.concatenate([[0], np.cumsum(lens)[:-1]])
    cols = np.arange(lens.sum()) - np.repeat(starts, lens)
    out[rows, cols] = vals
    return out


def _bands_from_lists(lo, hi, region) -> list[list[tuple[float, float, str]]]:
    out = []
    for a, b, c in zip(lo, hi, region):
        a, b, c = a or [], b or [], c or []
        out.append([(float(x), float(y), str(z)) for x, y, z in zip(a, b, c)])
    return out


def _normalise(record: Mapping[str, Any]) -> dict[str, Any]:
    """One row from a dict whose values may be N = 1 arrays (StepLogBuilder step dicts)."""
    out: dict[str, Any] = {}
    count = record.get("bands_count")
    if count is not None:
        count = int(np.asarray(count).reshape(-1)[0])
    for k, v in record.items():
        if isinstance(v, np.ndarray):
            if k in PER_INTRUDER or k in BANDS:
                v = v[0] if v.ndim == 2 else v
                v = v.tolist()
                if k in BANDS and count is not None:
                    v = v[:count]
            else:
                v = v.reshape(-1)[0].item() if v.size else None
        elif isinstance(v, np.generic):
            v = v.item()
        elif isinstance(v, (list, tuple)):
            v = list(v)
        out[k] = v
    return out


# --------------------------------------------------------------------------------------------
# geometry helpers


def _unit_enu(trk_deg: np.ndarray) -> np.ndarray:
    r = np.radians(trk_deg)
    return np.stack([np.sin(r), np.cos(r), np.zeros_like(r)], axis=-1)


def _arc(lo_deg: float, hi_deg: float, radius: float, step_deg: float = 3.0) -> np.ndarray:
    """Points of a compass-track arc (clockwise from ``lo`` to ``hi``) at ``radius`` around the origin."""
    span = (hi_deg - lo_deg) % 360.0
    if span == 0.0 and hi_deg != lo_deg:
        span = 360.0
    k = max(2, int(np.ceil(span / step_deg)) + 1)
    ang = np.radians(lo_deg + np.linspace(0.0, span, k))
    return np.stack([radius * np.sin(ang), radius * np.cos(ang), np.zeros(k)], axis=-1).astype(np.float32)


def _fmt(x: float, unit: str = "", prec: int = 1) -> str:
    return "n/a" if not np.isfinite(x) else f"{x:.{prec}f}{unit}"


def decision_text(cols: StepColumns, k: int) -> tuple[str, str]:
    """Text and level of row ``k``'s decision (empty text for ``none``)."""
    d = cols.s("decision")[k]
    if d in ("none", "", "nan"):
        return "", ""
    rule, ws, sm_p, sm_x = cols.s("rule", "-")[k], cols.f("wait_s")[k], cols.f("sm_pilot")[k], cols.f("sm_exec")[k]
    age, projl = cols.f("pilot_cmd_age_s")[k], cols.b("projl")[k]
    cmd = (f"trk {_fmt(cols.f('cmd_trk_deg')[k], '°', 0)} vs {_fmt(cols.f('cmd_vs')[k], ' m/s')} "
           f"gs {_fmt(cols.f('cmd_gs')[k], ' m/s')}")
    pilot = f"{cols.s('pilot_axis')[k]}/{cols.s('pilot_dir')[k]}"
    exe = f"{cols.s('exec_axis')[k]}/{cols.s('exec_dir')[k]}"
    if d == "wait":
        why = f"no fresh pilot command; w(S) = {_fmt(ws, ' s')}, no ProjL -> hold the pilot course ({cmd})"
    elif d == "no_wait":
        why = (f"no fresh pilot command; w(S) = {_fmt(ws, ' s')}, ProjL {'yes' if projl else 'no'} "
               f"-> DAA resolution ({cmd})")
    elif d == "pilot":
        why = f"pilot command {pilot} (age {_fmt(age, ' s')}) SM = {_fmt(sm_p, ' s')} > 0 -> execute ({cmd})"
    elif d == "blend":
        why = (f"pilot command {pilot} SM = {_fmt(sm_p, ' s')} <= 0 -> blended by rule {rule} to {exe}, "
               f"SM = {_fmt(sm_x, ' s')} ({cmd})")
    elif d == "daa_override":
        why = f"pilot command {pilot} SM = {_fmt(sm_p, ' s')} <= 0, no blending -> DAA resolution ({cmd})"
    elif d == "daa":
        why = f"onboard DAA resolution {exe} ({cmd})"
    elif d == "stale":
        why = f"pilot command too old (age {_fmt(age, ' s')}) -> not executed ({cmd})"
    elif d == "link_lost":
        why = f"no packet from the GCS -> link lost, onboard DAA ({cmd})"
    else:
        why = cmd
    label = {"no_wait": "no-wait", "blend": "blended", "daa_override": "DAA override", "daa": "DAA",
             "link_lost": "link lost"}.get(d, d)
    return f"{label}: {why}", DECISION_LEVEL.get(d, "INFO")


# --------------------------------------------------------------------------------------------
# emitting columns


class _Emitter:
    """Turns :class:`StepColumns` batches into ``send_columns`` calls; keeps trails across batches."""

    def __init__(self, rec, th: Thresholds, wait_lookup: "Callable[[np.ndarray], np.ndarray] | None" = None,
                 trail_s: float = TRAIL_S):
        self.rec, self.th, self.wait_lookup, self.trail_s = rec, th, wait_lookup, trail_s
        self.band_radius = BAND_RADIUS_FACTOR * th.dthr
        self.cmd_len = 1.15 * self.band_radius
        self.hist_t: collections.deque = collections.deque()
        self.hist_own: collections.deque = collections.deque()
        self.hist_intr: collections.deque = collections.deque()
        self.known_intruders: set[int] = set()
        self.prev_lowc = False
        self.prev_nmac = False
        self.steps_logged = 0
        self._static()

    # static -----------------------------------------------------------------------------
    def _static(self) -> None:
        rr = _rr()
        r, th = self.rec, self.th
        r.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        r.log("world/ownship/well_clear",
              rr.Cylinders3D.from_fields(lengths=[2.0 * th.zthr], radii=[th.dthr],
                                         fill_mode=rr.components.FillMode.TransparentFillMajorWireframe,
                                         labels=[f"well clear {th.name}: {th.dthr:.0f} m, ±{th.zthr:.0f} m"],
                                         show_labels=False), static=True)
        r.log("world/ownship/body", rr.Points3D.from_fields(positions=[[0.0, 0.0, 0.0]], radii=[-8.0],
                                                            colors=[OWN_COLOR]), static=True)
        for name, color, label in (("pilot", PILOT_COLOR, "pilot cmd"), ("daa", DAA_COLOR, "DAA resolution"),
                                   ("exec", EXEC_COLOR, "executed cmd")):
            r.log(f"world/ownship/cmd/{name}", rr.Arrows3D.from_fields(colors=[color], radii=[-2.0], labels=[label],
                                                                       show_labels=False), static=True)
        r.log("world/ownship/velocity", rr.Arrows3D.from_fields(colors=[OWN_COLOR], radii=[-1.5]), static=True)
        r.log("world/ownship_trail", rr.LineStrips3D.from_fields(colors=[OWN_COLOR], radii=[-1.5]), static=True)
        styles = {"plots/hmd/threshold": ("HMD* [m]", (150, 150, 150)),
                  "plots/tau_mod/threshold": ("tau_mod* [s]", (150, 150, 150)),
                  "plots/dh/zthr_up": ("+ZTHR [m]", (150, 150, 150)), "plots/dh/zthr_down": ("-ZTHR [m]", (150, 150, 150)),
                  "plots/wait/wait_s": ("wait-map value used [s]", (255, 200, 0)),
                  "plots/delay/up": ("uplink delay [s]", PILOT_COLOR), "plots/delay/down": ("downlink delay [s]", OWN_COLOR),
                  "plots/sm/pilot": ("SM(pilot cmd) [s]", PILOT_COLOR), "plots/sm/exec": ("SM(executed) [s]", EXEC_COLOR)}
        for path, (name, color) in styles.items():
            r.log(path, rr.SeriesLines(names=name, colors=[color], widths=2), static=True)

    def _intruder_static(self, j: int) -> None:
        rr = _rr()
        r = self.rec
        color = [(255, 80, 80), (255, 160, 60), (200, 100, 255), (80, 200, 255)][j % 4]
        r.log(f"world/intruders/{j}/trail", rr.LineStrips3D.from_fields(colors=[color], radii=[-1.5]), static=True)
        r.log(f"world/intruders/{j}/velocity", rr.Arrows3D.from_fields(colors=[color], radii=[-1.5]), static=True)
        for q, unit in (("range", "m"), ("hmd", "m"), ("dh", "m"), ("tau_mod", "s"), ("alert", "level")):
            r.log(f"plots/{q}/{j}", rr.SeriesLines(names=f"{q} #{j} [{unit}]", colors=[color], widths=2), static=True)
        if self.wait_lookup is not None:
            r.log(f"plots/wait/map/{j}", rr.SeriesLines(names=f"w(S) #{j} [s]", colors=[color], widths=2), static=True)
        self.known_intruders.add(j)

    # per batch -----------------------------------------------------------------------------
    def _send(self, path: str, mask: "np.ndarray | None", columns) -> None:
        rr = _rr()
        t, step = self._t, self._step
        if mask is not None:
            t, step = t[mask], step[mask]
            if t.size == 0:
                return
        self.rec.send_columns(path, indexes=[rr.TimeColumn("sim_time", duration=t),
                                             rr.TimeColumn("step", sequence=step)], columns=columns)

    def _scalar(self, path: str, values: np.ndarray) -> None:
        rr = _rr()
        ok = np.isfinite(values)
        if ok.any():
            self._send(path, ok, rr.Scalars.columns(scalars=values[ok]))

    def _arrows(self, path: str, origins: np.ndarray, vectors: np.ndarray) -> None:
        """Arrows with an empty row (nothing shown) where the vector is not finite."""
        rr = _rr()
        ok = np.all(np.isfinite(vectors), axis=-1) & np.all(np.isfinite(origins), axis=-1)
        lengths = ok.astype(np.int64)
        self._send(path, None, rr.Arrows3D.columns(origins=origins[ok], vectors=vectors[ok]).partition(lengths))

    def emit(self, c: StepColumns) -> None:
        """Log one batch of rows (consecutive steps of one encounter)."""
        rr = _rr()
        n, th = c.n, self.th
        if n == 0:
            return
        t = c.f("t")
        step = c.f("step")
        if np.isnan(step).all():
            step = np.arange(self.steps_logged, self.steps_logged + n, dtype=float)
        if np.isnan(t).any():
            t = np.where(np.isnan(t), step, t)
        self._t, self._step = t, step.astype(np.int64)
        own = np.stack([c.f("own_x"), c.f("own_y"), c.f("own_z")], axis=-1)
        gs, trk, vs = c.f("own_gs"), c.f("own_trk_deg"), c.f("own_vs")
        own_v = _unit_enu(trk) * gs[:, None]
        own_v[:, 2] = vs

        # ownship
        self._send("world/ownship", None, rr.Transform3D.columns(translation=np.nan_to_num(own)))
        auth = c.s("authority", "pilot")
        self._send("world/ownship/body", None, rr.Points3D.columns(labels=[f"ownship ({a})" for a in auth]))
        self._arrows("world/ownship/velocity", np.zeros((n, 3)), own_v * LEAD_S)
        for name in ("pilot", "daa", "cmd"):
            ctrk, cvs, cgs = c.f(f"{name}_trk_deg"), c.f(f"{name}_vs"), c.f(f"{name}_gs")
            cgs = np.where(np.isfinite(cgs), cgs, gs)
            cvs = np.where(np.isfinite(cvs), cvs, vs)
            vec = _unit_enu(ctrk) * self.cmd_len
            with np.errstate(invalid="ignore", divide="ignore"):
                vec[:, 2] = np.where(cgs > 0, cvs * self.cmd_len / cgs, 0.0)
            self._arrows(f"world/ownship/cmd/{'exec' if name == 'cmd' else name}", np.zeros((n, 3)), vec)

        # intruders, per-intruder plots
        m = c.m
        ipos = np.stack([c.i("intr_x"), c.i("intr_y"), c.i("intr_z")], axis=-1)  # (n, M, 3)
        igs, itrk, ivs = c.i("intr_gs"), c.i("intr_trk_deg"), c.i("intr_vs")
        ivel = _unit_enu(itrk) * igs[..., None]
        ivel[..., 2] = ivs
        alert = np.nan_to_num(c.i("alert_level")).astype(np.int64).clip(0, 3)
        wcv = np.nan_to_num(c.i("wcv")).astype(bool)
        rng = c.i("range_m")
        for j in range(m):
            if j not in self.known_intruders:
                self._intruder_static(j)
            ok = np.all(np.isfinite(ipos[:, j]), axis=-1)
            colors = np.where(wcv[:, j, None], ALERT_COLORS[3], ALERT_COLORS[alert[:, j]])
            labels = [f"#{j} {_fmt(x / 1000.0, ' km')}" for x in rng[:, j]]
            self._send(f"world/intruders/{j}", None,
                       rr.Points3D.columns(positions=ipos[ok, j], colors=colors[ok], radii=np.full(ok.sum(), -7.0),
                                           labels=[lb for lb, o in zip(labels, ok) if o]).partition(ok.astype(np.int64)))
            self._arrows(f"world/intruders/{j}/velocity", ipos[:, j], ivel[:, j] * LEAD_S)
            self._scalar(f"plots/range/{j}", rng[:, j])
            self._scalar(f"plots/hmd/{j}", c.i("hmd_m")[:, j])
            self._scalar(f"plots/dh/{j}", c.i("dh_m")[:, j])
            self._scalar(f"plots/tau_mod/{j}", c.i("tau_mod_s")[:, j])
            self._scalar(f"plots/alert/{j}", c.i("alert_level")[:, j])
            if self.wait_lookup is not None:
                self._wait_lookup(j, own, own_v, ipos[:, j], ivel[:, j])
        self._scalar("plots/hmd/threshold", np.full(n, th.dthr))
        self._scalar("plots/tau_mod/threshold", np.full(n, th.tthr))
        self._scalar("plots/dh/zthr_up", np.full(n, th.zthr))
        self._scalar("plots/dh/zthr_down", np.full(n, -th.zthr))

        # trails (last trail_s seconds, carried across batches)
        self._trails(t, own, ipos)

        # well clear volume colour, bands
        any_wcv = wcv.any(axis=1) if m else np.zeros(n, bool)
        self._send("world/ownship/well_clear", None,
                   rr.Cylinders3D.columns(colors=np.where(any_wcv[:, None], WC_VIOLATED, WC_OK).astype(np.uint8)))
        self._bands(c)

        # decisions, state lanes, scalars
        self._decisions(c, t)
        self._send("status/authority", None, rr.StateChange.columns(state=auth))
        self._send("status/decision", None, rr.StateChange.columns(state=c.s("decision")))
        self._scalar("plots/wait/wait_s", c.f("wait_s"))
        self._scalar("plots/delay/up", c.f("delay_up_s"))
        self._scalar("plots/delay/down", c.f("delay_down_s"))
        self._scalar("plots/sm/pilot", c.f("sm_pilot"))
        self._scalar("plots/sm/exec", c.f("sm_exec"))
        self.steps_logged += n

    def _wait_lookup(self, j: int, own, own_v, ipos, ivel) -> None:
        from .frames import to_paper_state

        ok = np.all(np.isfinite(ipos), axis=-1) & np.all(np.isfinite(own_v), axis=-1)
        w = np.full(len(ok), np.nan)
        if ok.any():
            w[ok] = np.asarray(self.wait_lookup(to_paper_state(own[ok], own_v[ok], ipos[ok], ivel[ok])), float)
        self._scalar(f"plots/wait/map/{j}", w)

    def _trails(self, t: np.ndarray, own: np.ndarray, ipos: np.ndarray) -> None:
        rr = _rr()
        n, m = ipos.shape[0], ipos.shape[1]
        own_strips, intr_strips = [], [[] for _ in range(m)]
        for k in range(n):
            self.hist_t.append(t[k])
            self.hist_own.append(own[k].astype(np.float32))
            self.hist_intr.append(ipos[k].astype(np.float32))
            while self.hist_t and self.hist_t[0] < t[k] - self.trail_s:
                self.hist_t.popleft()
                self.hist_own.popleft()
                self.hist_intr.popleft()
            o = np.array(self.hist_own)
            own_strips.append(o[np.all(np.isfinite(o), axis=-1)])
            for j in range(m):
                p = np.array([h[j] if j < len(h) else (np.nan,) * 3 for h in self.hist_intr], np.float32)
                intr_strips[j].append(p[np.all(np.isfinite(p), axis=-1)])
        self._send("world/ownship_trail", None, rr.LineStrips3D.columns(strips=own_strips))
        for j in range(m):
            self._send(f"world/intruders/{j}/trail", None, rr.LineStrips3D.columns(strips=intr_strips[j]))

    def _bands(self, c: StepColumns) -> None:
        rr = _rr()
        strips, colors, radii, lengths = [], [], [], []
        for row in c.bands:
            lengths.append(len(row))
            for lo, hi, region in row:
                strips.append(_arc(lo, hi, self.band_radius))
                colors.append(REGION_COLORS.get(region, REGION_COLORS["none"]))
                radii.append(REGION_WIDTH.get(region, -1.5))
        cols = rr.LineStrips3D.columns(strips=strips, colors=np.array(colors, np.uint8).reshape(-1, 4),
                                       radii=np.array(radii, np.float32))
        self._send("world/ownship/bands", None, cols.partition(np.array(lengths, np.int64)))

    def _decisions(self, c: StepColumns, t: np.ndarray) -> None:
        rr = _rr()
        texts, levels, idx = [], [], []
        seg_lowc, seg_nmac = c.b("lowc"), c.b("nmac")
        for k in range(c.n):
            text, level = decision_text(c, k)
            if text:
                texts.append(text)
                levels.append(level)
                idx.append(k)
            for flag, prev, what in ((seg_lowc[k], self.prev_lowc, "LoWC: well clear lost"),
                                     (seg_nmac[k], self.prev_nmac, "NMAC")):
                if flag and not prev:
                    texts.append(f"{what} on [{t[k]:.0f} s, {t[k] + 1:.0f} s]")
                    levels.append("CRITICAL")
                    idx.append(k)
            self.prev_lowc, self.prev_nmac = bool(seg_lowc[k]), bool(seg_nmac[k])
        if idx:
            ix = np.array(idx)
            self.rec.send_columns("decisions", indexes=[rr.TimeColumn("sim_time", duration=self._t[ix]),
                                                        rr.TimeColumn("step", sequence=self._step[ix])],
                                  columns=rr.TextLog.columns(text=texts, level=levels))


def _rr():
    import rerun as rr

    return rr


# --------------------------------------------------------------------------------------------
# blueprint


def blueprint(center: "Iterable[float] | None" = None, extent_m: float = 8000.0, top_height_m: float = 6000.0):
    """Default layout: 3-D view (looking at ``center`` from ``extent_m`` away), ownship-centred top-down
    view (from ``top_height_m`` above), decision log, plots, state lanes."""
    import rerun as rr
    import rerun.blueprint as rrb

    cx, cy, cz = (0.0, 0.0, 0.0) if center is None else (float(v) for v in center)
    d = max(float(extent_m), 3000.0)
    view3d = rrb.Spatial3DView(
        name="Encounter 3-D", origin="/world",
        eye_controls=rrb.EyeControls3D(position=[cx - 0.6 * d, cy - 0.9 * d, cz + 0.5 * d], look_target=[cx, cy, cz],
                                       eye_up=[0, 0, 1]),
        line_grid=rrb.LineGrid3D(visible=False))
    top = rrb.Spatial3DView(
        name="Top-down (ownship-centred)", origin="/world/ownship",
        contents=["+ /world/**"],
        eye_controls=rrb.EyeControls3D(position=[0.0, -1.0, top_height_m], look_target=[0.0, 0.0, 0.0],
                                       eye_up=[0, 1, 0]),
        line_grid=rrb.LineGrid3D(visible=False))
    whole = rrb.VisibleTimeRange("sim_time", start=rrb.TimeRangeBoundary.infinite(),
                                 end=rrb.TimeRangeBoundary.infinite())

    def ts(name: str, *paths: str):
        return rrb.TimeSeriesView(name=name, origin="/plots", contents=[f"+ /plots/{p}/**" for p in paths],
                                  plot_legend=rrb.PlotLegend(corner="RightTop"), time_ranges=whole,
                                  axis_x=rrb.TimeAxis(view_range=rr.TimeRange(start=rrb.TimeRangeBoundary.infinite(),
                                                                               end=rrb.TimeRangeBoundary.infinite())))

    plots = rrb.Grid(ts("Range, HMD [m]", "range", "hmd"), ts("d_h [m]", "dh"), ts("tau_mod [s]", "tau_mod"),
                     ts("Wait time [s]", "wait"), ts("Link delay [s]", "delay"), ts("SM [s]", "sm"),
                     grid_columns=2)
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(view3d,
                         rrb.Horizontal(top, rrb.TextLogView(name="Decisions", origin="/decisions"), column_shares=[1, 1]),
                         row_shares=[3, 2]),
            rrb.Vertical(plots, rrb.StateTimelineView(name="Authority / decision", origin="/status"), row_shares=[5, 1]),
            column_shares=[3, 2]),
        rrb.TimePanel(timeline="sim_time", playback_speed=8.0),
        collapse_panels=True)


# --------------------------------------------------------------------------------------------
# sinks


@dataclass
class SinkOptions:
    """Where a recording goes. All off = visualisation disabled (Rerun is not touched)."""

    rrd: "str | os.PathLike | None" = None  #: write an .rrd file (atomically, on close)
    spawn: bool = False  #: start the native viewer (needs a display)
    connect: "str | None" = None  #: gRPC URL of a running viewer, e.g. rerun+http://127.0.0.1:9876/proxy
    serve_web: bool = False  #: start the web viewer (the rerun binary) on ``bind``
    bind: str = "127.0.0.1"
    web_port: int = WEB_HTTP_PORT
    grpc_port: int = WEB_GRPC_PORT
    spawn_port: int = SPAWN_PORT
    overwrite: bool = False  #: replace an existing .rrd
    deterministic: bool = False  #: ChunkBatcherConfig.NEVER (identical files run to run)
    app_id: str = APP_ID
    #: where the .rrd is written before the atomic rename (default: a fresh name next to ``rrd``); a
    #: :class:`BackgroundRecorder` picks it so that its owner can remove it if the helper is killed
    rrd_tmp: "str | os.PathLike | None" = None

    @property
    def enabled(self) -> bool:
        return bool(self.rrd or self.spawn or self.connect or self.serve_web)


def has_display() -> bool:
    """True if a native window can be opened (always on macOS/Windows; DISPLAY/WAYLAND elsewhere)."""
    if sys.platform == "darwin" or os.name == "nt":
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY") or os.environ.get("WAYLAND_SOCKET"))


def _url_host_port(url: str) -> tuple[str, int]:
    u = urllib.parse.urlparse(url)
    if not u.scheme.startswith("rerun") or not u.hostname:
        raise UsageError(f"--connect URL {url!r} is not a Rerun gRPC URL like rerun+http://127.0.0.1:9876/proxy")
    return u.hostname, u.port or SPAWN_PORT


def _port_open(host: str, port: int, timeout: float = 0.5) -> bool:
    try:
        with socket.create_connection((host, port), timeout=timeout):
            return True
    except OSError:
        return False


def rerun_binary() -> str:
    """Path of the real rerun viewer binary (not the Python wrapper script)."""
    import rerun_cli

    exe = "rerun.exe" if os.name == "nt" else "rerun"
    return str(Path(rerun_cli.__file__).parent / exe)


class WebServer:
    """The rerun binary serving the web viewer and a gRPC proxy on ``bind`` (own process group)."""

    def __init__(self, bind: str = "127.0.0.1", grpc_port: int = WEB_GRPC_PORT, web_port: int = WEB_HTTP_PORT,
                 rrd: "str | None" = None, startup_s: float = 20.0):
        self.bind, self.grpc_port, self.web_port = bind, grpc_port, web_port
        host = "127.0.0.1" if bind in ("0.0.0.0", "::") else bind
        self.grpc_url = f"rerun+http://{host}:{grpc_port}/proxy"
        self.url = f"http://{host}:{web_port}/?url={urllib.parse.quote(self.grpc_url, safe='')}"
        for port in (grpc_port, web_port):
            if _port_open(host, port, 0.2):
                raise OSError(f"port {port} on {host} is already in use")
        cmd = [rerun_binary(), "--serve-web", "--bind", bind, "--port", str(grpc_port),
               "--web-viewer-port", str(web_port)] + ([str(rrd)] if rrd else [])
        self.proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                     stderr=subprocess.DEVNULL, start_new_session=True)
        atexit.register(self.stop)
        deadline = time.monotonic() + startup_s
        while not (_port_open(host, grpc_port) and _port_open(host, web_port)):
            if self.proc.poll() is not None or time.monotonic() > deadline:
                self.stop()
                raise OSError(f"the rerun web viewer did not start on {host}:{grpc_port}/{web_port}")
            time.sleep(0.1)

    def alive(self) -> bool:
        return self.proc.poll() is None

    def stop(self) -> None:
        """Terminate the server's process group (SIGTERM, then SIGKILL after 5 s)."""
        if self.proc.poll() is not None:
            return
        try:
            os.killpg(self.proc.pid, signal.SIGTERM)
            self.proc.wait(timeout=5.0)
        except subprocess.TimeoutExpired:
            os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait()
        except ProcessLookupError:
            pass


def check_rrd_path(path: "str | os.PathLike", overwrite: bool = False) -> Path:
    """``path`` as a Path if an .rrd can be written there; OutputError naming the problem otherwise."""
    rrd = Path(path)
    if rrd.is_dir():
        raise OutputError(f"{rrd} is a directory, not an .rrd file path")
    if rrd.exists() and not overwrite:
        raise OutputError(f"{rrd} exists; refusing to overwrite (use --force or another path)")
    parent = rrd.parent
    if not parent.is_dir() or not os.access(parent, os.W_OK):
        raise OutputError(f"cannot write {rrd}: directory {parent} is missing or not writable")
    return rrd


class Recording:
    """A ``RecordingStream`` attached to the sinks of :class:`SinkOptions` (file, viewer, web).

    Raises only for a bad explicit request (an .rrd that exists without ``overwrite``, an unwritable
    directory, a malformed ``connect`` URL); everything else that goes wrong is a :class:`VizWarning`
    and leaves ``rec`` None (disabled).
    """

    def __init__(self, sinks: "SinkOptions | None" = None, recording_id: "str | None" = None, blueprint_=None):
        self.sinks = sinks or SinkOptions()
        self.rec = None
        self.web: "WebServer | None" = None
        self.rrd_path: "Path | None" = None
        self._tmp: "Path | None" = None
        self._closed = False
        if self.sinks.rrd:
            self.rrd_path = check_rrd_path(self.sinks.rrd, self.sinks.overwrite)
        if self.sinks.connect:
            _url_host_port(self.sinks.connect)  # a malformed URL is a usage error, not a missing viewer
        if not self.sinks.enabled:
            return
        try:
            self._open(recording_id, blueprint_)
        except Exception as exc:  # visualisation must never stop the caller
            _warn(f"Rerun logging disabled: {type(exc).__name__}: {exc}")
            self._discard()

    def _open(self, recording_id, blueprint_) -> None:
        import rerun as rr

        o = self.sinks
        batcher = rr.ChunkBatcherConfig.NEVER() if o.deterministic else None
        rec = rr.RecordingStream(o.app_id, recording_id=recording_id, batcher_config=batcher)
        if not rec.is_enabled():
            _warn("Rerun is disabled in the environment (RERUN=off); no visualisation is written")
            return
        rec.set_log_time_enabled(False)
        sinks: list = []
        if self.rrd_path is not None:
            if o.rrd_tmp is not None:
                self._tmp = Path(o.rrd_tmp)
            else:
                fd, tmp = tempfile.mkstemp(prefix=f".{self.rrd_path.name}.", suffix=".tmp", dir=self.rrd_path.parent)
                os.close(fd)
                self._tmp = Path(tmp)
            sinks.append(rr.FileSink(str(self._tmp)))
        if o.connect:
            host, port = _url_host_port(o.connect)
            if _port_open(host, port):
                sinks.append(rr.GrpcSink(o.connect))
            else:
                _warn(f"no Rerun viewer at {o.connect}; live view disabled")
        if o.spawn:
            if not has_display():
                _warn("--spawn-viewer needs a display (DISPLAY/WAYLAND_DISPLAY unset); live view skipped "
                      "(use --serve-web or --rrd instead)")
            else:
                try:
                    rec.spawn(port=o.spawn_port, connect=False)
                    sinks.append(rr.GrpcSink(f"rerun+http://127.0.0.1:{o.spawn_port}/proxy"))
                except Exception as exc:
                    _warn(f"could not spawn the Rerun viewer: {exc}")
        if o.serve_web:
            try:
                self.web = WebServer(o.bind, o.grpc_port, o.web_port)
                sinks.append(rr.GrpcSink(self.web.grpc_url))
            except Exception as exc:
                _warn(f"could not start the Rerun web viewer: {exc}")
        if not sinks:
            return
        rec.set_sinks(*sinks, default_blueprint=blueprint_)
        self.rec = rec

    def _discard(self) -> None:
        self.rec = None
        if self._tmp is not None:
            self._tmp.unlink(missing_ok=True)
        if self.web is not None:
            self.web.stop()

    def close(self, keep_serving: bool = False, commit: bool = True) -> "Path | None":
        """Flush, disconnect, move the .rrd into place (unless ``commit`` is False); return its path."""
        if self._closed:
            return self.rrd_path if self.rrd_path is not None and self.rrd_path.exists() and commit else None
        self._closed = True
        written = None
        if self.rec is not None:
            try:
                self.rec.flush()
                self.rec.disconnect()
            except Exception as exc:
                _warn(f"Rerun flush failed: {exc}")
                commit = False
            if commit and self._tmp is not None and self._tmp.exists() and self._tmp.stat().st_size > 0:
                try:
                    with open(self._tmp, "rb+") as fh:
                        os.fsync(fh.fileno())
                    umask = os.umask(0)
                    os.umask(umask)
                    os.chmod(self._tmp, 0o666 & ~umask)  # mkstemp makes 0600; a normal output file
                    os.replace(self._tmp, self.rrd_path)
                    written = self.rrd_path
                except OSError as exc:
                    _warn(f"cannot write {self.rrd_path}: {exc.strerror or exc}")
        if self._tmp is not None:
            self._tmp.unlink(missing_ok=True)
        if not keep_serving and self.web is not None:
            self.web.stop()
        return written


class EncounterLogger:
    """One Rerun recording of one encounter; see the module docstring."""

    def __init__(self, sinks: "SinkOptions | None" = None, preset: "str | Thresholds | None" = None,
                 encounter_id: "int | str | None" = None, wait_lookup: "Callable[[np.ndarray], np.ndarray] | None" = None,
                 center: "Iterable[float] | None" = None, extent_m: float = 6000.0, flush_interval_s: float = 0.25,
                 defer_blueprint: bool = False):
        self.th = get_thresholds(preset)
        self.encounter_id = encounter_id
        self.flush_interval_s = flush_interval_s
        self._emitter: "_Emitter | None" = None
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
                self._emitter = _Emitter(self._recording.rec, self.th, wait_lookup)
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
            _warn(msg)
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

    def wait_serving(self) -> None:
        """Block until Ctrl-C while the web viewer runs, then stop it."""
        try:
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


# --------------------------------------------------------------------------------------------
# whole step logs


def select_encounter(table: pa.Table, encounter_id: "int | None" = None) -> tuple[pa.Table, "int | None"]:
    """The rows of one encounter in step order (the only one, or ``encounter_id``)."""
    if "encounter_id" not in table.column_names:
        return table, encounter_id
    ids = np.asarray(table.column("encounter_id").to_numpy(zero_copy_only=False))
    uniq = np.unique(ids)
    if encounter_id is None:
        if uniq.size > 1:
            shown = ", ".join(str(int(x)) for x in uniq[:8]) + (" ..." if uniq.size > 8 else "")
            raise UsageError(f"the step log holds {uniq.size} encounters ({shown}); choose one with --encounter")
        encounter_id = int(uniq[0]) if uniq.size else None
    elif int(encounter_id) not in set(uniq.tolist()):
        raise UsageError(f"encounter {encounter_id} is not in the step log (it holds {uniq.size} encounters)")
    rows = np.flatnonzero(ids == encounter_id) if encounter_id is not None else np.arange(table.num_rows)
    sub = table.take(pa.array(rows))
    if "step" in sub.column_names:
        sub = sub.take(pa.array(np.argsort(np.asarray(sub.column("step").to_numpy(zero_copy_only=False)), kind="stable")))
    return sub, encounter_id


def focus(table: pa.Table) -> tuple[list[float], float]:
    """Camera target (midpoint of ownship and intruder at the closest approach) and a view size, m."""
    c = StepColumns.from_table(table.select([n for n in table.column_names
                                             if n in ("own_x", "own_y", "own_z", "intr_x", "intr_y", "intr_z",
                                                      "range_m")]))
    own = np.stack([c.f("own_x"), c.f("own_y"), c.f("own_z")], axis=-1)
    ok = np.all(np.isfinite(own), axis=1)
    if not ok.any():
        return [0.0, 0.0, 0.0], 8000.0
    rng = c.i("range_m")
    k = int(np.nanargmin(np.nanmin(rng, axis=1))) if rng.size and np.isfinite(rng).any() else int(np.flatnonzero(ok)[-1])
    center = own[k]
    if rng.size and np.isfinite(rng[k]).any():
        j = int(np.nanargmin(rng[k]))
        intr = np.array([c.i("intr_x")[k, j], c.i("intr_y")[k, j], c.i("intr_z")[k, j]])
        if np.all(np.isfinite(intr)):
            half = (intr - own[k]) / 2.0
            norm = float(np.linalg.norm(half))
            center = own[k] + (half if norm <= 1500.0 else half * (1500.0 / norm))
    return center.tolist(), 6000.0


def predicted_focus(row: Mapping[str, Any], horizon_s: float = 600.0) -> tuple[list[float], float]:
    """Camera target for a live view from the first step-log row: :func:`focus` at the straight-line
    closest approach of the nearest intruder (predicted from the row's positions and velocities)."""
    r = _normalise(row)

    def g(k):
        v = r.get(k)
        return np.nan if v is None else float(v)

    own = np.array([g("own_x"), g("own_y"), g("own_z")])
    if not np.all(np.isfinite(own)):
        return [0.0, 0.0, 0.0], 8000.0
    own_v = np.append(_unit_enu(np.array(g("own_trk_deg")))[:2] * g("own_gs"), g("own_vs"))
    best = None
    for j in range(len(r.get("intr_x") or [])):
        p = np.array([float(r[k][j]) if r.get(k) and r[k][j] is not None else np.nan
                      for k in ("intr_x", "intr_y", "intr_z")])
        gs, trk, vs = (float(r[k][j]) if r.get(k) and r[k][j] is not None else np.nan
                       for k in ("intr_gs", "intr_trk_deg", "intr_vs"))
        v = np.append(_unit_enu(np.array(trk))[:2] * gs, vs)
        s, dv = p - own, v - own_v
        if not (np.all(np.isfinite(s)) and np.all(np.isfinite(dv))):
            continue
        t = float(np.clip(-np.dot(s[:2], dv[:2]) / max(float(np.dot(dv[:2], dv[:2])), 1e-9), 0.0, horizon_s))
        d = float(np.linalg.norm((s + dv * t)[:2]))
        if best is None or d < best[0]:
            best = (d, own + own_v * t, p + v * t)
    if best is None:
        return own.tolist(), 8000.0
    _, o, i = best
    half = (i - o) / 2.0
    norm = float(np.linalg.norm(half))
    return (o + (half if norm <= 1500.0 else half * (1500.0 / norm))).tolist(), 6000.0


def log_steplog(table: "pa.Table | pa.RecordBatch", sinks: SinkOptions, encounter_id: "int | None" = None,
                preset: "str | Thresholds | None" = None,
                wait_lookup: "Callable[[np.ndarray], np.ndarray] | None" = None,
                keep_serving: bool = False, until_s: "float | None" = None) -> "tuple[Path | None, EncounterLogger]":
    """Log one encounter of a step log into ``sinks``; return (the .rrd path or None, the closed logger).

    ``until_s`` keeps only steps with ``t <= until_s`` (a viewer opens a file at its last step, so this
    is how to show the picture at a given moment).
    """
    if isinstance(table, pa.RecordBatch):
        table = pa.Table.from_batches([table])
    table, encounter_id = select_encounter(table, encounter_id)
    if until_s is not None and "t" in table.column_names:
        t = np.asarray(table.column("t").to_numpy(zero_copy_only=False), float)
        table = table.filter(pa.array(t <= until_s))
    center, extent = focus(table)
    logger = EncounterLogger(sinks, preset=preset, encounter_id=encounter_id, wait_lookup=wait_lookup,
                             center=center, extent_m=extent)
    logger.log_table(table)
    return logger.close(keep_serving=keep_serving), logger


# --------------------------------------------------------------------------------------------
# wait maps


def wait_colors(w: np.ndarray, w_max: "float | None" = None) -> np.ndarray:
    """RGBA colours for wait times: 0 s dark blue -> w_max yellow (viridis-like), nan grey."""
    w = np.asarray(w, float)
    top = w_max if w_max is not None else (np.nanmax(w) if np.isfinite(w).any() else 1.0)
    x = np.clip(w / max(top, 1e-9), 0.0, 1.0)
    stops = np.array([[68, 1, 84], [59, 82, 139], [33, 145, 140], [94, 201, 98], [253, 231, 37]], float)
    pos = x * (len(stops) - 1)
    i0 = np.clip(np.floor(pos).astype(int), 0, len(stops) - 2)
    frac = (pos - i0)[..., None]
    rgb = stops[i0] * (1 - frac) + stops[i0 + 1] * frac
    rgba = np.concatenate([rgb, np.full(rgb.shape[:-1] + (1,), 255.0)], axis=-1)
    rgba[~np.isfinite(w)] = (128, 128, 128, 80)
    return rgba.astype(np.uint8)


def waitmap_slice(waitmap, vi: float, vh: float, theta_deg: float, turn_rate_deg: float = 0.0
                  ) -> tuple[np.ndarray, np.ndarray, dict]:
    """Grid nodes (dX, dY, d_h) ``(K, 3)`` and their wait times ``(K,)`` at the grid node nearest to
    (v_i, V_h, theta) of a :class:`~daa_sil.waitmap.WaitMap` (or a family: the map nearest ``turn_rate_deg``)."""
    wm = waitmap.map_for(turn_rate_deg) if hasattr(waitmap, "map_for") else waitmap
    g = wm.grid
    idx = []
    chosen = {}
    for name, val in (("vi", vi), ("vh", vh), ("theta", np.radians(theta_deg))):
        ax = g.axis(name)
        pts = ax.values
        d = np.abs(((pts - val + np.pi) % (2 * np.pi)) - np.pi) if ax.periodic else np.abs(pts - val)
        k = int(np.argmin(d))
        idx.append(k)
        chosen[name] = float(np.degrees(pts[k])) if name == "theta" else float(pts[k])
    dx, dy, dh = (g.axis(n).values for n in ("dx", "dy", "dh"))
    mesh = np.stack(np.meshgrid(dx, dy, dh, indexing="ij"), axis=-1).reshape(-1, 3)
    w = np.asarray(wm.wait_s)[:, :, :, idx[0], idx[1], idx[2]].reshape(-1)
    chosen["turn_rate_deg"] = float(wm.turn_rate_deg)
    chosen["preset"] = wm.params.preset
    return mesh, w, chosen


def log_waitmap(rec, waitmap, vi: float = 155.0, vh: float = 0.0, theta_deg: float = 180.0,
                turn_rate_deg: float = 0.0, entity: str = "waitmap") -> dict:
    """Log a wait-map slice as a 3-D point cloud over (dX, dY, d_h) coloured by wait time (paper frame:
    ownship at the origin flying +X, Y to the left, d_h up); return the slice actually shown."""
    import rerun as rr

    pts, w, chosen = waitmap_slice(waitmap, vi, vh, theta_deg, turn_rate_deg)
    title = (f"wait map (turn {chosen['turn_rate_deg']:+.1f} deg/s, {chosen['preset']}) at v_i = {chosen['vi']:.0f} m/s, "
             f"V_h = {chosen['vh']:+.1f} m/s, theta = {chosen['theta']:.0f} deg")
    log_waitmap_points(rec, pts, w, entity=entity, title=title)
    th = get_thresholds(chosen["preset"])
    rec.log(f"{entity}/well_clear", rr.Cylinders3D(lengths=[2 * th.zthr], radii=[th.dthr], colors=[WC_OK],
                                                   fill_mode=rr.components.FillMode.MajorWireframe), static=True)
    return chosen


def write_waitmap(waitmap, sinks: SinkOptions, vi: float = 155.0, vh: float = 0.0, theta_deg: float = 180.0,
                  turn_rate_deg: float = 0.0, keep_serving: bool = False) -> "tuple[Path | None, dict, Recording]":
    """:func:`log_waitmap` into the sinks of ``sinks`` (own recording and layout)."""
    import rerun.blueprint as rrb

    bp = rrb.Blueprint(rrb.Horizontal(rrb.Spatial3DView(name="Wait map", origin="/waitmap"),
                                      rrb.TextDocumentView(name="Slice", origin="/waitmap/info"),
                                      column_shares=[4, 1]), collapse_panels=True)
    recording = Recording(sinks, "waitmap", bp)
    chosen: dict = {}
    if recording.rec is not None:
        try:
            chosen = log_waitmap(recording.rec, waitmap, vi, vh, theta_deg, turn_rate_deg)
        except (UsageError, ValueError, IndexError) as exc:
            recording.close(commit=False)
            raise UsageError(f"cannot show this wait-map slice: {exc}") from None
    return recording.close(keep_serving=keep_serving), chosen, recording


def log_waitmap_points(rec, points: np.ndarray, wait_s: np.ndarray, entity: str = "waitmap",
                       title: str = "", radius: float = -5.0) -> None:
    """Log wait times at paper-frame points ``(K, 3)`` = (dX, dY, d_h) as a coloured point cloud."""
    import rerun as rr

    pts = np.asarray(points, float).reshape(-1, 3)
    w = np.asarray(wait_s, float).reshape(-1)
    rec.log(entity, rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    rec.log(f"{entity}/points", rr.Points3D(pts, colors=wait_colors(w), radii=radius,
                                            labels=[f"{x:.1f} s" if np.isfinite(x) else "n/a" for x in w],
                                            show_labels=False), static=True)
    rec.log(f"{entity}/ownship", rr.Arrows3D(origins=[[0.0, 0.0, 0.0]], vectors=[[1000.0, 0.0, 0.0]],
                                             colors=[OWN_COLOR], labels=["ownship (+X)"]), static=True)
    finite = w[np.isfinite(w)]
    summary = (f"{title}: {w.size} states, wait {finite.min():.1f}..{finite.max():.1f} s (mean {finite.mean():.1f} s)"
               if finite.size else f"{title}: {w.size} states, no finite wait time")
    rec.log(f"{entity}/info", rr.TextDocument(summary), static=True)
