"""``daa-sil daa``: onboard DAA for one ownship/intruder encounter: alert levels, bands, resolutions."""

from __future__ import annotations

import argparse
import json

import numpy as np

from ..daa import ALERT_NAMES, AXIS_NAMES, DIR_NAMES, DaaConfig, compute_bands, resolve
from ..errors import UsageError
from daa_sil.config.config_option import add_config_argument
from daa_sil.config.run_config import load_config
from daa_sil.config.settings import INTRUDERS
from daa_sil.files import to_jsonable
from daa_sil.geometry.kinematics import AircraftState
from daa_sil.geometry.thresholds import PRESETS
from daa_sil.geometry.units import FPM, KT
from .geometry import parse_state

EXAMPLES = """examples:
  # head-on, 6 km apart, the intruder passing 500 m to the right
  daa-sil daa --own 0,0,1000,0,55,0 --intruder 500,6000,1000,0,-55,0

  # two intruders, paper thresholds, JSON for a script
  daa-sil daa --own 0,0,1000,0,55,0 --intruder 500,6000,1000,0,-55,0 --intruder=-3000,2000,1100,60,0,-2 --preset paper --json

  # DAIDALUS v2.0.4 DO_365B_no_SUM.conf semantics (1 deg / 5 kt / 100 fpm grids, its horizons and recovery)
  daa-sil daa --own 0,0,1000,0,55,0 --intruder 5670.18,3933.31,772.05,-148.70,-65.81,1.64 --preset daidalus

States are "x,y,z,vx,vy,vz" in the ENU frame (m, m/s); write --intruder=-3000,... when a value
starts with a minus sign. Bands are printed in degrees (track, compass),
fpm (vertical speed) and kt (ground speed); JSON gives the same units with the unit in the key.
Regions: none (conflict free), mid (corrective), near (warning), recovery. Bands are intervals between
candidate values, each with the region of the values inside it (DAIDALUS's representation). A
resolution is the nearest conflict-free value on that side; "inf" / "-inf" means there is none on
that side, null that the current value is not in conflict.
Allowed ranges: |x|, |y| <= 1e7 m, z in [-1e4, 1e5] m, |vx|, |vy| <= 1000 m/s, |vz| <= 500 m/s.
"""

_UNITS = {"trk": (np.degrees, "deg"), "vs": (lambda v: np.asarray(v) / FPM, "fpm"),
          "gs": (lambda v: np.asarray(v) / KT, "kt")}


def register(sub) -> None:
    p = sub.add_parser("daa", help="alert levels, kinematic bands and resolutions for one encounter",
                       description="DAIDALUS-style onboard DAA: DO-365 alert level per intruder, kinematic "
                                   "track / vertical-speed / ground-speed bands and the resolutions.",
                       epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--own", required=True, metavar="X,Y,Z,VX,VY,VZ", help="ownship ENU state (m, m/s)")
    p.add_argument("--intruder", required=True, action="append", metavar="X,Y,Z,VX,VY,VZ",
                   help="intruder ENU state (m, m/s); repeat for several intruders")
    p.add_argument("--preset", default=None, help=f"DAA preset: {', '.join(PRESETS)} (default: the --config's "
                                                  "thresholds, else do365)")
    add_config_argument(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def daa_report(own: np.ndarray, intr: np.ndarray, preset: str = "do365", changes: "dict | None" = None) -> dict:
    """Alert levels, bands (intervals per axis) and resolutions as a JSON-ready dict (``changes``:
    DaaConfig fields set on top of the preset, as a configuration's ``daa`` section)."""
    cfg = DaaConfig.for_preset(preset, **(changes or {}))
    o = AircraftState.from_pos_vel(own[None, :3], own[None, 3:])
    i = AircraftState.from_pos_vel(intr[None, :, :3], intr[None, :, 3:])
    b = compute_bands(o, i, cfg)
    cmd, ax, dr = resolve(o, i, cfg, bands=b)
    out = {"preset": cfg.th.name, "alert_levels": [ALERT_NAMES[int(a)] for a in b.alert[0]], "bands": {},
           "resolutions": {}}
    for key, ab in zip(("trk", "vs", "gs"), b.axes()):
        conv, unit = _UNITS[key]
        out["bands"][f"{key}_{unit}"] = [[float(conv(lo)), float(conv(hi)), reg] for lo, hi, reg in ab.band_intervals(0)]
        out["resolutions"][ab.name] = {f"lo_{unit}": _res(conv(ab.res_lo[0])), f"hi_{unit}": _res(conv(ab.res_hi[0])),
                                       "preferred": {-1: "lo", 0: "none", 1: "hi"}[int(ab.preferred[0])]}
    out["daa_command"] = {"trk_deg": float(np.degrees(cmd.trk[0])), "vs_fpm": float(cmd.vs[0] / FPM),
                          "gs_kt": float(cmd.gs[0] / KT), "axis": AXIS_NAMES[int(ax[0])], "direction": DIR_NAMES[int(dr[0])]}
    return to_jsonable(out)


def _res(v) -> "float | str | None":
    """A resolution for JSON: the value, "inf" / "-inf" (none on that side) or None (no conflict)."""
    v = float(v)
    return v if np.isfinite(v) else (None if np.isnan(v) else ("inf" if v > 0 else "-inf"))


def run(args) -> int:
    own = parse_state(args.own, "--own")
    if len(args.intruder) > INTRUDERS.hi:  # as every other input: a scenario, a campaign
        raise UsageError(f"--intruder is given {len(args.intruder)} times; at most {INTRUDERS.hi} intruders "
                         f"(the range of every input, {INTRUDERS.help})")
    intr = np.array([parse_state(s, "--intruder") for s in args.intruder])
    rc = load_config(args.config) if args.config else None
    preset = args.preset or (rc.thresholds if rc else "do365")
    if preset.lower() not in PRESETS:
        raise UsageError(f"unknown --preset {preset!r}; allowed: {', '.join(PRESETS)}")
    if np.hypot(own[3], own[4]) <= 0:
        raise UsageError("--own needs a non-zero horizontal velocity (the track is undefined otherwise)")
    rep = daa_report(own, intr, preset.lower(), rc.daa if rc else None)
    if rc is not None:
        rep["config"] = to_jsonable(rc.with_(thresholds=preset.lower()).to_dict(full=True))
    if args.json:
        print(json.dumps(rep, sort_keys=True))
        return 0
    print(f"preset {rep['preset']}; alert level per intruder: {', '.join(rep['alert_levels'])}")
    for key, bands in rep["bands"].items():
        print(f"  {key:7s} " + "  ".join(f"[{lo:.0f}, {hi:.0f}] {reg}" for lo, hi, reg in bands))
    for name, r in rep["resolutions"].items():
        vals = ", ".join(f"{k} {'-' if v is None else (f'{v:.0f}' if isinstance(v, float) else v)}" for k, v in r.items())
        print(f"  resolution {name:10s} {vals}")
    c = rep["daa_command"]
    print(f"  DAA command: track {c['trk_deg']:.0f} deg, vs {c['vs_fpm']:.0f} fpm, gs {c['gs_kt']:.0f} kt "
          f"({c['axis']} {c['direction']})")
    return 0
