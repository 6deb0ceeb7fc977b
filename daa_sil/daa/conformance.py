"""Agreement of the onboard DAA with reference DAIDALUS outputs (the conformance set's JSONL format).

A record holds one ownship and one intruder (ENU, SI) and what NASA DAIDALUS computed for them: the
DWC violation interval, the alert level, and track / ground-speed / vertical-speed bands with their
regions, resolutions and preferred directions (field list in ``docs/daa.md``). :func:`evaluate`
runs our DAA on every record in one batch; :func:`compare` scores the agreement per record, and
:func:`agreement` pools the scores into the table :func:`format_table` prints. Every quantity is
compared on the reference's own grid, so a coarser preset is judged by the same yardstick:

* **classification** -- the region at every midpoint of the reference's step over the reference's
  range (0.5, 1.5, ... 359.5 deg; 10.5 ... 699.5 kt; -5950 ... 5950 fpm), i.e. per degree, per knot and
  per 100 fpm; a midpoint never falls on a band boundary, so both sides are unambiguous. Records are
  split by whether DAIDALUS painted a RECOVERY band on that axis.
* **region names** -- the region of the current value (``own_track_region`` etc.).
* **resolutions** -- both sides of each axis agree when both are undefined (no conflict), both are
  "none on that side" (+-inf), or both are values within one reference step.
* **preferred direction** -- DAIDALUS's boolean (right/up, else left/down; also left/down when there
  is no conflict).

Parsing is sans-IO (:func:`parse_records` takes lines); :func:`read_records` opens plain, ``.gz`` or
``.xz`` files. A malformed record raises :class:`~daa_sil.errors.FileFormatError` naming the file,
line and field.
"""

from __future__ import annotations

import gzip
import json
import lzma
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable

import numpy as np

from daa_sil.geometry import wellclear as wc
from ..errors import FileFormatError
from daa_sil.geometry.kinematics import AircraftState
from daa_sil.geometry.units import FPM, KT
from .alerting import alert_levels, relative_state
from .bands import AxisBands, Bands, compute_bands
from .config import REGION_NAMES, DaaConfig

#: reference grid per axis: (key of the bands in the record, unit in m/s or rad per record unit,
#: step, low end, high end) -- the DO_365B_no_SUM.conf grids
GRIDS = {"trk": ("track_bands_deg", 1.0, 0.0, 360.0), "gs": ("hs_bands_kt", 5.0, 10.0, 700.0),
         "vs": ("vs_bands_fpm", 100.0, -6000.0, 6000.0)}
#: the classification grid spacing (per degree, per knot, per 100 fpm)
SAMPLE = {"trk": 1.0, "gs": 1.0, "vs": 100.0}
AXES = ("trk", "gs", "vs")
_OWN_REGION = {"trk": "own_track_region", "gs": "own_hs_region", "vs": "own_vs_region"}
_RES = {"trk": ("track_resolution_left_deg", "track_resolution_right_deg", 1.0),
        "gs": ("hs_resolution_down_mps", "hs_resolution_up_mps", KT),
        "vs": ("vs_resolution_down_mps", "vs_resolution_up_mps", FPM)}
_PREF = {"trk": ("track_preferred_direction", "right"), "gs": ("hs_preferred_direction", "up"),
         "vs": ("vs_preferred_direction", "up")}
REQUIRED = ("own_pos_enu_m", "own_vel_enu_mps", "int_pos_enu_m", "int_vel_enu_mps", "dwc_conflict", "alert_level",
            "track_bands_deg", "hs_bands_kt", "vs_bands_fpm", "own_track_region", "own_hs_region", "own_vs_region")

#: the floors the ``daidalus`` preset is held to (issue 15); fractions
FLOORS = {"dwc_interval": 1.0, "alert_level": 1.0, "class_trk": 0.995, "class_gs": 0.995, "class_vs": 0.995,
          "class_trk_rec": 0.97, "class_gs_rec": 0.97, "class_vs_rec": 0.97, "region_names": 0.99,
          "resolutions": 0.99, "preferred": 0.98}
DWC_TOL_S = 1e-6  #: s, DWC interval agreement tolerance


# --------------------------------------------------------------------------------------------------
# reading
# --------------------------------------------------------------------------------------------------
def _num(v, where: str) -> float:
    """Strict-JSON number of the format: null = nan, "inf" / "-inf" strings."""
    if v is None:
        return math.nan
    if isinstance(v, str):
        if v in ("inf", "+inf"):
            return math.inf
        if v == "-inf":
            return -math.inf
        raise ValueError(f"{where}: expected a number, null, \"inf\" or \"-inf\", got {v!r}")
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ValueError(f"{where}: expected a number, got {type(v).__name__}")
    return float(v)


def _vec3(rec: dict, key: str) -> list[float]:
    v = rec[key]
    if not isinstance(v, list) or len(v) != 3:
        raise ValueError(f"{key}: expected a list of 3 numbers")
    out = [_num(x, key) for x in v]
    if not all(math.isfinite(x) for x in out):
        raise ValueError(f"{key}: every component must be finite")
    return out


def _bands(rec: dict, key: str) -> list[tuple[float, float, str]]:
    v = rec[key]
    if not isinstance(v, list) or not v:
        raise ValueError(f"{key}: expected a non-empty list of [low, high, region]")
    out = []
    for b in v:
        if not isinstance(b, list) or len(b) != 3 or not isinstance(b[2], str):
            raise ValueError(f"{key}: each band must be [low, high, region name]")
        if b[2].lower() not in REGION_NAMES and b[2] != "UNKNOWN":
            raise ValueError(f"{key}: unknown region {b[2]!r}; allowed: {', '.join(n.upper() for n in REGION_NAMES)}")
        out.append((_num(b[0], key), _num(b[1], key), b[2].upper()))
    return out


def validate_record(rec: dict) -> dict:
    """Check one record's fields (raises ValueError naming the field); returns it."""
    if not isinstance(rec, dict):
        raise ValueError("expected a JSON object per line")
    missing = [k for k in REQUIRED if k not in rec]
    if missing:
        raise ValueError(f"missing field(s) {', '.join(missing)}")
    for k in ("own_pos_enu_m", "own_vel_enu_mps", "int_pos_enu_m", "int_vel_enu_mps"):
        _vec3(rec, k)
    if math.hypot(*_vec3(rec, "own_vel_enu_mps")[:2]) <= 0:
        raise ValueError("own_vel_enu_mps: the ownship needs a non-zero horizontal velocity")
    if not isinstance(rec["alert_level"], int) or not 0 <= rec["alert_level"] <= 3:
        raise ValueError("alert_level: expected an integer 0..3")
    for ax in AXES:
        _bands(rec, GRIDS[ax][0])
    return rec


def parse_records(lines: Iterable[str], source: str = "<input>") -> list[dict]:
    """Records from JSONL text lines (blank lines skipped); a malformed line raises
    :class:`~daa_sil.errors.FileFormatError` naming ``source``, the line number and the field."""
    out = []
    for i, line in enumerate(lines, 1):
        if not line.strip():
            continue
        try:
            out.append(validate_record(json.loads(line)))
        except json.JSONDecodeError as exc:
            raise FileFormatError(f"{source}:{i}: not valid JSON ({exc.msg} at column {exc.colno})") from None
        except (ValueError, TypeError, KeyError) as exc:
            raise FileFormatError(f"{source}:{i}: {exc}") from None
    if not out:
        raise FileFormatError(f"{source}: no records (expected one JSON object per line)")
    return out


def read_records(path: "str | Path") -> list[dict]:
    """Read a conformance file: JSONL, optionally ``.gz`` or ``.xz`` compressed."""
    p = Path(path)
    opener = gzip.open if p.suffix == ".gz" else lzma.open if p.suffix == ".xz" else open
    try:
        with opener(p, "rt", encoding="utf-8") as fh:
            return parse_records(fh, str(p))
    except FileNotFoundError:
        raise FileFormatError(f"{p}: no such file") from None
    except IsADirectoryError:
        raise FileFormatError(f"{p}: is a directory, expected a .jsonl file") from None
    except (OSError, EOFError, lzma.LZMAError, UnicodeDecodeError) as exc:
        raise FileFormatError(f"{p}: cannot read ({exc.__class__.__name__}: {exc})") from None


# --------------------------------------------------------------------------------------------------
# evaluating and comparing
# --------------------------------------------------------------------------------------------------
@dataclass
class Ours:
    """Our DAA's outputs for N records: DWC interval (N,), alert level (N,) and the bands."""

    t_in: np.ndarray
    t_out: np.ndarray
    alert: np.ndarray
    bands: Bands
    cfg: DaaConfig


def states(records: list[dict]) -> tuple[AircraftState, AircraftState]:
    """Ownship (N,) and intruder (N, 1) states of the records."""
    arr = lambda k: np.array([r[k] for r in records], float)  # noqa: E731
    own = AircraftState.from_pos_vel(arr("own_pos_enu_m"), arr("own_vel_enu_mps"))
    intr = AircraftState.from_pos_vel(arr("int_pos_enu_m")[:, None], arr("int_vel_enu_mps")[:, None])
    return own, intr


def evaluate(records: list[dict], cfg: DaaConfig) -> Ours:
    """Run our DAA (stateless: one step, as the reference) on every record in one batch."""
    own, intr = states(records)
    s, v = relative_state(own, intr)
    t_in, t_out = wc.violation_interval(s, v, cfg.th, 0.0, cfg.lookahead_s)
    alert = alert_levels(own, intr, cfg)
    bands = compute_bands(own, intr, cfg, alert)
    return Ours(t_in[:, 0], t_out[:, 0], alert[:, 0], bands, cfg)


def _ref_region(bands: list[tuple[float, float, str]], x: np.ndarray) -> np.ndarray:
    """DAIDALUS region name at points ``x`` (never on a boundary) from its intervals."""
    out = np.full(x.shape, "UNKNOWN", dtype=object)
    for lo, hi, name in bands:
        out[(x > lo) & (x < hi)] = name
    return out


def _axis_values(ab: AxisBands, i: int, ax: str, own_trk_deg: float) -> np.ndarray:
    """Candidate positions of encounter ``i`` in the record's unit (track: relative degrees)."""
    if ax == "trk":
        return np.degrees(ab.delta[i])
    return ab.values[i] / (KT if ax == "gs" else FPM)


def our_regions(ab: AxisBands, i: int, ax: str, x: np.ndarray, own_trk_deg: float = 0.0) -> np.ndarray:
    """Our region name at points ``x`` (record units; track absolute degrees) of encounter ``i``: the
    region of the candidate there or of the interval between the two candidates around it;
    "OUTSIDE" beyond our candidate range."""
    vals = _axis_values(ab, i, ax, own_trk_deg)
    reg = np.asarray(ab.region[i], int)
    gap = np.asarray(ab.gaps()[i], int)
    names = np.array([n.upper() for n in REGION_NAMES] + ["OUTSIDE"], dtype=object)
    if ax == "trk":
        x = (np.asarray(x) - own_trk_deg + 180.0) % 360.0 - 180.0  # relative, [-180, 180)
    keep = np.ones(len(vals), bool)
    keep[1:] = np.abs(np.diff(vals)) > 1e-9  # saturated duplicates at a limit
    vals, reg = vals[keep], reg[keep]
    gap = gap[keep[1:]] if gap.size else gap
    j = np.searchsorted(vals, x)  # vals[j-1] < x <= vals[j]
    code = np.full(x.shape, len(REGION_NAMES))
    on = (j < len(vals)) & (np.abs(vals[np.minimum(j, len(vals) - 1)] - x) < 1e-9)
    code[on] = reg[j[on]]
    mid = ~on & (j > 0) & (j < len(vals))
    code[mid] = gap[j[mid] - 1]
    if ax == "trk":  # the interval through +-180 between the last and the first candidate
        wrap = ~on & ((j == 0) | (j == len(vals)))
        if wrap.any():
            a, b = int(reg[-1]), int(reg[0])
            rec_ = REGION_NAMES.index("recovery")
            worse = max(0 if a == rec_ else a, 0 if b == rec_ else b)
            code[wrap] = rec_ if a == b == rec_ else worse
    return names[code]


def _ref_res(rec: dict, key: str, scale: float) -> float:
    v = _num(rec.get(key), key)
    return v / scale if math.isfinite(v) else v


@dataclass
class RecordScore:
    """Agreement of one record, per quantity (see the module docstring)."""

    index: int
    id: str
    dwc_ok: bool
    dwc_err_s: float
    alert_ok: bool
    classified: dict = field(default_factory=dict)  #: axis -> (agreeing points, points)
    recovery: dict = field(default_factory=dict)  #: axis -> DAIDALUS painted RECOVERY
    region_ok: dict = field(default_factory=dict)  #: axis -> current-value region agrees
    res_ok: dict = field(default_factory=dict)  #: axis -> (low side agrees, high side agrees)
    pref_ok: dict = field(default_factory=dict)  #: axis -> preferred direction agrees
    detail: dict = field(default_factory=dict)  #: axis -> short text of what differs

    def worst(self) -> float:
        """Smallest classification agreement over the axes (for ranking the worst records)."""
        return min(a / n for a, n in self.classified.values())


def compare(records: list[dict], ours: Ours) -> list[RecordScore]:
    """Per-record agreement of ``ours`` with the reference outputs in ``records``."""
    out = []
    axes = {"trk": ours.bands.trk, "gs": ours.bands.gs, "vs": ours.bands.vs}
    for i, rec in enumerate(records):
        ref_conf = bool(rec["dwc_conflict"])
        mine_conf = bool(np.isfinite(ours.t_in[i]) and ours.t_out[i] > ours.t_in[i])
        if ref_conf and mine_conf:
            err = max(abs(ours.t_in[i] - _num(rec["dwc_t_in_s"], "dwc_t_in_s")),
                      abs(ours.t_out[i] - _num(rec["dwc_t_out_s"], "dwc_t_out_s")))
        else:
            err = 0.0 if ref_conf == mine_conf else math.inf
        sc = RecordScore(i, str(rec.get("id", i)), err <= DWC_TOL_S, float(err), int(ours.alert[i]) == rec["alert_level"])
        own_trk = float(np.degrees(ours.bands.trk.values[i, ours.bands.trk.k0]))
        for ax in AXES:
            ab = axes[ax]
            key, step, lo, hi = GRIDS[ax]
            ref_bands = _bands(rec, key)
            x = np.arange(lo + SAMPLE[ax] / 2, hi, SAMPLE[ax])
            ref = _ref_region(ref_bands, x)
            mine = our_regions(ab, i, ax, x, own_trk)
            agree = ref == mine
            sc.classified[ax] = (int(agree.sum()), int(x.size))
            sc.recovery[ax] = any(b[2] == "RECOVERY" for b in ref_bands)
            k0 = ab.k0
            sc.region_ok[ax] = REGION_NAMES[int(ab.region[i, k0])].upper() == rec[_OWN_REGION[ax]]
            lo_key, hi_key, scale = _RES[ax]
            r_lo, r_hi = _ref_res(rec, lo_key, scale), _ref_res(rec, hi_key, scale)
            unit = 1.0 if ax == "trk" else (KT if ax == "gs" else FPM)
            conv = np.degrees if ax == "trk" else (lambda v: v / unit)
            m_lo, m_hi = float(conv(ab.res_lo[i])), float(conv(ab.res_hi[i]))
            sc.res_ok[ax] = (_res_agree(r_lo, m_lo, step, ax), _res_agree(r_hi, m_hi, step, ax))
            pkey, plus = _PREF[ax]
            sc.pref_ok[ax] = (rec.get(pkey) == plus) == (int(ab.preferred[i]) > 0)
            if not agree.all():
                bad = x[~agree]
                sc.detail[ax] = (f"{(~agree).sum()} of {x.size} differ in [{bad.min():g}, {bad.max():g}]: "
                                 f"DAIDALUS {_summ(ref_bands)} / ours {_summ(ab.band_intervals(i), ax)}")
        out.append(sc)
    return out


def _summ(bands, ax: "str | None" = None) -> str:
    def f(v):
        if ax is None:
            return f"{v:g}"
        return f"{np.degrees(v) % 360:.0f}" if ax == "trk" else f"{v / (KT if ax == 'gs' else FPM):.0f}"
    return " ".join(f"[{f(lo)},{f(hi)}]{name[:3].upper()}" for lo, hi, name in bands)


def _res_agree(ref: float, mine: float, step: float, ax: str) -> bool:
    if math.isnan(ref) or math.isnan(mine):
        return math.isnan(ref) and math.isnan(mine)
    if math.isinf(ref) or math.isinf(mine):
        return ref == mine
    d = abs(ref - mine)
    if ax == "trk":
        d = min(d % 360.0, 360.0 - d % 360.0)
    return d <= step + 1e-6


def agreement(scores: list[RecordScore]) -> dict:
    """Pooled agreement fractions (and the population sizes) keyed as in :data:`FLOORS`."""
    out: dict = {"records": len(scores)}
    out["dwc_interval"] = float(np.mean([s.dwc_ok for s in scores]))
    out["alert_level"] = float(np.mean([s.alert_ok for s in scores]))
    for ax in AXES:
        for rec_flag, suffix in ((False, ""), (True, "_rec")):
            pop = [s for s in scores if s.recovery[ax] == rec_flag]
            a = sum(s.classified[ax][0] for s in pop)
            n = sum(s.classified[ax][1] for s in pop)
            out[f"class_{ax}{suffix}"] = a / n if n else float("nan")
            out[f"n_{ax}{suffix}"] = len(pop)
    out["region_names"] = float(np.mean([s.region_ok[ax] for s in scores for ax in AXES]))
    out["resolutions"] = float(np.mean([ok for s in scores for ax in AXES for ok in s.res_ok[ax]]))
    out["preferred"] = float(np.mean([s.pref_ok[ax] for s in scores for ax in AXES]))
    out["dwc_max_err_s"] = float(max((s.dwc_err_s for s in scores), default=0.0))
    return out


_ROWS = [("dwc_interval", "DWC interval within 1e-6 s", None), ("alert_level", "alert level", None),
         ("class_trk", "track, per degree, no recovery", "n_trk"),
         ("class_trk_rec", "track, per degree, with recovery", "n_trk_rec"),
         ("class_gs", "ground speed, per knot, no recovery", "n_gs"),
         ("class_gs_rec", "ground speed, per knot, with recovery", "n_gs_rec"),
         ("class_vs", "vertical speed, per 100 fpm, no recovery", "n_vs"),
         ("class_vs_rec", "vertical speed, per 100 fpm, with recovery", "n_vs_rec"),
         ("region_names", "region of the current value (3 axes)", None),
         ("resolutions", "resolutions within one step (3 axes x 2 sides)", None),
         ("preferred", "preferred direction (3 axes)", None)]


def failures(table: dict, floors: "dict | None" = None) -> list[str]:
    """Names of the rows below their floor (nan rows, an empty population, do not fail)."""
    floors = FLOORS if floors is None else floors
    return [k for k, f in floors.items() if not (table[k] != table[k]) and table[k] < f - 1e-12]


def format_table(table: dict, preset: str, floors: "dict | None" = None) -> str:
    """The agreement table as text (one row per quantity; floors marked when given)."""
    lines = [f"agreement with DAIDALUS, preset {preset}, {table['records']} records",
             f"  {'quantity':50s} {'agree':>9s} {'records':>8s} {'floor':>7s}"]
    for key, label, pop in _ROWS:
        v = table[key]
        n = table[pop] if pop else table["records"]
        fl = "" if floors is None else f"{floors[key] * 100:6.1f}%"
        mark = "" if floors is None or v != v or v >= floors[key] - 1e-12 else "  BELOW"
        val = "     n/a" if v != v else f"{v * 100:8.2f}%"
        lines.append(f"  {label:50s} {val:>9s} {n:8d} {fl:>7s}{mark}")
    lines.append(f"  largest DWC interval difference: {table['dwc_max_err_s']:.3g} s")
    return "\n".join(lines)


def worst_records(scores: list[RecordScore], k: int = 10) -> str:
    """The ``k`` records with the lowest classification agreement, with what differs."""
    ranked = sorted(scores, key=lambda s: (s.worst(), s.id))[:k]
    lines = []
    for s in ranked:
        flags = [f"{ax} {a}/{n}" for ax, (a, n) in s.classified.items() if a < n]
        other = [f"{ax} region" for ax, ok in s.region_ok.items() if not ok]
        other += [f"{ax} res" for ax, ok in s.res_ok.items() if not all(ok)]
        other += [f"{ax} pref" for ax, ok in s.pref_ok.items() if not ok]
        if not s.alert_ok:
            other.append("alert")
        if not s.dwc_ok:
            other.append(f"dwc {s.dwc_err_s:.2g} s")
        lines.append(f"{s.id}: {', '.join(flags + other) or 'agrees'}")
        for ax, text in s.detail.items():
            lines.append(f"    {ax}: {text}")
    return "\n".join(lines)


def run(records: list[dict], cfg: DaaConfig) -> tuple[dict, list[RecordScore]]:
    """Evaluate, compare and pool: ``(table, per-record scores)``."""
    scores = compare(records, evaluate(records, cfg))
    return agreement(scores), scores
