"""A step log of one encounter built from real geometry (daa_sil.geometry.kinematics / wellclear), for viz tests.

Ownship 55 m/s north at 1000 m; one intruder head-on from 20 km, 80 m/s south, 30 m above, 300 m
east. From t = 110 s the ownship turns right toward 060 deg (a DAA resolution). Range, HMD, d_h,
tau_mod, WCV, LoWC on each segment and the track bands (tracks whose straight-line projection
violates well clear within 55 s) are computed with the project's geometry core. The decision
fields follow the allocation rules loosely (pilot commands while alerting, waits in between).
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pytest

from daa_sil.geometry import wellclear as wc
from daa_sil.geometry.kinematics import AircraftState, Command, advance, fly_command
from daa_sil.geometry.thresholds import get_thresholds
from daa_sil.geometry.units import DEG

TRACKS = np.arange(0.0, 360.0, 5.0)


@pytest.fixture
def rerun_env(monkeypatch):
    """Rerun enabled and no display: a spawned viewer must fail cleanly (a warning), never hang."""
    monkeypatch.delenv("RERUN", raising=False)
    for var in ("DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET"):
        monkeypatch.delenv(var, raising=False)


def _bands(own: AircraftState, ipos: np.ndarray, ivel: np.ndarray, th) -> tuple[list, list, list]:
    vel = np.stack([own.gs * np.sin(TRACKS * DEG), own.gs * np.cos(TRACKS * DEG), np.full(TRACKS.size, own.vs)], -1)
    s, v = wc.relative(own.position()[None], vel, ipos[None], ivel[None])
    t_in, _ = wc.violation_interval(s, v, th, 0.0, 55.0)
    region = np.where(t_in <= 25.0, "near", np.where(t_in <= 40.0, "mid", np.where(t_in <= 55.0, "far", "none")))
    lo, hi, reg = [], [], []
    start = 0
    for k in range(1, TRACKS.size + 1):
        if k == TRACKS.size or region[k] != region[start]:
            lo.append(float(TRACKS[start]))
            hi.append(float(TRACKS[k - 1] + 5.0))
            reg.append(str(region[start]))
            start = k
    return lo, hi, reg


def make_steplog(n_steps: int = 240, encounter_id: int = 7, preset: str = "do365") -> pa.Table:
    """Step-log table (architecture.md column names) of one 1-s-step encounter."""
    th = get_thresholds(preset)
    own = AircraftState(0.0, 0.0, 1000.0, 55.0, 0.0, 0.0)
    intr = AircraftState(300.0, 20000.0, 1030.0, 80.0, np.pi, 0.0)
    rows: dict[str, list] = {k: [] for k in (
        "encounter_id", "step", "t", "own_x", "own_y", "own_z", "own_gs", "own_trk_deg", "own_vs",
        "intr_x", "intr_y", "intr_z", "intr_gs", "intr_trk_deg", "intr_vs", "range_m", "hmd_m", "dh_m",
        "tau_mod_s", "alert_level", "wcv", "intr_turn_est_dps", "decision", "rule", "authority", "wait_s", "projl",
        "decided_by", "wait_p_lowc", "wait_in_box", "wait_map_turn_dps", "pilot_cmd_received", "pilot_cmd_age_s", "sm_pilot", "sm_exec", "cmd_trk_deg", "cmd_vs", "cmd_gs",
        "pilot_trk_deg", "pilot_vs", "pilot_gs", "daa_trk_deg", "daa_vs", "daa_gs", "pilot_axis", "pilot_dir",
        "exec_axis", "exec_dir", "delay_up_s", "delay_down_s", "lowc", "nmac", "bands_trk_lo_deg",
        "bands_trk_hi_deg", "bands_trk_region")}
    resolution = Command(60.0 * DEG, 0.0, 55.0)
    for k in range(n_steps):
        t = float(k)
        s, v = wc.relative(own.position(), own.velocity(), intr.position(), intr.velocity())
        ttv = float(wc.time_to_violation(s, v, th, 75.0))
        alert = 3 if ttv <= 25 else 2 if ttv <= 55 else 1 if ttv <= 75 else 0
        active = alert >= 2
        turning = t >= 110.0
        cmd = resolution if turning else Command.hold(own)
        if active:
            decision = "pilot" if k % 5 == 0 else ("wait" if k % 5 in (1, 2) else "no_wait")
            if k % 7 == 0:
                decision = "blend"
        else:
            decision = "none"
        nxt_own = fly_command(own, cmd, 1.0)
        nxt_intr = advance(intr, dt=1.0)
        s1, _ = wc.relative(nxt_own.position(), nxt_own.velocity(), nxt_intr.position(), nxt_intr.velocity())
        lowc, nmac = wc.segment_events(s, s1, 1.0, th)
        lo, hi, reg = _bands(own, intr.position(), intr.velocity(), th)
        vals = {
            "encounter_id": encounter_id, "step": k, "t": t,
            "own_x": float(own.x), "own_y": float(own.y), "own_z": float(own.z), "own_gs": float(own.gs),
            "own_trk_deg": float(own.trk / DEG), "own_vs": float(own.vs),
            "intr_x": [float(intr.x)], "intr_y": [float(intr.y)], "intr_z": [float(intr.z)],
            "intr_gs": [float(intr.gs)], "intr_trk_deg": [float(intr.trk / DEG)], "intr_vs": [float(intr.vs)],
            "range_m": [float(wc.horizontal_range(s))], "hmd_m": [float(wc.hmd(s, v, 180.0))],
            "dh_m": [float(intr.z - own.z)], "tau_mod_s": [float(wc.tau_mod(s, v, th.dthr))],
            "alert_level": [alert], "wcv": [bool(wc.wcv(s, v, th))], "intr_turn_est_dps": [0.0],
            "decision": decision, "rule": "axis" if decision == "blend" else "-",
            "authority": "daa" if decision in ("no_wait", "blend") else ("waiting" if decision == "wait" else "pilot"),
            "wait_s": 6.0 - 0.02 * k if active else np.nan, "projl": decision == "no_wait",
            "decided_by": ("projl" if decision == "no_wait" else "neither") if decision in ("wait", "no_wait") else "none",
            "wait_p_lowc": 0.3 if active else np.nan, "wait_in_box": False,
            "wait_map_turn_dps": 0.0 if active else np.nan,
            "pilot_cmd_received": decision in ("pilot", "blend"), "pilot_cmd_age_s": 4.0 if active else np.nan,
            "sm_pilot": (20.0 - 0.1 * k) if active else np.nan, "sm_exec": (25.0 - 0.1 * k) if active else np.nan,
            "cmd_trk_deg": float(cmd.resolved(own).trk / DEG), "cmd_vs": 0.0, "cmd_gs": 55.0,
            "pilot_trk_deg": 30.0 if active else np.nan, "pilot_vs": 0.0 if active else np.nan,
            "pilot_gs": 55.0 if active else np.nan,
            "daa_trk_deg": 60.0 if active else np.nan, "daa_vs": 0.0 if active else np.nan,
            "daa_gs": 55.0 if active else np.nan,
            "pilot_axis": "horizontal" if active else "none", "pilot_dir": "right" if active else "none",
            "exec_axis": "horizontal" if active else "none", "exec_dir": "right" if active else "none",
            "delay_up_s": 4.0 + 0.5 * np.sin(k / 10.0), "delay_down_s": 4.0 + 0.5 * np.cos(k / 10.0),
            "lowc": bool(lowc), "nmac": bool(nmac),
            "bands_trk_lo_deg": lo, "bands_trk_hi_deg": hi, "bands_trk_region": reg,
        }
        for key, val in vals.items():
            rows[key].append(val)
        own, intr = nxt_own, nxt_intr
    types = {"encounter_id": pa.int64(), "step": pa.int32(), "alert_level": pa.list_(pa.int8()),
             "wcv": pa.list_(pa.bool_())}
    return pa.table({k: pa.array(v, types.get(k)) for k, v in rows.items()})


def records(table: pa.Table) -> list[dict]:
    """The table as per-step row dicts (what the SIL vehicle passes to ``log_step``)."""
    return table.to_pylist()
