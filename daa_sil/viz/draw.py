"""Geometry and text helpers: compass tracks as ENU unit vectors, band arcs (m), decision log lines."""

from __future__ import annotations

import numpy as np

from .records import StepColumns

DECISION_LEVEL = {"wait": "INFO", "pilot": "INFO", "blend": "INFO", "no_wait": "WARN", "daa": "WARN",
                  "daa_override": "WARN", "stale": "ERROR", "link_lost": "ERROR"}


def track_unit_enu(trk_deg: np.ndarray) -> np.ndarray:
    """ENU unit vectors ``(..., 3)`` (east, north, 0) of compass tracks ``trk_deg`` (deg, clockwise from north)."""
    r = np.radians(trk_deg)
    return np.stack([np.sin(r), np.cos(r), np.zeros_like(r)], axis=-1)


def track_arc(lo_deg: float, hi_deg: float, radius: float, step_deg: float = 3.0) -> np.ndarray:
    """Points ``(K, 3)`` of a compass-track arc (deg, clockwise from ``lo`` to ``hi``) at ``radius`` (m) around the
    origin, one every ``step_deg`` at most."""
    span = (hi_deg - lo_deg) % 360.0
    if span == 0.0 and hi_deg != lo_deg:
        span = 360.0
    k = max(2, int(np.ceil(span / step_deg)) + 1)
    ang = np.radians(lo_deg + np.linspace(0.0, span, k))
    return np.stack([radius * np.sin(ang), radius * np.cos(ang), np.zeros(k)], axis=-1).astype(np.float32)


def fmt_value(x: float, unit: str = "", prec: int = 1) -> str:
    """``x`` with ``prec`` decimals and ``unit`` appended; ``n/a`` when not finite."""
    return "n/a" if not np.isfinite(x) else f"{x:.{prec}f}{unit}"


def decision_text(cols: StepColumns, k: int) -> tuple[str, str]:
    """Text and level of row ``k``'s decision (empty text for ``none``)."""
    d = cols.s("decision")[k]
    if d in ("none", "", "nan"):
        return "", ""
    rule, ws, sm_p, sm_x = cols.s("rule", "-")[k], cols.f("wait_s")[k], cols.f("sm_pilot")[k], cols.f("sm_exec")[k]
    age, projl = cols.f("pilot_cmd_age_s")[k], cols.b("projl")[k]
    cmd = (f"trk {fmt_value(cols.f('cmd_trk_deg')[k], '°', 0)} vs {fmt_value(cols.f('cmd_vs')[k], ' m/s')} "
           f"gs {fmt_value(cols.f('cmd_gs')[k], ' m/s')}")
    pilot = f"{cols.s('pilot_axis')[k]}/{cols.s('pilot_dir')[k]}"
    exe = f"{cols.s('exec_axis')[k]}/{cols.s('exec_dir')[k]}"
    if d == "wait":
        why = f"no fresh pilot command; w(S) = {fmt_value(ws, ' s')}, no ProjL -> hold the pilot course ({cmd})"
    elif d == "no_wait":
        why = (f"no fresh pilot command; w(S) = {fmt_value(ws, ' s')}, ProjL {'yes' if projl else 'no'} "
               f"-> DAA resolution ({cmd})")
    elif d == "pilot":
        why = f"pilot command {pilot} (age {fmt_value(age, ' s')}) SM = {fmt_value(sm_p, ' s')} > 0 -> execute ({cmd})"
    elif d == "blend":
        why = (f"pilot command {pilot} SM = {fmt_value(sm_p, ' s')} <= 0 -> blended by rule {rule} to {exe}, "
               f"SM = {fmt_value(sm_x, ' s')} ({cmd})")
    elif d == "daa_override":
        why = f"pilot command {pilot} SM = {fmt_value(sm_p, ' s')} <= 0, no blending -> DAA resolution ({cmd})"
    elif d == "daa":
        why = f"onboard DAA resolution {exe} ({cmd})"
    elif d == "stale":
        why = f"pilot command too old (age {fmt_value(age, ' s')}) -> not executed ({cmd})"
    elif d == "link_lost":
        why = f"no packet from the GCS -> link lost, onboard DAA ({cmd})"
    else:
        why = cmd
    label = {"no_wait": "no-wait", "blend": "blended", "daa_override": "DAA override", "daa": "DAA",
             "link_lost": "link lost"}.get(d, d)
    return f"{label}: {why}", DECISION_LEVEL.get(d, "INFO")
