"""State grids for the wait-map MDP, in the paper's relative frame (see ``daa_sil.geometry.frames``).

A :class:`Grid` has six axes in the order of the paper state
``(dx [m], dy [m], dh [m], vi [m/s], vh [m/s], theta [rad])``. Each non-periodic axis is a sorted
list of grid **points** (nodes; the paper's "bins" are read as nodes, values in between are
multilinearly interpolated); ``theta`` is periodic with ``n`` equally spaced nodes starting at 0.

Presets (``GRID_PRESETS``):

``paper``   12 x 12 x 4 x 5 x 5 x 5 = 72,000 states: dx, dy in [-1500, 1500] m, dh in [-200, 200] m,
            vi in [70, 300] m/s, vh in [-5, 5] m/s, theta 5 nodes (0, 72, ... deg) (paper Sec. IV).
``alerting`` 23 x 23 x 11 x 5 x 5 x 8 = 1,163,800 states sized to the DO-365 alerting region, where
            the agent decides: a corrective alert comes 55 s before the predicted loss of well
            clear, i.e. 5-17 km out at the paper's Table 6 speeds (99 % of the decisions of a
            study). dx, dy in [-17, 17] km on nodes 0, +-0.5, 1, 1.5, 2.2, 3, 4, 5.5, 7.5, 10,
            13, 17 km (fine near the well-clear volume, coarse far out); dh in [-750, 750] m on
            0, +-100, 150, 300, 500, 750 m; vi 70, 100, 130, 170, 250 m/s; vh -12, -5, 0, 5, 12
            m/s; theta every 45 deg. Used with a 120 s horizon (``waitmap.MAP_PRESETS``).
``fine``    24 x 24 x 6 x 5 x 5 x 12 = 1,036,800 states on the paper's box (theta every 30 deg, so
            head-on 180 deg and crossing 90/270 deg are nodes).

Custom grids: a YAML file ``{base: paper, dx: {min: -1500, max: 1500, n: 24}, theta: {n: 8},
vi: {points: [70, 100, 155, 300]}}`` or an inline spec ``"paper,dx=24,dy=24,theta=8,dh=-300:300:6"``
(``name=N`` keeps the base range, ``name=lo:hi:N`` sets both).
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..config.settings import GRID_AXIS_POINTS
from ..errors import FileFormatError, UsageError

AXES = ("dx", "dy", "dh", "vi", "vh", "theta")
UNITS = {"dx": "m", "dy": "m", "dh": "m", "vi": "m/s", "vh": "m/s", "theta": "rad"}
TWO_PI = 2.0 * np.pi


@dataclass(frozen=True)
class Axis:
    """One grid axis: sorted node values (SI), or ``n`` periodic nodes on [0, 2pi)."""

    name: str
    points: tuple[float, ...]
    periodic: bool = False

    @property
    def n(self) -> int:
        """Number of nodes."""
        return len(self.points)

    @property
    def values(self) -> np.ndarray:
        """Node values as a float array."""
        return np.asarray(self.points, dtype=float)

    @property
    def lo(self) -> float:
        return self.points[0]

    @property
    def hi(self) -> float:
        return self.points[-1]

    def to_dict(self) -> dict:
        """JSON form (periodic axes store only ``n``)."""
        if self.periodic:
            return {"n": self.n, "periodic": True}
        return {"points": list(self.points)}

    def weights(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Linear interpolation of values ``x`` on this axis.

        Returns ``(i0, i1, w1, inside)``: lower/upper node indices, the weight of the upper node
        (the lower gets ``1 - w1``) and whether ``x`` lies within ``[lo, hi]``. Values outside are
        clamped to the end node (the caller decides what "outside" means). Periodic axes wrap and
        are always inside.
        """
        x = np.asarray(x, dtype=float)
        if self.periodic:
            u = np.mod(x, TWO_PI) * (self.n / TWO_PI)
            f = np.floor(u)
            w1 = u - f
            i0 = f.astype(np.int64) % self.n
            return i0, (i0 + 1) % self.n, w1, np.ones(x.shape, bool)
        p = self.values
        inside = (x >= p[0]) & (x <= p[-1])
        if self.n == 1:
            z = np.zeros(x.shape, np.int64)
            return z, z, np.zeros(x.shape), inside
        xc = np.clip(x, p[0], p[-1])
        i0 = np.clip(np.searchsorted(p, xc, side="right") - 1, 0, self.n - 2)
        w1 = (xc - p[i0]) / (p[i0 + 1] - p[i0])
        return i0, i0 + 1, w1, inside


def _linear_axis(name: str, lo: float, hi: float, n: int) -> Axis:
    pts = np.linspace(lo, hi, n)
    if np.isclose(lo, -hi):  # make a symmetric axis exactly antisymmetric (mirror oracle)
        pts = 0.5 * (pts - pts[::-1])
    return Axis(name, tuple(float(v) for v in pts))


def _theta_axis(n: int) -> Axis:
    return Axis("theta", tuple(float(v) for v in TWO_PI * np.arange(n) / n), periodic=True)


@dataclass(frozen=True)
class Grid:
    """Six-axis MDP grid in the paper's relative frame. ``name`` is informational."""

    axes: tuple[Axis, ...]
    name: str = "custom"

    def __post_init__(self):
        names = tuple(a.name for a in self.axes)
        if names != AXES:
            raise UsageError(f"grid axes must be {AXES}, got {names}")
        for a in self.axes:
            if a.n < (1 if a.periodic else 2):
                raise UsageError(f"grid axis {a.name} needs at least 2 points, got {a.n}")
            if not a.periodic and np.any(np.diff(a.values) <= 0):
                raise UsageError(f"grid axis {a.name} points must be strictly increasing")
            if not np.all(np.isfinite(a.values)):
                raise UsageError(f"grid axis {a.name} points must be finite")

    @property
    def shape(self) -> tuple[int, ...]:
        """Node counts per axis."""
        return tuple(a.n for a in self.axes)

    @property
    def size(self) -> int:
        """Number of grid states (without EXIT / LoWC / OUT)."""
        return int(np.prod(self.shape))

    def axis(self, name: str) -> Axis:
        return self.axes[AXES.index(name)]

    def nodes(self) -> np.ndarray:
        """All grid states as ``(*shape, 6)`` paper states (C order = flat state index)."""
        mesh = np.meshgrid(*[a.values for a in self.axes], indexing="ij")
        return np.stack(mesh, axis=-1)

    def to_dict(self) -> dict:
        """JSON form (round-trips through :func:`grid_from_dict`)."""
        return {"name": self.name, "axes": {a.name: a.to_dict() for a in self.axes}}

    def key(self) -> str:
        """Short content hash of the axis values."""
        return hashlib.sha256(json.dumps(self.to_dict()["axes"], sort_keys=True).encode()).hexdigest()[:16]

    def mirror_index(self) -> np.ndarray:
        """Flat index of each state's mirror image across the ownship track: (dy, theta) -> (-dy, -theta).

        Only valid when the dy axis is symmetric about 0 (checked).
        """
        dy = self.axis("dy").values
        if not np.allclose(dy, -dy[::-1], atol=1e-9):
            raise UsageError("the dy axis is not symmetric about 0; the mirror image is undefined")
        idx = np.indices(self.shape)
        idx[1] = self.shape[1] - 1 - idx[1]
        idx[5] = (-idx[5]) % self.shape[5]
        return np.ravel_multi_index(tuple(idx), self.shape).ravel()


def _symmetric_axis(name: str, positive: "tuple[float, ...]", zero: bool = True) -> Axis:
    """An axis with nodes ``-positive[::-1], (0,) positive`` (exactly antisymmetric)."""
    pos = [float(v) for v in positive]
    return Axis(name, tuple([-v for v in pos[::-1]] + ([0.0] if zero else []) + pos))


#: alerting-region position nodes (m, one side): 500 m spacing near the well-clear volume
#: (DMOD 1220 m), growing to 4 km at the edge of the DO-365 alerting region
ALERTING_POSITIONS = (500, 1000, 1500, 2200, 3000, 4000, 5500, 7500, 10000, 13000, 17000)
#: alerting-region altitude nodes (m, one side): 100 and 150 m bracket the LoWC thresholds
#: d_h* = 122 m (paper) and ZTHR = 137 m (DO-365)
ALERTING_ALTITUDES = (100, 150, 300, 500, 750)


def alerting_grid() -> Grid:
    """A grid sized to the DO-365 alerting region (see the module docstring)."""
    return Grid((_symmetric_axis("dx", ALERTING_POSITIONS), _symmetric_axis("dy", ALERTING_POSITIONS),
                 _symmetric_axis("dh", ALERTING_ALTITUDES), Axis("vi", (70.0, 100.0, 130.0, 170.0, 250.0)),
                 _symmetric_axis("vh", (5.0, 12.0)), _theta_axis(8)), name="alerting")


def paper_grid() -> Grid:
    """The paper's 12 x 12 x 4 x 5 x 5 x 5 grid (72,000 states)."""
    return Grid((_linear_axis("dx", -1500, 1500, 12), _linear_axis("dy", -1500, 1500, 12),
                 _linear_axis("dh", -200, 200, 4), _linear_axis("vi", 70, 300, 5),
                 _linear_axis("vh", -5, 5, 5), _theta_axis(5)), name="paper")


def fine_grid() -> Grid:
    """A finer grid on the paper's box: 24 x 24 x 6 x 5 x 5 x 12 = 1,036,800 states."""
    return Grid((_linear_axis("dx", -1500, 1500, 24), _linear_axis("dy", -1500, 1500, 24),
                 _linear_axis("dh", -200, 200, 6), _linear_axis("vi", 70, 300, 5),
                 _linear_axis("vh", -5, 5, 5), _theta_axis(12)), name="fine")


GRID_PRESETS = {"paper": paper_grid, "alerting": alerting_grid, "fine": fine_grid}


def _axis_from_spec(name: str, spec, base: Axis) -> Axis:
    """One axis from a YAML mapping / inline value, with one-line errors."""
    where = f"grid axis {name!r}"
    try:
        if name == "theta":
            n = spec.get("n") if isinstance(spec, dict) else spec
            return _theta_axis(GRID_AXIS_POINTS.check(n, where, "n"))
        if isinstance(spec, (int, float)) and not isinstance(spec, bool):
            spec = {"n": spec}
        if not isinstance(spec, dict):
            raise UsageError(f"{where}: expected a mapping with min/max/n or points, got {spec!r}")
        if "points" in spec:
            GRID_AXIS_POINTS.check(len(spec["points"]), where, "the number of points")
            pts = [float(v) for v in spec["points"]]
            return Axis(name, tuple(pts))
        lo = float(spec.get("min", base.lo))
        hi = float(spec.get("max", base.hi))
        n = GRID_AXIS_POINTS.check(spec.get("n", base.n), where, "n")  # before any array is made
        if not (np.isfinite(lo) and np.isfinite(hi) and hi > lo):
            raise UsageError(f"{where}: need finite min < max, got {lo} .. {hi}")
        return _linear_axis(name, lo, hi, n)
    except (TypeError, ValueError):
        raise UsageError(f"{where}: bad value {spec!r}") from None


def grid_from_dict(d: dict, name: str = "custom") -> Grid:
    """Grid from a mapping ``{base: paper, <axis>: spec, ...}`` or ``{axes: {...}}`` (stored form)."""
    if not isinstance(d, dict):
        raise UsageError(f"grid definition must be a mapping, got {type(d).__name__}")
    d = dict(d)
    name = str(d.pop("name", name))
    axes_spec = d.pop("axes", None)
    base_name = str(d.pop("base", "paper"))
    if base_name not in GRID_PRESETS:
        raise UsageError(f"unknown base grid {base_name!r}; allowed: {', '.join(GRID_PRESETS)}")
    base = GRID_PRESETS[base_name]()
    spec = dict(axes_spec or {})
    spec.update(d)
    unknown = set(spec) - set(AXES)
    if unknown:
        raise UsageError(f"unknown grid axis {sorted(unknown)[0]!r}; allowed: {', '.join(AXES)}")
    axes = tuple(_axis_from_spec(a, spec[a], base.axis(a)) if a in spec else base.axis(a) for a in AXES)
    return Grid(axes, name=name)


def parse_inline(text: str) -> Grid:
    """Grid from ``"[base,]axis=N,axis=lo:hi:N,..."`` (base defaults to ``paper``)."""
    parts = [p.strip() for p in text.split(",") if p.strip()]
    d: dict = {}
    if parts and "=" not in parts[0]:
        d["base"] = parts.pop(0)
    for p in parts:
        if "=" not in p:
            raise UsageError(f"grid spec item {p!r} must look like axis=N or axis=lo:hi:N")
        k, v = (s.strip() for s in p.split("=", 1))
        try:
            nums = [float(s) for s in v.split(":")]
        except ValueError:
            raise UsageError(f"grid spec item {p!r}: not numbers") from None
        if len(nums) == 1:
            d[k] = {"n": nums[0]}
        elif len(nums) == 3:
            d[k] = {"min": nums[0], "max": nums[1], "n": nums[2]}
        else:
            raise UsageError(f"grid spec item {p!r} must look like axis=N or axis=lo:hi:N")
    return grid_from_dict(d, name=text)


def resolve_grid(spec: "str | os.PathLike | Grid | dict | None") -> Grid:
    """A Grid from a preset name, a YAML file path, an inline spec, a mapping or a Grid."""
    if spec is None:
        return paper_grid()
    if isinstance(spec, Grid):
        return spec
    if isinstance(spec, dict):
        return grid_from_dict(spec)
    text = str(spec)
    if text in GRID_PRESETS:
        return GRID_PRESETS[text]()
    path = Path(text)
    if path.suffix.lower() in (".yaml", ".yml", ".json") or path.is_file():
        from daa_sil.config.yaml_input import load_yaml_file  # lazy: start-up time

        try:
            data = load_yaml_file(path, "grid")  # bounded size, depth and aliases; one-line errors
        except FileNotFoundError:
            raise UsageError(f"grid file {path} does not exist") from None
        except FileFormatError as exc:
            raise FileFormatError(f"cannot read grid file {exc}") from None
        return grid_from_dict(data or {}, name=path.stem)
    if "=" in text:
        return parse_inline(text)
    raise UsageError(f"unknown grid {text!r}; use {', '.join(GRID_PRESETS)}, a YAML file, or axis=N,... ")
