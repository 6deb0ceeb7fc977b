"""The default Rerun viewer layout (blueprint); distances in m."""

from __future__ import annotations

from typing import Iterable

def blueprint(center: "Iterable[float] | None" = None, extent_m: float = 8000.0, top_height_m: float = 6000.0):
    """Default layout: 3-D view (looking at ``center`` from ``extent_m`` away), ownship-centred top-down
    view (from ``top_height_m`` above), decision log, plots, state lanes."""
    import rerun as rr  # lazy: start-up time
    import rerun.blueprint as rrb  # lazy: start-up time

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
