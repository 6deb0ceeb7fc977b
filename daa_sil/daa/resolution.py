"""Maneuver search (paper Algorithm 2), the onboard DAA's own resolution, command classification.

All candidates come from the kinematic bands (:mod:`daa_sil.daa.bands`): single-axis maneuvers
(one of track / vertical speed / ground speed changed, the others held). A candidate is **safe**
when its first LoWC time exceeds the SM horizon (``SM > 0``, :func:`daa_sil.daa.safety_metric`).
"""

from __future__ import annotations

from functools import cached_property

import numpy as np

from daa_sil.daa import kernels
from daa_sil.geometry.frames import TWO_PI, wrap_pi
from daa_sil.geometry.kinematics import AircraftState, Command
from daa_sil.geometry.units import DEG, FPM, KT
from .bands import Bands, compute_bands
from .intervals import as_vector
from .config import (AXIS_HORIZONTAL, AXIS_NAMES, AXIS_NONE, AXIS_SPEED, AXIS_VERTICAL, DIR_AXIS, DIR_SIDE,
                     REGION_NONE, REGION_RECOVERY, RULE_ANY, RULE_AXIS, RULE_AXIS_DIR, RULE_BEST_EFFORT, DaaConfig,
                     axis_code, dir_code, side_to_dir)

#: False: :func:`classify_command`, :func:`search_maneuver` and :func:`resolve` in numpy (the oracles of
#: ``kernels.elementwise.classify_command_into``, ``kernels.select.search_into`` and ``resolution_into``)
COMPILED = True
#: changes below these are "no change" when classifying a command
CLASSIFY_DEADBAND = {"trk": 0.5 * DEG, "vs": 50.0 * FPM, "gs": 1.0 * KT}


def command_deltas(state: AircraftState, cmd: Command) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Signed changes (track rad, - = left; vs m/s; gs m/s) that ``cmd`` asks for; nan fields are 0."""
    c = cmd.resolved(state)
    return wrap_pi(c.trk - state.trk), c.vs - state.vs, c.gs - state.gs


def classify_command(state: AircraftState, cmd: Command, cfg: "DaaConfig | None" = None
                     ) -> tuple[np.ndarray, np.ndarray]:
    """(axis, direction) codes (int8 arrays) of a command relative to the current state.

    The axis is the one whose change takes longest at the kinematic limits (turn rate, vertical
    and horizontal acceleration); changes within :data:`CLASSIFY_DEADBAND` do not count, and a
    command with no change is ``(none, none)``. Direction: left/right, up/down, faster/slower.
    """
    cfg = cfg or DaaConfig()
    if COMPILED and np.ndim(state.trk) == 1:
        n = np.shape(state.trk)[0]
        out = np.empty(n, np.int8), np.empty(n, np.int8)
        kernels.get().classify_command_into(
            *(as_vector(a, n) for a in (state.trk, state.vs, state.gs, cmd.trk, cmd.vs, cmd.gs)), CLASSIFY_DEADBAND["trk"],
            CLASSIFY_DEADBAND["vs"], CLASSIFY_DEADBAND["gs"], float(cfg.turn_rate), float(cfg.vertical_accel),
            float(cfg.horizontal_accel), np.pi, TWO_PI, *out)
        return out
    dtrk, dvs, dgs = command_deltas(state, cmd)
    dtrk = np.where(np.abs(dtrk) < CLASSIFY_DEADBAND["trk"], 0.0, dtrk)
    dvs = np.where(np.abs(dvs) < CLASSIFY_DEADBAND["vs"], 0.0, dvs)
    dgs = np.where(np.abs(dgs) < CLASSIFY_DEADBAND["gs"], 0.0, dgs)
    times = np.stack([np.abs(dtrk) / cfg.turn_rate, np.abs(dvs) / cfg.vertical_accel,
                      np.abs(dgs) / cfg.horizontal_accel], axis=-1)
    ax = np.argmax(times, axis=-1) + 1
    moved = times.max(axis=-1) > 0
    side = np.choose(ax - 1, [np.sign(dtrk), np.sign(dvs), np.sign(dgs)])
    axis = np.where(moved, ax, AXIS_NONE).astype(np.int8)
    return axis, np.where(moved, side_to_dir(axis, side), 0).astype(np.int8)


class _Candidates:
    """All single-axis candidates of the three axes concatenated: arrays (N, K) and (K,)."""

    def __init__(self, own: AircraftState, bands: Bands):
        ab = bands.axes()
        self._ab = ab
        self.axis = np.concatenate([np.full(a.side.shape, a.axis) for a in ab])
        self.side = np.concatenate([a.side for a in ab])
        sizes = np.cumsum([0] + [len(a.side) for a in ab])
        #: column slice of each axis code in the concatenated arrays
        self.cols = {a.axis: slice(int(sizes[k]), int(sizes[k + 1])) for k, a in enumerate(ab)}
        self.own = own

    def _cat(self, name: str) -> np.ndarray:
        return np.concatenate([getattr(a, name) for a in self._ab], axis=1)

    @cached_property
    def values(self) -> np.ndarray:
        return self._cat("values")

    @cached_property
    def delta(self) -> np.ndarray:
        return self._cat("delta")

    @cached_property
    def t_man(self) -> np.ndarray:
        return self._cat("t_man")

    @cached_property
    def t_in(self) -> np.ndarray:
        return self._cat("t_in")

    @cached_property
    def t_out(self) -> np.ndarray:
        return self._cat("t_out")

    @cached_property
    def region(self) -> np.ndarray:
        return self._cat("region")

    @staticmethod
    def take(a: np.ndarray, idx: np.ndarray) -> np.ndarray:
        return np.take_along_axis(a, idx[:, None], -1)[:, 0]

    def at(self, name: str, idx: np.ndarray) -> np.ndarray:
        """Field ``name`` of candidate ``idx[i]`` of encounter i (as ``take(self.<name>, idx)``, without
        concatenating the axes)."""
        out = None
        for a in self._ab:
            c = self.cols[a.axis]
            sel = np.flatnonzero((idx >= c.start) & (idx < c.stop))
            vals = a.pick(name, sel, idx[sel] - c.start)
            if out is None:
                out = np.empty(idx.shape, vals.dtype)
            out[sel] = vals
        return out

    def rows(self, name: str, rows: np.ndarray) -> np.ndarray:
        """Field ``name`` of encounters ``rows`` (as ``self.<name>[rows]``)."""
        return np.concatenate([a.sub(name, rows) for a in self._ab], axis=1)

    @cached_property
    def own_cols(self) -> np.ndarray:
        """(N, K) bool: each encounter's own candidates (``AxisBands.own_mask``)."""
        return np.concatenate([np.ones(a.values.shape, bool) if a.own_mask() is None else a.own_mask()
                               for a in self._ab], axis=1)

    def command(self, idx: np.ndarray) -> Command:
        """Command of candidate ``idx`` (N,): the candidate's axis set, the other axes held."""
        ax, val = self.axis[idx], self.at("values", idx)
        o = self.own
        return Command(np.where(ax == AXIS_HORIZONTAL, val, o.trk), np.where(ax == AXIS_VERTICAL, val, o.vs),
                       np.where(ax == AXIS_SPEED, val, o.gs))

    def best_effort(self, rows: np.ndarray) -> np.ndarray:
        """Best-effort candidate index for ``rows``: latest first LoWC, then earliest regain of well clear."""
        if rows.size == 0:
            return np.zeros(0, int)
        t_in = np.minimum(self.rows("t_in", rows), 1e6)
        score = t_in * 1e3 - np.maximum(self.rows("t_out", rows), 0.0)
        return np.argmax(np.where(self.own_cols[rows], score, -np.inf), axis=-1)  # (another row's column never wins)


def _pick(mask, cost):
    c = np.where(mask, cost, np.inf)
    idx = np.argmin(c, axis=-1)
    return idx, np.isfinite(np.take_along_axis(c, idx[:, None], -1)[:, 0])


def _codes(val, n: int, conv) -> np.ndarray:
    if isinstance(val, str) or np.ndim(val) == 0:
        return np.full(n, conv(val if isinstance(val, str) else int(val)), np.int8)
    arr = np.asarray(val)
    if arr.dtype.kind in "US":
        return np.array([conv(str(x)) for x in arr], np.int8)
    return arr.astype(np.int8)


def search_maneuver(own: AircraftState, intr: AircraftState, axis, direction, cfg: "DaaConfig | None" = None,
                    ref: "Command | None" = None, horizon_s: "float | None" = None,
                    bands: "Bands | None" = None, return_t_in: bool = False) -> tuple[Command, np.ndarray]:
    """Paper Algorithm 2 (batched): a safe maneuver for the pilot's (axis, direction).

    ``axis``/``direction``: names or codes, scalar or ``(N,)``. ``ref``: the pilot's command (the
    candidate closest to it on the axis is preferred; default the current state). Safe means
    ``SM > 0`` with ``horizon_s`` (default ``cfg.sm_horizon_s``). Rules, first that succeeds:
    1 ``axis_dir`` safe candidate on the axis in the direction, closest to ``ref``;
    2 ``axis`` safe candidate on the axis (either side, not the current value), closest to ``ref``;
    3 ``any`` safe candidate of any axis (the current value included) reached soonest;
    4 ``best_effort`` the candidate with the largest SM (latest LoWC, then earliest recovery).
    Returns ``(Command, rule)`` with rule codes ``RULE_*`` (int8, N) (plus the chosen candidate's first
    LoWC time, s, with ``return_t_in``).
    """
    cfg = cfg or DaaConfig()
    n = own.shape[0]
    bands = bands if bands is not None else compute_bands(own, intr, cfg)
    cand = _Candidates(own, bands)
    horizon = cfg.sm_horizon_s if horizon_s is None else float(horizon_s)
    ax = _codes(axis, n, axis_code)
    dc = _codes(direction, n, dir_code)
    side = np.asarray(DIR_SIDE)[dc]
    ax = np.where((np.asarray(DIR_AXIS)[dc] != ax) & (dc != 0), np.asarray(DIR_AXIS)[dc], ax)
    # distance to the reference along the candidate's own axis, in seconds of maneuvering
    rates = np.array([1.0, cfg.turn_rate, cfg.vertical_accel, cfg.horizontal_accel])
    ref_d = np.zeros((n, 4))
    if ref is not None:
        d = command_deltas(own, ref)
        ref_d[:, 1], ref_d[:, 2], ref_d[:, 3] = d
    ref_t = ref_d / rates
    if COMPILED and n and all(a is not None for a in bands.axes()):  # one pass per row, the bands read in place
        idx, rule = np.empty(n, np.int64), np.empty(n, np.int8)
        src = [a.source() for a in bands.axes()]
        rows = [np.arange(n) if r is None else r for _, r in src]
        field = lambda name: tuple(getattr(b, name) for b, _ in src)  # noqa: E731
        own = [b.own_range() for b, _ in src]
        kernels.get().search_into(field("delta"), field("t_man"), field("t_in"), field("t_out"), tuple(rows),
                                  tuple(o[0] for o in own), tuple(o[1] for o in own),
                                  tuple(np.asarray(a.side, np.int64) for a in bands.axes()), ax.astype(np.int64),
                                  side.astype(np.int64), ref_t, rates, horizon, idx, rule)
        if return_t_in:
            return cand.command(idx), rule, cand.at("t_in", idx)
        return cand.command(idx), rule
    safe = (cand.t_in > horizon) & cand.own_cols
    cand_t = cand.delta / rates[cand.axis]
    dist = np.abs(cand_t - ref_t[:, cand.axis])
    on_axis = (cand.axis[None, :] == ax[:, None]) & (ax[:, None] != AXIS_NONE)
    moving = cand.side[None, :] != 0
    i1, f1 = _pick(safe & on_axis & moving & (cand.side[None, :] == side[:, None]) & (side[:, None] != 0), dist)
    i2, f2 = _pick(safe & on_axis & moving, dist)
    i3, f3 = _pick(safe, cand.t_man)
    i4 = np.zeros(n, int)
    rest = np.nonzero(~(f1 | f2 | f3))[0]
    i4[rest] = cand.best_effort(rest)
    idx = np.where(f1, i1, np.where(f2, i2, np.where(f3, i3, i4)))
    rule = np.where(f1, RULE_AXIS_DIR, np.where(f2, RULE_AXIS, np.where(f3, RULE_ANY, RULE_BEST_EFFORT)))
    if return_t_in:
        return cand.command(idx), rule.astype(np.int8), cand.take(cand.t_in, idx)
    return cand.command(idx), rule.astype(np.int8)


def resolve(own: AircraftState, intr: AircraftState, cfg: "DaaConfig | None" = None,
            prev: "tuple[np.ndarray, np.ndarray] | None" = None, bands: "Bands | None" = None,
            return_t_in: bool = False) -> tuple[Command, np.ndarray, np.ndarray]:
    """The onboard DAA resolution with its (axis, direction) codes (and, with ``return_t_in``, its
    first LoWC time in s); see :func:`daa_resolution`."""
    cfg = cfg or DaaConfig()
    n = own.shape[0]
    bands = bands if bands is not None else compute_bands(own, intr, cfg)
    cand = _Candidates(own, bands)
    k0 = np.nonzero((cand.axis == AXIS_HORIZONTAL) & (cand.side == 0))[0][0]
    in_conflict = bands.trk.pick("region", slice(None), k0 - cand.cols[AXIS_HORIZONTAL].start) != REGION_NONE
    axes = bands.axes()
    src = [a.source() for a in axes] if COMPILED and n and all(a is not None for a in axes) else None
    if src and all(b.region.dtype == np.int8 and b.preferred.dtype == np.int8 for b, _ in src):
        # one pass per row, the bands read in place (kernels.select.resolution_into)
        chosen = np.empty(n, np.int64)
        rows = [np.arange(n) if r is None else r for _, r in src]
        field = lambda name: tuple(getattr(b, name) for b, _ in src)  # noqa: E731
        if prev is not None:
            p_ax, p_dir = (np.asarray(a).astype(np.int64) for a in prev)
            p_side = np.asarray(DIR_SIDE, np.int64)[p_dir]
        else:
            p_ax = p_side = np.zeros(n, np.int64)
        own = [b.own_range() for b, _ in src]
        kernels.get().resolution_into(field("region"), field("t_man"), field("preferred"), field("t_in"),
                                      field("t_out"), tuple(rows), tuple(o[0] for o in own), tuple(o[1] for o in own),
                                      tuple(np.asarray(a.side, np.int64) for a in axes), in_conflict, prev is not None,
                                      p_ax, p_side, np.array([axis_code(a) for a in cfg.resolution_axes], np.int64),
                                      chosen)
    else:
        chosen = _resolve_numpy(cand, bands, cfg, n, in_conflict, prev)
    hold = chosen < 0
    idx = np.where(hold, k0, chosen)
    cmd = cand.command(idx)
    axis = np.where(hold, AXIS_NONE, cand.axis[idx]).astype(np.int8)
    direction = np.where(hold, 0, side_to_dir(axis, cand.side[idx])).astype(np.int8)
    if return_t_in:
        return cmd, axis, direction, cand.at("t_in", idx)
    return cmd, axis, direction


def _resolve_numpy(cand: _Candidates, bands: Bands, cfg: DaaConfig, n: int, in_conflict: np.ndarray,
                   prev) -> np.ndarray:
    """The candidate :func:`resolve` chooses per row (-1: none, not in conflict), in numpy (the oracle of
    ``kernels.select.resolution_into``)."""
    moving = cand.side[None, :] != 0
    chosen = np.full(n, -1)
    p_ax = np.full(n, AXIS_NONE)
    # (each step works on the rows it can still change only)
    # 1. persistence: keep the previous (axis, direction) while it still has a conflict-free candidate
    if prev is not None:
        p_ax, p_dir = (np.asarray(a).astype(int) for a in prev)
        p_side = np.asarray(DIR_SIDE)[p_dir]
        r = np.flatnonzero((p_ax != AXIS_NONE) & in_conflict)
        if r.size:
            region = cand.rows("region", r)
            okr = ((region == REGION_NONE) | (region == REGION_RECOVERY)) & cand.own_cols[r]
            m = okr & (cand.axis[None, :] == p_ax[r, None]) & (cand.side[None, :] == p_side[r, None]) & moving
            i, f = _pick(m, cand.rows("t_man", r))
            chosen[r] = np.where(f, i, chosen[r])
    # 2. fresh: first axis in priority order with a NONE resolution on its preferred side, then RECOVERY.
    #    No reversal first: when the previous direction has lost its conflict-free candidates (the
    #    intruder did not fly the straight line it was projected on, e.g. it turns toward us), the
    #    other axes are tried before the opposite direction of the same axis.
    for want in (REGION_NONE, REGION_RECOVERY):
        for allow_reversal in (False, True):
            for name in cfg.resolution_axes:
                if not np.any((chosen < 0) & in_conflict):
                    break
                a = axis_code(name)
                ab, cols = bands.axis(a), cand.cols[a]
                r = np.flatnonzero((chosen < 0) & in_conflict & (allow_reversal | (p_ax != a)))
                if not r.size:
                    continue
                ok = (ab.sub("region", r) == want) & (ab.side != 0)[None, :] & cand.own_cols[r, cols]
                pref = ab.sub("preferred", r).astype(int)
                m_side = (ab.side[None, :] == pref[:, None]) | (pref[:, None] == 0)
                t_man = ab.sub("t_man", r)
                i, f = _pick(ok & m_side, t_man)
                i_any, f_any = _pick(ok, t_man)
                i = np.where(f, i, i_any) + cols.start
                chosen[r] = np.where(f | f_any, i, chosen[r])
    # 3. best effort
    rest = np.nonzero((chosen < 0) & in_conflict)[0]
    chosen[rest] = cand.best_effort(rest)
    return chosen


def daa_resolution(own: AircraftState, intr: AircraftState, cfg: "DaaConfig | None" = None,
                   prev: "tuple[np.ndarray, np.ndarray] | None" = None, bands: "Bands | None" = None) -> Command:
    """The onboard DAA's own resolution command (batched).

    Not in conflict (current trajectory NONE) -> hold the current state. In conflict:
    1. persistence: ``prev = (axis, direction)`` codes of the previous resolution are kept while that
       axis/side still has a NONE or RECOVERY candidate (closest one taken);
    2. otherwise the first axis of ``cfg.resolution_axes`` (horizontal, vertical, speed) with a NONE
       candidate, on its preferred side (DAIDALUS: reached sooner, ties right/up/faster), closest
       one -- except that when step 1 failed, the previous axis comes last (no reversal while
       another axis resolves: a reversal chases an intruder that is turning into the resolution);
       then the same with RECOVERY candidates;
    3. otherwise the best-effort candidate (latest LoWC, then earliest recovery).
    """
    return resolve(own, intr, cfg, prev, bands)[0]


__all__ = ["classify_command", "command_deltas", "search_maneuver", "daa_resolution", "resolve", "AXIS_NAMES"]
