"""Alerting with state: DAIDALUS-style hysteresis, M-of-N and persistence (sans-IO, batched).

:class:`DaaState` carries, for N encounters and M intruders, what DAIDALUS keeps between calls
(``HysteresisData``, ``MofN``, ``BandsHysteresis``; rules restated in ``docs/daa.md``). It is used
only when ``cfg.hysteresis_s > 0`` (the ``daidalus`` preset: hysteresis 5 s, persistence 4 s, M-of-N
2 of 4). Every update takes the sim time ``t`` (s) and works on arrays; nothing here reads a clock.

Alerts, per intruder:

* the level of the previous output uses its *early* alerting time (75 / 75 / 55 s instead of 55 / 55 /
  25 s) when the raw level is computed (:meth:`DaaState.early_alert_level`);
* **M of N**: the output is the highest level reached by at least M of the last N raw levels (the queue
  is seeded with M copies of the first raw level, so the first output is the raw level);
* **persistence**: a raised level is not lowered until ``persistence_s`` after it was raised;
* **reset**: all history is dropped when more than ``hysteresis_s`` passes between updates, or when
  time does not advance.

Bands, per axis: M of N of the region of every value on a fixed grid of absolute values (one bin per
band step), and persistence of the conflict band that holds the current value (for ``persistence_s``
it keeps its region even if the raw bands weaken). Resolutions, per axis: the previous resolution on a
side is kept while it stays in the same conflict-free region and (persistence time not elapsed, or it
is within the persistence delta of the new one, or the new one needs a larger recovery cylinder
reduction); the preferred direction is kept for ``persistence_s`` and while the two sides are within the
delta, and never switched to the side with the larger recovery reduction.

``DaaState[idx]`` selects encounters; updates for a subset of encounters (the agent computes bands
only for active encounters) use ``rows``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace

import numpy as np

from daa_sil.geometry.frames import wrap_pi
from .bands import AxisBands, Bands, gap_regions, resolutions
from .config import AXIS_HORIZONTAL, AXIS_SPEED, AXIS_VERTICAL, REGION_MID, REGION_NEAR, REGION_RECOVERY, DaaConfig

#: DAIDALUS ``orderOfRegion``: NONE 0, FAR 1, MID 2, NEAR 3, RECOVERY 4 (our region codes are the same)
CONFLICT_CODES = (1, REGION_MID, REGION_NEAR)


def mofn_output(queue: np.ndarray, m: int) -> np.ndarray:
    """M-of-N value of queues ``(..., N)`` (int, -1 = none): the M-th largest entry (-1 if negative)."""
    srt = np.sort(queue, axis=-1)
    out = srt[..., -m]
    return np.where(out < 0, -1, out)


def seeded_queue(value: np.ndarray, m: int, n: int) -> np.ndarray:
    """An M-of-N queue ``(..., N)`` seeded with M copies of ``value`` and N - M empty (-1) slots (oldest first)."""
    q = np.full(np.shape(value) + (n,), -1, np.int8)
    q[..., :m] = np.asarray(value, np.int8)[..., None]
    return q


def push(queue: np.ndarray, value: np.ndarray) -> np.ndarray:
    """The queue with its oldest entry dropped and ``value`` appended (a new array)."""
    return np.concatenate([queue[..., 1:], np.asarray(value, np.int8)[..., None]], axis=-1)


def _stale(last_time: np.ndarray, t: float, hysteresis_s: float) -> np.ndarray:
    """History to drop: never updated, time did not advance, or the gap exceeds the hysteresis time."""
    return np.isnan(last_time) | (t <= last_time) | (t - last_time > hysteresis_s)


@dataclass
class AxisState:
    """Band and resolution hysteresis of one axis for N encounters (see the module docstring)."""

    last_time: np.ndarray  #: (N,) s, last update (nan = none)
    queue: np.ndarray  #: (N, B, Nq) int8 M-of-N queues of the region per absolute bin
    cr_region: np.ndarray  #: (N,) int8 remembered conflict region of the current value (-1 = none)
    cr_lo: np.ndarray  #: (N,) its band, absolute (rad or m/s)
    cr_hi: np.ndarray
    cr_time: np.ndarray  #: (N,) s, when that region was set (nan = persistence inactive)
    res_lo: np.ndarray  #: (N,) resolutions after hysteresis (nan = none)
    res_hi: np.ndarray
    nf_lo: np.ndarray  #: (N,) recovery cylinder reductions of those resolutions
    nf_hi: np.ndarray
    pref_up: np.ndarray  #: (N,) bool, preferred direction right / up / faster
    time_of_dir: np.ndarray  #: (N,) s (nan = none)

    @classmethod
    def initial(cls, n: int, bins: int, nq: int) -> "AxisState":
        nan = np.full(n, np.nan)
        return cls(nan.copy(), np.full((n, bins, nq), -1, np.int8), np.full(n, -1, np.int8), nan.copy(), nan.copy(),
                   nan.copy(), nan.copy(), nan.copy(), np.zeros(n, np.int16), np.zeros(n, np.int16), np.zeros(n, bool),
                   nan.copy())

    def __getitem__(self, idx) -> "AxisState":
        return AxisState(*(getattr(self, f.name)[idx] for f in fields(self)))

    def copy(self) -> "AxisState":
        return AxisState(*(getattr(self, f.name).copy() for f in fields(self)))

    def put(self, idx, other: "AxisState") -> None:
        for f in fields(self):
            getattr(self, f.name)[idx] = getattr(other, f.name)


@dataclass
class DaaState:
    """Hysteresis state of N encounters x M intruders (module docstring). Mutable; copy before updating
    if the previous state must be kept (:func:`daa_sil.agent.step.agent_step` does)."""

    last_time: np.ndarray  #: (N,) s, last alert update (nan = none)
    init_time: np.ndarray  #: (N, M) s, when the current output level was raised (nan = none)
    level: np.ndarray  #: (N, M) int8 last output level (-1 = none)
    queue: np.ndarray  #: (N, M, Nq) int8 M-of-N queue of raw levels
    axes: dict = field(default_factory=dict)  #: axis code -> AxisState

    @classmethod
    def initial(cls, n: int, m: int, cfg: DaaConfig) -> "DaaState":
        """Empty state (no history) for ``n`` encounters and ``m`` intruders."""
        nq = max(cfg.alert_n, 1)
        axes = {a: AxisState.initial(n, grid(cfg, a)[2], nq) for a in (AXIS_HORIZONTAL, AXIS_VERTICAL, AXIS_SPEED)}
        return cls(np.full(n, np.nan), np.full((n, m), np.nan), np.full((n, m), -1, np.int8),
                   np.full((n, m, nq), -1, np.int8), axes)

    def __getitem__(self, idx) -> "DaaState":
        return DaaState(self.last_time[idx], self.init_time[idx], self.level[idx], self.queue[idx],
                        {a: s[idx] for a, s in self.axes.items()})

    def copy(self) -> "DaaState":
        return DaaState(self.last_time.copy(), self.init_time.copy(), self.level.copy(), self.queue.copy(),
                        {a: s.copy() for a, s in self.axes.items()})

    # -- alerts -----------------------------------------------------------------------------------------
    def early_alert_level(self, t: float) -> np.ndarray:
        """(N, M): the level whose early alerting time applies when the raw level is computed at ``t``
        (the last output level, if it was output before ``t``; else -1)."""
        before = ~np.isnan(self.last_time) & (self.last_time < t)
        return np.where(before[:, None], self.level, -1).astype(np.int8)

    def band_early_level(self, t: float) -> np.ndarray:
        """(N, M): the level whose early alerting time selects the bands' conflict aircraft at ``t``
        (the current output level, if it was raised before ``t``; else -1)."""
        return np.where(~np.isnan(self.init_time) & (self.init_time < t), self.level, -1).astype(np.int8)

    def update_alerts(self, t: float, raw: np.ndarray, cfg: DaaConfig) -> np.ndarray:
        """Feed the raw levels ``(N, M)`` at time ``t`` (s); returns the filtered levels (int8)."""
        raw = np.asarray(raw, np.int8)
        m_, n_ = cfg.alert_m, cfg.alert_n
        reset = _stale(self.last_time, t, cfg.hysteresis_s)[:, None] & np.ones(raw.shape, bool)
        self.queue = np.where(reset[..., None], seeded_queue(raw, m_, n_), self.queue)
        self.init_time = np.where(reset, np.nan, self.init_time)
        self.level = np.where(reset, -1, self.level).astype(np.int8)
        self.queue = push(self.queue, raw)
        mofn = mofn_output(self.queue, m_).astype(np.int8)
        keep = (~np.isnan(self.init_time) & (self.level > 0) & (mofn < self.level) & (t >= self.init_time)
                & (t - self.init_time < cfg.persistence_s))
        raised = ~keep & (mofn > 0) & (mofn > self.level)
        self.init_time = np.where(raised, t, self.init_time)
        self.level = np.where(keep, self.level, np.maximum(mofn, 0)).astype(np.int8)
        self.last_time = np.full(self.last_time.shape, float(t))
        return self.level.copy()

    # -- bands ------------------------------------------------------------------------------------------
    def update_bands(self, t: float, bands: Bands, cfg: DaaConfig, rows: "np.ndarray | None" = None) -> Bands:
        """Filter ``bands`` (of encounters ``rows``, default all) at time ``t`` (s): M of N and persistence
        of the regions, then resolution and preferred-direction hysteresis. Returns new :class:`Bands`."""
        rows = np.arange(self.last_time.size) if rows is None else np.asarray(rows)
        out = []
        for ab in bands.axes():
            st = self.axes[ab.axis][rows]
            new_ab, st = _filter_axis(t, ab, st, cfg)
            self.axes[ab.axis].put(rows, st)
            out.append(new_ab)
        return Bands(*out, alert=bands.alert, preset=bands.preset)


def grid(cfg: DaaConfig, axis: int) -> tuple[float, float, int]:
    """(origin, step, bins) of an axis's fixed grid of absolute values (track rad, speeds m/s)."""
    if axis == AXIS_HORIZONTAL:
        return 0.0, cfg.trk_step, int(round(2 * np.pi / cfg.trk_step))
    lo, hi, step = ((-cfg.max_vs, cfg.max_vs, cfg.vs_step) if axis == AXIS_VERTICAL
                    else (cfg.min_gs, cfg.max_gs, cfg.gs_step))
    return lo, step, int(np.floor((hi - lo) / step + 1e-9)) + 1


def _own_value(ab: AxisBands) -> np.ndarray:
    return ab.values[:, ab.k0]


def _bin_regions(ab: AxisBands, cfg: DaaConfig) -> np.ndarray:
    """Region (N, B) at every bin of the axis's fixed grid, from the candidates (uniform steps anchored at
    the current value) and the intervals between them; -1 outside the candidates."""
    origin, step, nb = grid(cfg, ab.axis)
    n, k = ab.region.shape
    u = origin + step * np.arange(nb)[None, :]
    rel = (wrap_pi(u - _own_value(ab)[:, None]) if ab.axis == AXIS_HORIZONTAL else u - _own_value(ab)[:, None]) / step
    pos = rel + ab.k0
    j = np.floor(pos + 1e-9).astype(np.int64)
    frac = pos - j
    on = np.abs(frac) < 1e-6
    inside = (j >= 0) & ((j < k - 1) | (on & (j == k - 1)))
    jj = np.clip(j, 0, k - 1)
    reg = np.take_along_axis(ab.region, jj, 1)
    if k > 1:
        reg = np.where(on, reg, np.take_along_axis(ab.gaps(), np.clip(jj, 0, k - 2), 1))
    return np.where(inside, reg, -1).astype(np.int8)


def _filter_axis(t: float, ab: AxisBands, st: AxisState, cfg: DaaConfig) -> tuple[AxisBands, AxisState]:
    """One axis: M of N of the bin regions, band persistence, then resolution hysteresis."""
    m_, n_ = cfg.alert_m, cfg.alert_n
    origin, step, nb = grid(cfg, ab.axis)
    n, k = ab.region.shape
    reset = _stale(st.last_time, t, cfg.hysteresis_s)
    if reset.any():
        blank = AxisState.initial(int(reset.sum()), nb, st.queue.shape[-1])
        st.put(np.flatnonzero(reset), blank)
    raw_bins = _bin_regions(ab, cfg)
    queue = np.where(reset[:, None, None], seeded_queue(raw_bins, m_, n_), st.queue)
    queue = push(queue, raw_bins)
    filt = mofn_output(queue, m_)
    st = replace(st, queue=queue, last_time=np.full(n, float(t)))
    # back to the candidates: where the filtered bin differs from the raw one, the candidate takes it
    vals = ab.values
    b = np.rint(((vals - origin) % (2 * np.pi) if ab.axis == AXIS_HORIZONTAL else vals - origin) / step)
    b = np.asarray(b, np.int64) % nb if ab.axis == AXIS_HORIZONTAL else np.clip(np.asarray(b, np.int64), 0, nb - 1)
    f_c = np.take_along_axis(filt, b, 1)
    r_c = np.take_along_axis(raw_bins, b, 1)
    changed = (f_c != r_c) & (f_c >= 0)
    region = np.where(changed, f_c, ab.region).astype(np.int8)
    # band persistence: the conflict band that held the current value keeps its region for persistence_s
    region, st = _band_persistence(t, ab, region, st, cfg)
    altered = (region != ab.region).any(axis=1)
    gap = ab.gaps().copy()
    if altered.any():
        gap[altered] = gap_regions(region[altered])
    res_lo, res_hi, pref = resolutions(region, ab.values, ab.delta, ab.side, ab.t_man, ab.k0, ab.axis, cfg,
                                       ab.own_mask())
    res_lo, res_hi, pref, st = _resolution_hysteresis(t, ab, region, res_lo, res_hi, st, cfg)
    new = ab.with_fields(region=region, gap_region=gap, res_lo=res_lo, res_hi=res_hi, preferred=pref)
    return new, st


def _band_persistence(t, ab: AxisBands, region, st: AxisState, cfg: DaaConfig):
    if not (cfg.bands_persistence and cfg.persistence_s > 0):
        return region, st
    n, k = region.shape
    k0 = ab.k0
    cur = region[:, k0].astype(np.int16)
    known = np.isfinite(st.cr_lo) & np.isfinite(st.cr_hi)
    cr = st.cr_region.astype(np.int16)
    cr_conflict = np.isin(cr, CONFLICT_CODES)
    cr_time = np.where(known, st.cr_time, t)
    hold = (known & cr_conflict & ~np.isnan(cr_time) & (cur < cr) & (t >= cr_time)
            & (t - cr_time < cfg.persistence_s))
    if hold.any():
        lo, hi = _relative(ab, st.cr_lo), _relative(ab, st.cr_hi)
        d = ab.delta
        span = (d >= np.minimum(lo, hi)[:, None] - 1e-9) & (d <= np.maximum(lo, hi)[:, None] + 1e-9)
        paint = hold[:, None] & span & (region.astype(np.int16) < cr[:, None])
        region = np.where(paint, cr[:, None], region).astype(np.int8)
    stronger = known & cr_conflict & ~hold & np.isin(cur, CONFLICT_CODES) & (cur > cr)
    cr_time = np.where(stronger, t, cr_time)
    # remember the conflict band that holds the current value now (or forget it)
    cur = region[:, k0]
    is_conf = np.isin(cur, CONFLICT_CODES) & ~np.isnan(cr_time)
    same = region == cur[:, None]
    run_lo = k0 - (np.cumprod(same[:, k0::-1], axis=1).sum(axis=1) - 1)  # the run of the current region
    run_hi = k0 + np.cumprod(same[:, k0:], axis=1).sum(axis=1) - 1
    rows = np.arange(n)
    lo_v, hi_v = ab.values[rows, run_lo], ab.values[rows, run_hi]
    st = replace(st, cr_region=np.where(is_conf, cur, -1).astype(np.int8), cr_lo=np.where(is_conf, lo_v, np.nan),
                 cr_hi=np.where(is_conf, hi_v, np.nan), cr_time=np.where(is_conf, cr_time, np.nan))
    return region, st


def _relative(ab: AxisBands, value: np.ndarray) -> np.ndarray:
    """Signed change from the current value to absolute ``value`` (track: wrapped to [-pi, pi))."""
    d = value - _own_value(ab)
    return wrap_pi(d) if ab.axis == AXIS_HORIZONTAL else d


def _contiguous(ab: AxisBands, region, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(N,) every candidate whose change from the current value lies between ``a`` and ``b`` (signed
    changes) is conflict-free (NONE or RECOVERY): the two resolutions are in one conflict-free region."""
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    between = (ab.delta >= lo[:, None] - 1e-9) & (ab.delta <= hi[:, None] + 1e-9)
    ok = (region == 0) | (region == REGION_RECOVERY)
    return np.all(ok | ~between, axis=1) & np.any(between, axis=1)


def _resolution_hysteresis(t, ab: AxisBands, region, raw_lo, raw_hi, st: AxisState, cfg: DaaConfig):
    """DAIDALUS ``resolutionsHysteresis`` + ``preferredDirectionHysteresis`` (module docstring)."""
    with np.errstate(invalid="ignore"):  # +-inf resolutions: their differences are nan and compare False
        return _resolution_hysteresis_(t, ab, region, raw_lo, raw_hi, st, cfg)


def _resolution_hysteresis_(t, ab: AxisBands, region, raw_lo, raw_hi, st: AxisState, cfg: DaaConfig):
    delta = {AXIS_HORIZONTAL: cfg.pref_delta_trk, AXIS_VERTICAL: cfg.pref_delta_vs, AXIS_SPEED: cfg.pref_delta_gs}[ab.axis]
    circular = ab.axis == AXIS_HORIZONTAL
    mod = 2 * np.pi if circular else 0.0
    val = _own_value(ab)
    nfactor = np.asarray(ab.recovery_nfactor, np.int16)
    persist = cfg.persistence_s

    def smod(x):  # DAIDALUS safe_modulo: the value itself when mod is 0
        return np.mod(x, mod) if circular else x

    no_hyst = np.isnan(st.time_of_dir) | (t <= st.time_of_dir) | (delta <= 0) | (cfg.hysteresis_s <= 0)
    res_lo, res_hi = st.res_lo.copy(), st.res_hi.copy()
    nf_lo, nf_hi = st.nf_lo.copy(), st.nf_hi.copy()
    within = (t - st.time_of_dir) < persist
    # up / right side
    same_side_up = _relative(ab, res_hi) >= -1e-12 if circular else res_hi >= val - 1e-12
    keep_up = (~no_hyst & np.isfinite(raw_hi) & np.isfinite(res_hi) & same_side_up
               & (within | (nf_hi < nfactor) | (smod(res_hi - raw_hi) < delta))
               & _contiguous(ab, region, _relative(ab, raw_hi), _relative(ab, res_hi)))
    same_side_lo = _relative(ab, res_lo) <= 1e-12 if circular else res_lo <= val + 1e-12
    keep_lo = (~no_hyst & np.isfinite(raw_lo) & np.isfinite(res_lo) & same_side_lo
               & (within | (nf_lo < nfactor) | (smod(raw_lo - res_lo) < delta))
               & _contiguous(ab, region, _relative(ab, raw_lo), _relative(ab, res_lo)))
    res_hi, nf_hi = np.where(keep_up, res_hi, raw_hi), np.where(keep_up, nf_hi, nfactor)
    res_lo, nf_lo = np.where(keep_lo, res_lo, raw_lo), np.where(keep_lo, nf_lo, nfactor)
    time_of_dir = np.where(no_hyst, np.nan, st.time_of_dir)
    # preferred direction
    pref = st.pref_up.copy()
    fin_up, fin_lo = np.isfinite(raw_hi), np.isfinite(raw_lo)
    none = ~fin_up & ~fin_lo
    switch = np.zeros_like(pref)
    target = pref.copy()
    only_lo = ~fin_up & fin_lo & pref
    only_up = fin_up & ~fin_lo & ~pref
    switch |= only_lo | only_up
    target = np.where(only_lo, False, np.where(only_up, True, target))
    both = fin_up & fin_lo
    d_up = smod(raw_hi - val)
    d_dn = smod(val - raw_lo)
    actual = d_up <= d_dn + 1e-9 * np.maximum(np.abs(d_dn), 1.0)
    fresh = both & (np.isnan(time_of_dir) | (t < time_of_dir) | (delta <= 0) | (cfg.hysteresis_s <= 0))
    pref = np.where(fresh, actual, pref)
    time_of_dir = np.where(fresh, t, time_of_dir)
    held = both & ~fresh & (((t - time_of_dir) < persist) | (np.abs(d_up - d_dn) < delta))
    larger_nf = both & ~fresh & ~held & ((pref & (nf_lo > nf_hi)) | (~pref & (nf_hi > nf_lo)))
    change = both & ~fresh & ~held & ~larger_nf & (pref != actual)
    switch |= change
    target = np.where(change, actual, target)
    # switch_dir: new direction now; the raw resolution replaces a kept one unless its reduction was larger
    pref = np.where(switch, target, pref)
    time_of_dir = np.where(switch, t, time_of_dir)
    res_lo = np.where(switch & (nfactor <= nf_lo), raw_lo, res_lo)
    res_hi = np.where(switch & (nfactor <= nf_hi), raw_hi, res_hi)
    pref = np.where(none, False, pref)
    time_of_dir = np.where(none, np.nan, time_of_dir)
    st = replace(st, res_lo=res_lo, res_hi=res_hi, nf_lo=nf_lo.astype(np.int16), nf_hi=nf_hi.astype(np.int16),
                 pref_up=pref, time_of_dir=time_of_dir)
    out_pref = np.where(none, 0, np.where(pref, 1, -1)).astype(np.int8)
    return res_lo, res_hi, out_pref, st


__all__ = ["DaaState", "AxisState", "mofn_output", "seeded_queue", "push", "grid"]
