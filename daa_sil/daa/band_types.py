"""The bands' data types: :class:`AxisBands` (one axis's candidates, regions, resolutions and recovery for N
encounters), its rows views, :class:`Bands` (the three axes) and :func:`gap_regions`. The bands themselves
are made by :mod:`daa_sil.daa.bands`."""

from __future__ import annotations

import functools
from dataclasses import MISSING, dataclass, fields

import numpy as np

from .config import AXIS_HORIZONTAL, AXIS_NAMES, AXIS_SPEED, AXIS_VERTICAL, REGION_MID, REGION_NAMES, REGION_RECOVERY


@functools.lru_cache(maxsize=256)
def column_sides(j_lo: int, j_hi: int) -> np.ndarray:
    """The side of each column (K,) -1 / 0 / +1: ``j_lo`` low-side candidates, the current value, ``j_hi`` high-side
    ones (read-only; made once per pair of counts)."""
    side = np.concatenate([-np.ones(j_lo, np.int64), [0], np.ones(j_hi, np.int64)])
    side.setflags(write=False)
    return side


@dataclass
class AxisBands:
    """Candidates of one axis for N encounters; K candidates ordered from the low side to the high side.

    ``values`` (N, K) absolute (track rad [0, 2pi) / vs m/s / gs m/s; a speed candidate past a limit is
    shown at the limit); ``delta`` (N, K) signed change from the current value (rad or m/s; track:
    - = left); ``side`` (K,) -1/0/+1; ``t_man`` (N, K) s to reach; ``t_in`` (N, K) first LoWC with any
    intruder over the lookahead (inf = none); ``t_out`` (N, K) last exit from a conflicting violation;
    ``region`` (N, K) REGION_* codes; ``gap_region`` (N, K-1) region of the open interval between
    candidates k and k+1; ``res_lo``, ``res_hi`` (N,) resolutions (nan = no conflict, -inf / +inf = no
    resolution on that side); ``preferred`` (N,) side -1/0/+1; ``recovery_time`` (N,) s (nan = no
    recovery bands, -inf = saturated); ``recovery_nfactor`` (N,) cylinder shrinks (-1 = none);
    ``recovery_h``/``recovery_v`` (N,) m, the cylinder the recovery band keeps clear of; ``own_lo``/``own_hi``
    (N,) the first and last column of each encounter's own candidates (None: every column). A speed axis's
    encounters have their own candidate counts: the columns past an encounter's own candidates repeat its
    outermost one on that side, and every reading that picks a candidate looks at its own columns only
    (:meth:`own_mask`), so it finds what it finds in a call of its own.
    """

    axis: int
    values: np.ndarray
    delta: np.ndarray
    side: np.ndarray
    t_man: np.ndarray
    t_in: np.ndarray
    t_out: np.ndarray
    region: np.ndarray
    res_lo: np.ndarray
    res_hi: np.ndarray
    preferred: np.ndarray
    gap_region: "np.ndarray | None" = None
    recovery_time: "np.ndarray | None" = None
    recovery_nfactor: "np.ndarray | None" = None
    recovery_h: "np.ndarray | None" = None
    recovery_v: "np.ndarray | None" = None
    own_lo: "np.ndarray | None" = None
    own_hi: "np.ndarray | None" = None

    def __post_init__(self):
        n = self.values.shape[0]
        for name, fill in (("recovery_time", np.nan), ("recovery_nfactor", -1), ("recovery_h", np.nan),
                           ("recovery_v", np.nan)):
            if getattr(self, name) is None:
                setattr(self, name, np.full(n, fill, np.int16 if name == "recovery_nfactor" else float))

    @property
    def name(self) -> str:
        return AXIS_NAMES[self.axis]

    def with_fields(self, **changes) -> "AxisBands":
        """A plain :class:`AxisBands` with ``changes`` and this one's other fields (``dataclasses.replace``,
        which a rows view of :meth:`rows` cannot take: its constructor is not the dataclass's)."""
        kw = {f.name: getattr(self, f.name) for f in fields(AxisBands)}
        kw.update(changes)
        return AxisBands(**kw)

    def gaps(self) -> np.ndarray:
        """``gap_region`` (computed from ``region`` by :func:`gap_regions` when not given)."""
        if self.gap_region is None:
            self.gap_region = gap_regions(self.region)
        return self.gap_region

    @property
    def k0(self) -> int:
        """Column of the current value."""
        return int(np.nonzero(self.side == 0)[0][0])

    def own_range(self) -> tuple[np.ndarray, np.ndarray]:
        """``(own_lo, own_hi)`` as (N,) int64 arrays (every column when not set)."""
        n, k = self.values.shape
        if self.own_lo is None:
            return np.zeros(n, np.int64), np.full(n, k - 1, np.int64)
        return np.asarray(self.own_lo, np.int64), np.asarray(self.own_hi, np.int64)

    def own_mask(self) -> "np.ndarray | None":
        """(N, K) bool: the columns that are each encounter's own candidates (None: all of them)."""
        if self.own_lo is None:
            return None
        col = np.arange(self.values.shape[1])[None, :]
        return (col >= np.asarray(self.own_lo)[:, None]) & (col <= np.asarray(self.own_hi)[:, None])

    def rows(self, idx) -> "AxisBands":
        """The bands of encounters ``idx`` (an index array or a boolean mask: each field is selected when
        it is first read, and :meth:`sub` / :meth:`pick` select from this object's fields directly)."""
        arr = np.asarray(idx) if isinstance(idx, (np.ndarray, list)) else None
        if arr is None or arr.ndim != 1 or arr.dtype.kind not in "biu":  # (a slice, a scalar: selected now)
            keep = lambda f: f.name in ("axis", "side") or getattr(self, f.name) is None  # noqa: E731
            return AxisBands(**{f.name: (getattr(self, f.name) if keep(f) else getattr(self, f.name)[idx])
                                for f in fields(self)})
        return _AxisRows(self, np.flatnonzero(arr) if arr.dtype.kind == "b" else arr)

    def source(self) -> "tuple[AxisBands, np.ndarray | None]":
        """``(bands, rows)``: these bands are ``bands``' encounters ``rows`` (an integer array), read in place
        (a :meth:`rows` view); ``rows`` None: ``bands`` is this object."""
        return self, None

    def sub(self, name: str, rows) -> np.ndarray:
        """Field ``name`` of encounters ``rows`` (``self.<name>[rows]``, without selecting the whole field of
        a :meth:`rows` first; None for a field that is None)."""
        value = getattr(self, name)
        return None if value is None else value[rows]

    def pick(self, name: str, rows, cols) -> np.ndarray:
        """``self.<name>[rows, cols]`` (as :meth:`sub`)."""
        return getattr(self, name)[rows, cols]

    def intervals(self, i: int = 0) -> list[tuple[float, float, str]]:
        """Bands of encounter ``i`` as ``[(lo, hi, region_name), ...]`` in SI units, low side first.

        Contiguous candidates with the same region are merged; duplicates at a saturated limit
        collapse. Track intervals are in compass radians and may wrap through north.
        """
        vals, reg = self.values[i], self.region[i]
        keep = np.ones(len(vals), bool)
        keep[1:] = ~np.isclose(vals[1:], vals[:-1], rtol=0.0, atol=1e-9)
        vals, reg = vals[keep], reg[keep]
        out: list[tuple[float, float, str]] = []
        start = 0
        for j in range(1, len(vals) + 1):
            if j == len(vals) or reg[j] != reg[start]:
                out.append((float(vals[start]), float(vals[j - 1]), REGION_NAMES[int(reg[start])]))
                start = j
        return out

    def band_intervals(self, i: int = 0) -> list[tuple[float, float, str]]:
        """DAIDALUS-style bands of encounter ``i``: ``[(lo, hi, region_name), ...]`` whose bounds are
        candidate values and whose regions are those of the intervals between candidates (so they cover
        the whole candidate range without gaps); low side first, SI units, tracks may wrap."""
        vals, gap = self.values[i], self.gaps()[i]
        width = np.abs(np.diff(self.delta[i]))
        out: list[tuple[float, float, str]] = []
        for j in range(len(gap)):
            if width[j] <= 1e-12:
                continue
            name = REGION_NAMES[int(gap[j])]
            if out and out[-1][2] == name:
                out[-1] = (out[-1][0], float(vals[j + 1]), name)
            else:
                out.append((float(vals[j]), float(vals[j + 1]), name))
        return out


#: the :class:`AxisBands` fields that are per encounter (``axis`` and ``side`` are not), and those of them
#: without a default (the others are class attributes too, so :class:`_AxisRows` selects them at once)
_ROW_FIELDS = frozenset(f.name for f in fields(AxisBands)) - {"axis", "side"}
_LAZY_FIELDS = frozenset(f.name for f in fields(AxisBands) if f.default is MISSING) & _ROW_FIELDS


class _AxisRows(AxisBands):
    """:meth:`AxisBands.rows`: the bands of encounters ``idx`` (integer array) of ``base``; a per-encounter
    field is ``base``'s at ``idx`` (a copy, as ``base.<field>[idx]``), made when it is first read, and
    :meth:`sub` / :meth:`pick` of a field not made select from ``base`` at once."""

    def __init__(self, base: AxisBands, idx: np.ndarray):  # (not the dataclass's: the fields come from ``base``)
        self._base, self._idx = base, idx
        self.axis, self.side = base.axis, base.side
        for name in _ROW_FIELDS - _LAZY_FIELDS:
            setattr(self, name, base.sub(name, idx))

    def __getattr__(self, name: str):  # (called only for a field not made yet)
        if name not in _ROW_FIELDS or "_base" not in self.__dict__:
            raise AttributeError(name)
        value = self._base.sub(name, self._idx)
        setattr(self, name, value)
        return value

    def source(self) -> "tuple[AxisBands, np.ndarray | None]":
        base, idx = self._base.source()
        return base, (self._idx if idx is None else idx[self._idx])

    def sub(self, name: str, rows) -> np.ndarray:
        if name in self.__dict__ or name not in _ROW_FIELDS:
            return super().sub(name, rows)
        return self._base.sub(name, self._idx[rows])

    def pick(self, name: str, rows, cols) -> np.ndarray:
        if name in self.__dict__ or name not in _ROW_FIELDS:
            return getattr(self, name)[rows, cols]
        return self._base.pick(name, self._idx[rows], cols)


def gap_regions(region: np.ndarray) -> np.ndarray:
    """Region (N, K-1) of the open interval between neighbouring candidates from their regions: the
    more severe of the two; RECOVERY only between two RECOVERY candidates; NONE between NONE and
    RECOVERY."""
    a, b = region[:, :-1].astype(np.int16), region[:, 1:].astype(np.int16)
    ca, cb = np.where(a == REGION_RECOVERY, 0, a), np.where(b == REGION_RECOVERY, 0, b)
    worse = np.maximum(ca, cb)
    both_rec = (a == REGION_RECOVERY) & (b == REGION_RECOVERY)
    return np.where(both_rec, REGION_RECOVERY, worse).astype(np.int8)


@dataclass
class Bands:
    """Bands of the three axes plus the alert levels ``(N, M)`` they were computed with (an axis
    :func:`compute_bands` was not asked for is None)."""

    trk: "AxisBands | None"
    vs: "AxisBands | None"
    gs: "AxisBands | None"
    alert: np.ndarray
    preset: str

    def axes(self) -> tuple[AxisBands, AxisBands, AxisBands]:
        return (self.trk, self.vs, self.gs)

    def axis(self, code: int) -> AxisBands:
        return {AXIS_HORIZONTAL: self.trk, AXIS_VERTICAL: self.vs, AXIS_SPEED: self.gs}[code]

    def in_conflict(self) -> np.ndarray:
        """(N,) bool: the current trajectory (k = 0) is in a conflict region (MID or worse) or RECOVERY."""
        r = self.trk.region[:, self.trk.k0]
        return r >= REGION_MID

    def __getitem__(self, idx) -> "Bands":
        rows = lambda ab: None if ab is None else ab.rows(idx)  # noqa: E731  (an axis not computed stays None)
        return Bands(rows(self.trk), rows(self.vs), rows(self.gs), self.alert[idx], self.preset)


__all__ = ["AxisBands", "Bands", "column_sides", "gap_regions"]
