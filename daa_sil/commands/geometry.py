"""``daa-sil geometry``: DO-365 well-clear geometry of one ownship/intruder pair."""

from __future__ import annotations

import argparse
import json

import numpy as np

from daa_sil.geometry import wellclear as wc
from daa_sil.geometry import penetration as pen
from ..errors import UsageError
from daa_sil.config.settings import STANDARD_PRESET
from daa_sil.files import to_jsonable
from daa_sil.geometry.kinematics import STATE_BOUNDS  # physical bounds of a state: (component, lo, hi, unit)
from daa_sil.geometry.thresholds import PRESETS, get_thresholds
from .common_args import finite_float, parse_vector

EXAMPLES = """examples:
  # head-on, 6 km apart, co-altitude, ownship 55 m/s north, intruder 100 m/s south
  daa-sil geometry --own 0,0,1000,0,55,0 --intruder 0,6000,1000,0,-100,0

  # the same with the paper's thresholds, as JSON for a script
  daa-sil geometry --own 0,0,1000,0,55,0 --intruder 0,6000,1000,0,-100,0 --preset paper --json

States are "x,y,z,vx,vy,vz" in the ENU frame: metres east, north, up and m/s. All outputs are SI
(m, s, m/s). JSON uses null where a quantity is undefined (e.g. tau_mod while diverging).
Allowed ranges: |x|, |y| <= 1e7 m, z in [-1e4, 1e5] m, |vx|, |vy| <= 1000 m/s, |vz| <= 500 m/s.
"""



def parse_state(text: str, name: str) -> np.ndarray:
    """``"x,y,z,vx,vy,vz"`` (m, m/s, ENU) -> array (6,), each component finite and within
    :data:`STATE_BOUNDS`; otherwise a one-line UsageError naming the flag, component and range."""
    vec = np.array(parse_vector(text, 6, name, "x,y,z,vx,vy,vz in m and m/s"))
    for val, (comp, lo, hi, unit) in zip(vec, STATE_BOUNDS):
        if not lo <= val <= hi:
            raise UsageError(f"{name} {comp} must be within [{lo:g}, {hi:g}] {unit}, got {val:g}")
    return vec


def register(sub) -> None:
    p = sub.add_parser("geometry", help="well-clear geometry of an ownship/intruder pair",
                       description="Range, HMD, t_cpa, tau_mod, vertical separation, the exact well-clear "
                                   "violation interval within the look-ahead, NMAC and alerting quantities.",
                       epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--own", required=True, metavar="X,Y,Z,VX,VY,VZ", help="ownship ENU state (m, m/s)")
    p.add_argument("--intruder", required=True, metavar="X,Y,Z,VX,VY,VZ", help="intruder ENU state (m, m/s)")
    p.add_argument("--preset", default=STANDARD_PRESET.default,
                   help=f"threshold preset: {', '.join(PRESETS)} (default {STANDARD_PRESET.default})")
    p.add_argument("--lookahead", type=finite_float("--lookahead", 0.0, 3600.0), default=180.0, metavar="S",
                   help="look-ahead time for HMD and the violation interval, s (default 180)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def geometry_report(own: np.ndarray, intr: np.ndarray, preset: str = "do365", lookahead: float = 180.0) -> dict:
    """All geometry quantities for one pair as a JSON-ready dict (SI units, None if undefined)."""
    th = get_thresholds(preset)
    s, v = wc.relative(own[:3], own[3:], intr[:3], intr[3:])
    t_in, t_out = wc.violation_interval(s, v, th, 0.0, lookahead)
    interval = [float(t_in), float(t_out)] if np.isfinite(t_in) else None
    out = {
        "preset": th.name,
        "thresholds": th.to_dict(),
        "lookahead_s": lookahead,
        "range_m": float(wc.horizontal_range(s)),
        "range_rate_mps": float(wc.range_rate(s, v)),
        "hmd_m": float(wc.hmd(s, v, lookahead)),
        "d_cpa_m": float(wc.d_cpa(s, v)),
        "t_cpa_s": float(wc.t_cpa(s, v)),
        "tau_mod_s": float(wc.tau_mod(s, v, th.dthr)),
        "dh_m": float(intr[2] - own[2]),
        "vertical_rate_mps": float(intr[5] - own[5]),
        "t_coa_s": float(wc.t_coa(s, v)),
        "vmd_m": float(wc.vmd(s, v, lookahead)),
        "wcv_now": bool(wc.wcv(s, v, th)),
        "violation_interval_s": interval,
        "time_to_violation_s": float(t_in) if np.isfinite(t_in) else None,
        "nmac_now": bool(wc.nmac(s, th)),
        "penetration_rate": float(pen.penetration_rate(s, v, th)),
    }
    return to_jsonable(out)


def _fmt(val, unit="", prec=1):
    return "n/a" if val is None else f"{val:.{prec}f}{unit}"


def run(args) -> int:
    own = parse_state(args.own, "--own")
    intr = parse_state(args.intruder, "--intruder")
    if args.preset.lower() not in PRESETS:
        raise UsageError(f"unknown --preset {args.preset!r}; allowed: {', '.join(PRESETS)}")
    rep = geometry_report(own, intr, args.preset, args.lookahead)
    if args.json:
        print(json.dumps(rep, sort_keys=True))
        return 0
    th = rep["thresholds"]
    iv = rep["violation_interval_s"]
    print(f"preset {rep['preset']}: DMOD/HMD* {th['dthr']:.1f} m, ZTHR {th['zthr']:.2f} m, "
          f"TAUMOD* {th['tthr']:.0f} s, NMAC {th['nmac_h']:.1f} m / {th['nmac_v']:.2f} m")
    print(f"  range            {_fmt(rep['range_m'], ' m')}   (rate {_fmt(rep['range_rate_mps'], ' m/s')})")
    print(f"  HMD ({args.lookahead:g} s)      {_fmt(rep['hmd_m'], ' m')}   at t_cpa {_fmt(rep['t_cpa_s'], ' s')}")
    print(f"  tau_mod          {_fmt(rep['tau_mod_s'], ' s')}")
    print(f"  dh (intr - own)  {_fmt(rep['dh_m'], ' m')}   (rate {_fmt(rep['vertical_rate_mps'], ' m/s')}, "
          f"t_coa {_fmt(rep['t_coa_s'], ' s')}, VMD {_fmt(rep['vmd_m'], ' m')})")
    print(f"  well clear now   {'VIOLATED' if rep['wcv_now'] else 'yes'}")
    if iv:
        print(f"  violation        from {iv[0]:.2f} s to {iv[1]:.2f} s (within {args.lookahead:g} s)")
    else:
        print(f"  violation        none within {args.lookahead:g} s")
    print(f"  NMAC now         {'YES' if rep['nmac_now'] else 'no'}")
    return 0
