"""Whole step logs: pick one encounter, aim the camera (m), log it into the sinks."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np
import pyarrow as pa

from daa_sil.errors import UsageError
from daa_sil.geometry.thresholds import Thresholds
from .draw import track_unit_enu
from .logger import EncounterLogger
from .records import StepColumns, normalise_row
from .sinks import SinkOptions

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
    r = normalise_row(row)

    def g(k):
        v = r.get(k)
        return np.nan if v is None else float(v)

    own = np.array([g("own_x"), g("own_y"), g("own_z")])
    if not np.all(np.isfinite(own)):
        return [0.0, 0.0, 0.0], 8000.0
    own_v = np.append(track_unit_enu(np.array(g("own_trk_deg")))[:2] * g("own_gs"), g("own_vs"))
    best = None
    for j in range(len(r.get("intr_x") or [])):
        p = np.array([float(r[k][j]) if r.get(k) and r[k][j] is not None else np.nan
                      for k in ("intr_x", "intr_y", "intr_z")])
        gs, trk, vs = (float(r[k][j]) if r.get(k) and r[k][j] is not None else np.nan
                       for k in ("intr_gs", "intr_trk_deg", "intr_vs"))
        v = np.append(track_unit_enu(np.array(trk))[:2] * gs, vs)
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
