"""Wait-map views: a slice of a :class:`~daa_sil.waitmap.WaitMap` as a 3-D point cloud over
(dX, dY, d_h) in m, coloured by wait time in s."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import UsageError
from daa_sil.geometry.thresholds import get_thresholds
from .sinks import Recording, SinkOptions
from .style import OWN_COLOR, WC_OK

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
    import rerun as rr  # lazy: start-up time

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
    import rerun.blueprint as rrb  # lazy: start-up time

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
    import rerun as rr  # lazy: start-up time

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
