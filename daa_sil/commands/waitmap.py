"""``daa-sil waitmap build|show|plot``: build, query and plot MDP wait maps."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np

from ..errors import UsageError
from daa_sil.config.config_option import add_config_argument
from daa_sil.config.run_config import load_config
from daa_sil.files import to_jsonable
from daa_sil.geometry.thresholds import PRESETS
from ..waitmap.model import WAIT_DEFINITIONS
from daa_sil.config.settings import WORKERS_PER_CORE
from .common_args import add_allow_large, finite_float, workers_option
from ..waitmap.store import map_filename
from .. import waitmap
from daa_sil.files import check_output_path
from ..waitmap.model import params_hash
from ..waitmap.build import build_memory, default_workers
from ..waitmap.family_files import FAMILY_INDEX, write_family_index
from ..waitmap.store import map_filename, read_meta
from ..errors import OutputError

BUILD_EX = """examples:
  daa-sil waitmap build --out maps/paper                      # the paper grid, 5 turn-rate maps
  daa-sil waitmap build --grid alerting --out maps/alerting   # the study's default (about 1 min)
  daa-sil waitmap build --grid fine --preset do365 --out maps/fine
  daa-sil waitmap build --definition until_evade --out maps/until-evade
  daa-sil waitmap build --grid paper,dx=24,dy=24,theta=8 --out maps/custom --force
  daa-sil waitmap build --grid mygrid.yaml --turn-rates -5,0,5 --gamma 0.9 --out maps/mine
  daa-sil waitmap check maps/paper                            # the paper's map properties on it

--grid takes a map preset (paper: the paper's +-1,500 m box, H = 60 s; alerting: the DO-365
alerting region, H = 120 s; fine), a YAML file ({base: paper, dx: {min: -1500, max: 1500, n: 24},
theta: {n: 8}}) or an inline spec "base,axis=N,axis=lo:hi:N" (H = 60 s). --definition paper (the
default) stores E[time to LoWC | LoWC within H]; until_evade the expected time until LoWC or an
evade-optimal state. The maps are built min(cores, maps) at a time (--workers), each written as soon
as it is finished; family.json, written last, makes the directory a family. Existing maps are never
overwritten without --force. A directory built here is used by 'campaign run --waitmap DIR' and
'daa-sil run --waitmap DIR'.
"""

CHECK_EX = """examples:
  daa-sil waitmap check maps/paper
  daa-sil waitmap check maps/alerting --json

Checks the paper's stated properties on the map's non-trivial states (0 < W < H): head-on waits
shorter than overtaking, waits shrinking as an intruder closes, the +-omega maps mirror images and
the 0 map symmetric, how waits change with intruder speed, and the histogram of the threatening
states against the paper's Fig. 3. Exit 1 if a property the paper states does not hold.
"""

SHOW_EX = """examples:
  daa-sil waitmap show maps/paper/waitmap_turn+0.0.npz --dx 1200 --dy 300 --dh 150 --vi 155 --vh 0 --theta 180
  daa-sil waitmap show maps/paper --turn-rate 5 --dx -900 --dy 0 --dh 180 --vi 100 --vh -2 --theta 0 --json

The state is the paper's relative state: dx ahead, dy LEFT of the ownship track (m), dh intruder
minus ownship altitude (m), vi intruder ground speed (m/s), vh intruder minus ownship vertical speed
(m/s), theta intruder heading CCW from the ownship track (deg; 180 = head-on).
"""

PLOT_EX = """examples:
  daa-sil waitmap plot maps/paper --out figs/             # a family directory: all figures
  daa-sil waitmap plot maps/paper/waitmap_turn+0.0.npz --out figs/ --vi 155 --dh 150

Writes PNGs: slices over (dx, dy) for head-on / crossing / overtaking, the mirrored +-5 deg/s pair
(when the family has them), the histogram of wait times (paper Fig. 3) and a 3-D view (paper Fig. 4).
"""


def _turn_rates(text: str) -> list[float]:
    try:
        vals = [float(t) for t in text.split(",") if t.strip()]
    except ValueError:
        raise UsageError(f"--turn-rates must be comma-separated numbers in deg/s, got {text!r}") from None
    if not vals or not all(math.isfinite(v) and abs(v) <= 30 for v in vals):
        raise UsageError(f"--turn-rates must be finite values within [-30, 30] deg/s, got {text!r}")

    seen: dict[str, float] = {}
    for v in vals:
        name = map_filename(v)
        if name in seen:
            raise UsageError(f"--turn-rates {seen[name]:g} and {v:g} both give the file {name}; "
                             f"give each rate once, at least 0.1 deg/s apart")
        seen[name] = v
    return vals


def register(sub) -> None:
    p = sub.add_parser("waitmap", help="build, query and plot MDP wait maps",
                       description="MDP wait maps (paper Sec. II, IV): how long the UAS can wait for the "
                                   "delayed remote pilot before the onboard DAA must act.",
                       epilog=BUILD_EX, formatter_class=argparse.RawDescriptionHelpFormatter)
    vs = p.add_subparsers(dest="verb", metavar="VERB", parser_class=sub._parser_class)
    vs.required = True

    b = vs.add_parser("build", help="build one map per turn-rate condition", epilog=BUILD_EX,
                      formatter_class=argparse.RawDescriptionHelpFormatter)
    b.add_argument("--grid", default="paper", help="paper | fine | FILE.yaml | inline spec (default paper)")
    b.add_argument("--preset", default=None, help=f"LoWC threshold preset: {', '.join(PRESETS)} (default: the "
                                                  "--config's thresholds, else paper)")
    add_config_argument(b)
    b.add_argument("--out", default="waitmaps", metavar="DIR", help="output directory (default ./waitmaps)")
    b.add_argument("--turn-rates", default="-5,-2.5,0,2.5,5", metavar="LIST",
                   help="conditioning initial turn rates, deg/s, + = left (default -5,-2.5,0,2.5,5)")
    b.add_argument("--gamma", type=finite_float("--gamma", 1e-6, 0.999999), default=None,
                   help="discount (default: the --config's waitmap.gamma, else 0.95)")
    b.add_argument("--horizon", type=finite_float("--horizon", 1.0, 600.0), default=None, metavar="S",
                   help="wait-time horizon H, s (default: the map preset's, 60 or 120 for alerting)")
    b.add_argument("--definition", choices=WAIT_DEFINITIONS, default="paper",
                   help="wait time stored: paper (default) or until_evade")
    b.add_argument("--p-min", type=finite_float("--p-min", 1e-9, 0.5), default=1e-3, metavar="P",
                   help="LoWC-probability floor: states below it are no threat, W = H (default 0.001)")
    b.add_argument("--workers", type=workers_option(), default=None, metavar="K",
                   help=f"maps built at once, one process each (default: min(cores, maps); at most "
                        f"{WORKERS_PER_CORE} per core)")
    b.add_argument("--force", action="store_true", help="overwrite existing maps in DIR")
    add_allow_large(b, "the build (about 0.5 kB per grid state for each map being built)")
    b.add_argument("--json", action="store_true", help="print a JSON summary instead of paths")
    b.set_defaults(func=run_build)

    s = vs.add_parser("show", help="query a map at one state", epilog=SHOW_EX,
                      formatter_class=argparse.RawDescriptionHelpFormatter)
    s.add_argument("map", metavar="MAP", help="a map .npz, a family directory or a map preset (paper, alerting, fine)")
    for name, unit, lo, hi in (("dx", "m", -1e6, 1e6), ("dy", "m", -1e6, 1e6), ("dh", "m", -1e5, 1e5),
                               ("vi", "m/s", 0.0, 1000.0), ("vh", "m/s", -200.0, 200.0), ("theta", "deg", -720.0, 720.0)):
        s.add_argument(f"--{name}", required=True, type=finite_float(f"--{name}", lo, hi), metavar=unit.upper())
    s.add_argument("--turn-rate", type=finite_float("--turn-rate", -30.0, 30.0), default=0.0, metavar="DEG/S",
                   help="intruder turn rate, + = left; picks the nearest map of a family (default 0)")
    s.add_argument("--json", action="store_true", help="print one JSON object")
    s.set_defaults(func=run_show)

    c = vs.add_parser("check", help="the paper's map properties on a map family", epilog=CHECK_EX,
                      formatter_class=argparse.RawDescriptionHelpFormatter)
    c.add_argument("map", metavar="MAP", help="a family directory (or a map preset: paper, alerting, fine)")
    c.add_argument("--json", action="store_true", help="print one JSON object")
    c.set_defaults(func=run_check)

    pl = vs.add_parser("plot", help="write PNG figures of a map or family", epilog=PLOT_EX,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    pl.add_argument("map", metavar="MAP", help="a map .npz, a family directory or a map preset (paper, alerting, fine)")
    pl.add_argument("--out", required=True, metavar="DIR", help="directory for the PNGs")
    pl.add_argument("--vi", type=finite_float("--vi", 1.0, 1000.0), default=155.0, help="intruder speed of the slices, m/s (default 155)")
    pl.add_argument("--dh", type=finite_float("--dh", -1e4, 1e4), default=200.0, help="relative altitude of the slices, m (default 200)")
    pl.add_argument("--vh", type=finite_float("--vh", -200.0, 200.0), default=-2.5, help="relative vertical speed, m/s (default -2.5)")
    pl.add_argument("--force", action="store_true", help="overwrite existing PNGs")
    pl.add_argument("--rerun", metavar="FILE.rrd", help="also write the (--vi, --vh, --theta) slice as a Rerun 3-D "
                                                        "point cloud over (dx, dy, dh) coloured by wait time")
    pl.add_argument("--theta", type=finite_float("--theta", -360.0, 360.0), default=180.0, metavar="DEG",
                    help="intruder heading of the --rerun slice, deg CCW from the ownship track (default 180)")
    pl.set_defaults(func=run_plot)


def _load_any(path: str):
    """A family directory, one map file, or a map preset (built and cached like a campaign's)."""

    p = Path(path)
    if p.is_dir():
        return waitmap.load_family(p)
    if not p.exists() and str(path) in waitmap.MAP_PRESETS:
        return waitmap.family_for(str(path))
    return waitmap.WaitMapFamily([waitmap.load(p)])


def run_build(args) -> int:
    from rich.progress import Progress  # lazy: start-up time

    from daa_sil.out_dir import check_not_busy, claim_out_dir  # lazy: start-up time

    rc = load_config(args.config) if args.config else None
    args.preset = args.preset or (rc.thresholds if rc else "paper")
    if args.gamma is None:
        args.gamma = (rc.waitmap["gamma"] if rc else None) or 0.95
    if args.preset.lower() not in PRESETS:
        raise UsageError(f"unknown --preset {args.preset!r}; allowed: {', '.join(PRESETS)}")
    rates = _turn_rates(args.turn_rates)
    grid, params = waitmap.map_params(args.grid, args.preset.lower(), gamma=args.gamma,
                                      wait_definition=args.definition, p_min=args.p_min)
    if args.horizon is not None:
        params = params.with_(horizon=args.horizon)
    out = check_output_path(args.out, "--out", directory=True)  # name, length, kind, writable: one line
    workers = args.workers or default_workers(len(rates))
    build_memory(grid, len(rates), workers).check(args.allow_large, "use a smaller --grid, fewer --turn-rates "
                                                                    "or fewer --workers")
    check_not_busy(out)
    if not args.force:
        clash = [out / map_filename(r) for r in rates] + [out / FAMILY_INDEX]
        clash = [c for c in clash if c.exists()]
        if clash:
            raise OutputError(f"{clash[0]} exists; refusing to overwrite (use --force or another --out)")
    with claim_out_dir(out, keep=True):  # other files may stay; a second build into DIR meanwhile is refused
        (out / FAMILY_INDEX).unlink(missing_ok=True)  # --force: the old index must not describe new maps
        with Progress(transient=True) as prog:
            task = prog.add_task(f"building {len(rates)} maps on {grid.size:,} states ({workers} processes)",
                                 total=len(rates))
            paths = waitmap.build_members(grid, params, rates, out, workers=workers,
                                          progress=lambda r: prog.advance(task))
        write_family_index(out, [(r, p, read_meta(p)["content_hash"]) for r, p in zip(rates, paths)],
                           params_hash(grid.to_dict(), params, rates), rates)
    fam = waitmap.load_family(out)
    paths = [out / map_filename(m.turn_rate_deg) for m in fam.maps]
    if args.json:
        print(json.dumps(to_jsonable({"maps": [str(p) for p in paths], "states": grid.size,
                                      "stats": [m.stats for m in fam.maps]}), sort_keys=True))
    else:
        for p, m in zip(paths, fam.maps):
            print(f"{p}  (turn {m.turn_rate_deg:+.1f} deg/s, {m.stats['iterations']} sweeps, "
                  f"{m.stats['total_s']:.2f} s)")
    return 0


def run_show(args) -> int:
    fam = _load_any(args.map)
    wm = fam.map_for(args.turn_rate)
    state = np.array([args.dx, args.dy, args.dh, args.vi, args.vh, math.radians(args.theta)])
    r = wm.lookup(state)
    rep = {"wait_s": float(r.wait_s), "p_lowc": float(r.p_lowc), "action": "evade" if r.evade else "wait",
           "in_grid": bool(r.in_grid), "turn_rate_deg": wm.turn_rate_deg, "preset": wm.params.preset,
           "horizon_s": wm.params.horizon, "content_hash": wm.content_hash,
           "state": {"dx": args.dx, "dy": args.dy, "dh": args.dh, "vi": args.vi, "vh": args.vh, "theta_deg": args.theta}}
    if args.json:
        print(json.dumps(rep, sort_keys=True))
        return 0
    print(f"{rep['action'].upper()}: wait {rep['wait_s']:.1f} s of {rep['horizon_s']:g} s, "
          f"P(LoWC within H if waiting) {rep['p_lowc']:.3f}, {'in' if rep['in_grid'] else 'outside'} the grid "
          f"(map turn {wm.turn_rate_deg:+.1f} deg/s, preset {wm.params.preset})")
    return 0


def run_check(args) -> int:
    from ..waitmap.oracles import check_family  # lazy: start-up time

    fam = _load_any(args.map)
    rep = check_family(fam)
    ok = rep["head_on_vs_overtaking"]["holds"] and rep["converging_lines"]["holds"]
    mir = rep["mirror"]
    ok = ok and (mir["zero_map"] is None or mir["zero_map"] < 1e-3) and all(
        d["mirror_error_s"] < 1e-3 for d in mir["pairs"].values())
    rep["ok"] = bool(ok)
    if args.json:
        print(json.dumps(to_jsonable(rep), sort_keys=True))
        return 0 if ok else 1
    h, yes = rep["histogram"], lambda b: "holds" if b else "DOES NOT HOLD"  # noqa: E731
    ho, cl = rep["head_on_vs_overtaking"], rep["converging_lines"]
    print(f"wait maps: {fam.grid.name} grid ({fam.grid.size:,} states), H = {fam.params.horizon:g} s, "
          f"wait = {fam.params.wait_definition}, p_min = {fam.params.p_min:g}, turn rates {[float(r) for r in fam.turn_rates_deg]} deg/s")
    print(f"  head-on waits < overtaking at equal range: {yes(ho['holds'])} ({ho['held']}/{ho['n']} non-trivial pairs)")
    print(f"  waits shrink as |dx| shrinks:             {yes(cl['holds'])} ({cl['held']}/{cl['n']} converging lines)")
    pairs = ", ".join(f"{k} deg/s {d['mirror_error_s']:.1e} s" for k, d in mir["pairs"].items()) or "no +-pair"
    z = "no 0 map" if mir["zero_map"] is None else f"{mir['zero_map']:.1e} s"
    print(f"  +-omega maps mirror images: {pairs}; 0 map asymmetry {z}")
    for t in rep["speed_trend"]:
        print(f"  turn {t['turn_rate_deg']:+5.1f} deg/s: waits fall with intruder speed on {100 * t['decreasing']:.0f} %, "
              f"grow on {100 * t['increasing']:.0f} % of {t['lines']:,} non-trivial speed lines")
    if h["n"]:
        q = h["quartiles_s"]
        print(f"  threatening states: {h['n']:,}, min {h['min_s']:.1f} s, quartiles {q[0]:.1f} / {q[1]:.1f} / {q[2]:.1f} s, "
              f"max {h['max_s']:.1f} s, {100 * h['share_5_10']:.0f} % within 5-10 s, quartile skew "
              f"{h['quartile_skew']:+.2f}")
        failed = [k for k, held in rep["shape_checks"].items() if not held]
        print("  the paper's Fig. 3 shape (" + "; ".join(rep["shape_checks"]) + "): "
              f"{'yes' if rep['paper_shape'] else 'no, fails: ' + '; '.join(failed)}")
    return 0 if ok else 1


def run_plot(args) -> int:
    from ..waitmap.plots import write_plots  # lazy: start-up time

    check_output_path(args.out, "--out", directory=True)
    if args.rerun:
        check_output_path(args.rerun, "--rerun")
    fam = _load_any(args.map)
    for p in write_plots(fam, Path(args.out), vi=args.vi, dh=args.dh, vh=args.vh, overwrite=args.force):
        print(p)
    if args.rerun:
        from ..viz import SinkOptions, write_waitmap  # lazy: start-up time

        path, _, _ = write_waitmap(fam, SinkOptions(rrd=args.rerun, overwrite=args.force), vi=args.vi, vh=args.vh,
                                   theta_deg=args.theta)
        if path is None:
            return 1
        print(path)
    return 0
