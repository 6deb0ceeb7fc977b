"""Fast-time results: the per-encounter and per-decision tables of the architecture contract
("Campaign result tables") and their accumulators over the steps (a step's step-log columns are
:func:`daa_sil.onboard.step_columns`, shared with the SIL vehicle). A batch of several parts (:func:`daa_sil.study.simulation.fasttime.simulate_parts`)
accumulates once and cuts one pair of tables per part (a row range of the batch)."""

from __future__ import annotations

from typing import Sequence

import numpy as np
import pyarrow as pa

from daa_sil.agent.decision import (BY_BOTH, BY_MAP, BY_PROJL, CODE_NAMES, D_BLEND, D_DAA_OVERRIDE, D_LINK_LOST,
    D_NO_WAIT, D_PILOT, D_STALE, D_WAIT)
from daa_sil.geometry.kinematics import AircraftState
from daa_sil.onboard import StepOutput

_I = pa.int64()
#: commands the link released in a step besides the newest (superseded within their step, never decided
#: on), counted with the freshness and the decision of the newest: over the whole encounter and the
#: active phase, and by what happened to the newest (executed as sent, blended -- a maneuver's blend --,
#: overridden)
#: the encounter's severity and its trajectory deviation under other definitions than ``dev_h_m`` /
#: ``dev_v_m`` (the largest distance from the unperturbed straight path p0 + v0 t): the highest alert
#: level raised; the time-mean horizontal / vertical distance from that path; the largest cross-track
#: distance from the planned track (the along-track lag of a slower or returning ownship left out); the
#: horizontal distance at the end of the encounter
EXTRA_COLUMNS = ("max_alert_level", "dev_h_tmean_m", "dev_v_tmean_m", "dev_xtrack_m", "dev_h_end_m")
SUPERSEDED_COLUMNS = ("n_superseded_whole", "n_superseded", "n_superseded_exec_whole", "n_superseded_exec",
                      "n_superseded_blend", "n_superseded_blend_intent", "n_superseded_override")
ENCOUNTER_SCHEMA = pa.schema(
    [("group", pa.string()), ("encounter_id", _I), ("seed", _I), ("duration_s", pa.float64()),
     ("lowc", pa.bool_()), ("nmac", pa.bool_()), ("lowc_duration_s", pa.float64()), ("pi", pa.float64()),
     ("pi_paper", pa.float64()), ("min_range_m", pa.float64()), ("vsep_at_min_range_m", pa.float64()), ("dev_h_m", pa.float64()),
     ("dev_v_m", pa.float64()), ("n_active_steps", _I), ("n_wait", _I), ("n_no_wait", _I),
     ("n_pilot_received", _I), ("n_pilot_exec", _I), ("n_blend", _I), ("n_blend_exact", _I),
     ("n_blend_axis", _I), ("n_blend_intent", _I), ("n_daa_override", _I), ("n_stale", _I), ("n_link_lost", _I),
     ("n_by_map", _I), ("n_by_projl", _I), ("n_by_both", _I), ("n_lookup_in_box", _I),
     ("n_pilot_received_whole", _I), ("n_pilot_exec_whole", _I),
     ("intruder_turns", pa.bool_()), ("preset", pa.string()),
     *[(c, _I) for c in SUPERSEDED_COLUMNS], ("max_alert_level", _I),
     *[(c, pa.float64()) for c in EXTRA_COLUMNS[1:]]])

DECISION_SCHEMA = pa.schema(
    [("group", pa.string()), ("encounter_id", _I), ("t", pa.float64()), ("decision", pa.string()),
     ("rule", pa.string()), ("wait_s", pa.float64()), ("projl", pa.bool_()), ("decided_by", pa.string()),
     ("wait_p_lowc", pa.float64()), ("wait_in_box", pa.bool_()), ("wait_turn_dps", pa.float64()),
     ("wait_map_turn_dps", pa.float64()), ("sm_pilot", pa.float64()),
     ("sm_exec", pa.float64()), ("pilot_axis", pa.string()), ("pilot_dir", pa.string()),
     ("exec_axis", pa.string()), ("exec_dir", pa.string()), ("exact_match", pa.bool_())])

_DEC_FIELDS = ("decision", "rule", "wait_s", "projl", "decided_by", "wait_p_lowc", "wait_in_box", "wait_turn_dps",
               "wait_map_turn_dps", "sm_pilot", "sm_exec", "pilot_axis", "pilot_dir", "exec_axis", "exec_dir",
               "exact_match")


class Accumulators:
    """Per-encounter result accumulators (N,) and the decision rows of the active steps."""

    def __init__(self, n: int, own0: AircraftState):
        self.lowc = np.zeros(n, bool)
        self.nmac = np.zeros(n, bool)
        self.lowc_time = np.zeros(n)
        self.pi = np.zeros(n)  # PI (s), preset constants, integrated on the LoWC segments
        self.pi_paper = np.zeros(n)  # PI (s), the paper's Eq. constants (4000 ft / 450 ft / 35 s)
        self.min_range = np.full(n, np.inf)
        self.vsep_at_min = np.full(n, np.nan)
        self.dev_h = np.zeros(n)
        self.dev_v = np.zeros(n)
        self.counts = np.zeros((n, len(CODE_NAMES["decision"])), np.int64)
        self.n_active = np.zeros(n, np.int64)
        self.n_blend_exact = np.zeros(n, np.int64)
        self.n_blend_axis = np.zeros(n, np.int64)
        self.n_blend_intent = np.zeros(n, np.int64)
        self.by = np.zeros((n, len(CODE_NAMES["decided_by"])), np.int64)
        self.n_in_box = np.zeros(n, np.int64)
        self.n_recv_whole = np.zeros(n, np.int64)
        self.n_exec_whole = np.zeros(n, np.int64)
        self.superseded = {c: np.zeros(n, np.int64) for c in SUPERSEDED_COLUMNS}
        self.max_alert = np.zeros(n, np.int64)
        self.dev_sum = np.zeros((n, 2))  # time integrals of the horizontal / vertical deviation (m s)
        self.dev_xtrack = np.zeros(n)
        self.dev_end = np.zeros(n)
        self.t_sum = 0.0
        self.p0 = own0.position()
        self.v0 = own0.velocity()
        self.dec_parts: list[tuple[np.ndarray, float, dict]] = []

    def deviation(self, own: AircraftState, t: float, dt: float = 0.0) -> None:
        """Max deviation (m) of the ownship from its unperturbed straight path p0 + v0 t; with ``dt`` > 0
        (s) also the time integrals, the cross-track maximum and the last value (:data:`EXTRA_COLUMNS`)."""
        d = own.position() - (self.p0 + self.v0 * t)
        h = np.hypot(d[:, 0], d[:, 1])
        self.dev_h = np.maximum(self.dev_h, h)
        self.dev_v = np.maximum(self.dev_v, np.abs(d[:, 2]))
        if dt > 0:
            self.dev_sum += np.stack([h, np.abs(d[:, 2])], axis=1) * dt
            self.t_sum += dt
            u = self.v0[:, :2] / np.maximum(np.hypot(self.v0[:, 0], self.v0[:, 1]), 1e-9)[:, None]
            self.dev_xtrack = np.maximum(self.dev_xtrack, np.abs(d[:, 0] * u[:, 1] - d[:, 1] * u[:, 0]))
        self.dev_end = h  # the last call: at the end of the encounter

    def add(self, out: StepOutput, dt: float, superseded: "np.ndarray | None" = None) -> None:
        """Accumulate one step; ``superseded`` (N,) the commands released besides the newest this step."""
        dec = out.decisions
        self.lowc |= out.lowc
        self.nmac |= out.nmac
        self.lowc_time += out.lowc_time_s
        self.pi += out.pi_s
        self.pi_paper += out.pi_paper_s
        closer = out.seg_min_range_m < self.min_range
        self.min_range = np.where(closer, out.seg_min_range_m, self.min_range)
        self.vsep_at_min = np.where(closer, out.seg_vsep_m, self.vsep_at_min)
        self.deviation(out.own, out.t, dt)
        self.max_alert = np.maximum(self.max_alert, np.asarray(dec["max_alert"], np.int64))
        active = np.asarray(dec["active"], bool)
        code = np.asarray(dec["decision"], np.int64)
        fresh = np.asarray(dec["pilot_cmd_fresh"], bool)
        self.n_recv_whole += fresh
        self.n_exec_whole += fresh & (~active | (code == D_PILOT))  # outside the active phase it is flown as sent
        if superseded is not None:
            k = np.where(fresh, np.asarray(superseded, np.int64), 0)
            sup = self.superseded
            sup["n_superseded_whole"] += k
            sup["n_superseded"] += np.where(active, k, 0)
            sup["n_superseded_exec_whole"] += np.where(~active | (code == D_PILOT), k, 0)
            sup["n_superseded_exec"] += np.where(active & (code == D_PILOT), k, 0)
            sup["n_superseded_blend"] += np.where(active & (code == D_BLEND), k, 0)
            sup["n_superseded_blend_intent"] += np.where(active & (code == D_BLEND) & (np.asarray(dec["pilot_axis"]) != 0),
                                                         k, 0)
            sup["n_superseded_override"] += np.where(active & (code == D_DAA_OVERRIDE), k, 0)
        ia = np.flatnonzero(active)
        if ia.size:
            np.add.at(self.counts, (ia, code[ia]), 1)
            self.n_active[ia] += 1
            blend = code == D_BLEND
            exact = blend & np.asarray(dec["exact_match"], bool)
            intent = blend & (np.asarray(dec["pilot_axis"]) != 0)
            axis_only = intent & ~exact & (np.asarray(dec["exec_axis"]) == np.asarray(dec["pilot_axis"]))
            self.n_blend_exact += exact & active
            self.n_blend_axis += axis_only & active
            self.n_blend_intent += intent & active
            np.add.at(self.by, (ia, np.asarray(dec["decided_by"], np.int64)[ia]), 1)
            self.n_in_box += active & np.asarray(dec["wait_in_box"], bool)
            self.dec_parts.append((ia, out.t, {k: np.asarray(dec[k])[ia] for k in _DEC_FIELDS}))

    def decisions(self) -> tuple[np.ndarray, np.ndarray, dict]:
        """Every decision row so far as ``(row, t, fields)``, sorted by row (encounter), then time."""
        if not self.dec_parts:
            return np.zeros(0, np.int64), np.zeros(0), {k: np.zeros(0) for k in _DEC_FIELDS}
        rows = np.concatenate([p[0] for p in self.dec_parts])
        t = np.concatenate([np.full(p[0].size, p[1]) for p in self.dec_parts])
        order = np.lexsort((t, rows))  # encounter-major, then time
        col = {k: np.concatenate([p[2][k] for p in self.dec_parts])[order] for k in _DEC_FIELDS}
        return rows[order], t[order], col


def _strings(codes: np.ndarray, names: Sequence[str]) -> pa.Array:
    return pa.DictionaryArray.from_arrays(pa.array(np.asarray(codes, np.int32)),
                                          pa.array(list(names), pa.string())).cast(pa.string())


def decision_table(sorted_rows: tuple, lo: int, hi: int, ids: np.ndarray, group: str) -> pa.Table:
    """The decision table of rows ``[lo, hi)`` of a batch (``sorted_rows`` from
    :meth:`Accumulators.decisions`; ``ids`` the encounter ids of those rows)."""
    all_rows, all_t, all_col = sorted_rows
    a, b = np.searchsorted(all_rows, lo), np.searchsorted(all_rows, hi)
    if a == b:
        return DECISION_SCHEMA.empty_table()
    rows, t = all_rows[a:b] - lo, all_t[a:b]
    col = {k: v[a:b] for k, v in all_col.items()}
    arrays = [pa.array(np.full(rows.size, group), pa.string()), pa.array(ids[rows], _I), pa.array(t),
              _strings(col["decision"], CODE_NAMES["decision"]), _strings(col["rule"], CODE_NAMES["rule"]),
              pa.array(col["wait_s"].astype(float)), pa.array(col["projl"].astype(bool)),
              _strings(col["decided_by"], CODE_NAMES["decided_by"]), pa.array(col["wait_p_lowc"].astype(float)),
              pa.array(col["wait_in_box"].astype(bool), mask=np.isnan(col["wait_p_lowc"].astype(float))),
              pa.array(col["wait_turn_dps"].astype(float)),
              pa.array(col["wait_map_turn_dps"].astype(float)),
              pa.array(col["sm_pilot"].astype(float)), pa.array(col["sm_exec"].astype(float)),
              _strings(col["pilot_axis"], CODE_NAMES["pilot_axis"]), _strings(col["pilot_dir"], CODE_NAMES["pilot_dir"]),
              _strings(col["exec_axis"], CODE_NAMES["exec_axis"]), _strings(col["exec_dir"], CODE_NAMES["exec_dir"]),
              pa.array(col["exact_match"].astype(bool))]
    return pa.Table.from_arrays(arrays, schema=DECISION_SCHEMA)


def encounter_table(acc: Accumulators, lo: int, hi: int, encounters, group: str, preset: str,
                    duration: float) -> pa.Table:
    """The per-encounter table of rows ``[lo, hi)`` of a batch (``encounters`` the part's set)."""
    n = len(encounters)
    sl = slice(lo, hi)
    c = acc.counts[sl]
    received = c[:, D_PILOT] + c[:, D_BLEND] + c[:, D_DAA_OVERRIDE]
    by = acc.by[sl]
    g = lambda a: a[sl]  # noqa: E731
    cols = {
        "group": pa.array(np.full(n, group), pa.string()), "encounter_id": pa.array(encounters.encounter_id, _I),
        "seed": pa.array(encounters.seed, _I), "duration_s": pa.array(np.full(n, float(duration))),
        "lowc": pa.array(g(acc.lowc)), "nmac": pa.array(g(acc.nmac)), "lowc_duration_s": pa.array(g(acc.lowc_time)),
        "pi": pa.array(g(acc.pi)), "pi_paper": pa.array(g(acc.pi_paper)), "min_range_m": pa.array(g(acc.min_range)), "vsep_at_min_range_m": pa.array(g(acc.vsep_at_min)),
        "dev_h_m": pa.array(g(acc.dev_h)), "dev_v_m": pa.array(g(acc.dev_v)), "n_active_steps": pa.array(g(acc.n_active), _I),
        "n_wait": pa.array(c[:, D_WAIT], _I), "n_no_wait": pa.array(c[:, D_NO_WAIT], _I),
        "n_pilot_received": pa.array(received, _I), "n_pilot_exec": pa.array(c[:, D_PILOT], _I),
        "n_blend": pa.array(c[:, D_BLEND], _I), "n_blend_exact": pa.array(g(acc.n_blend_exact), _I),
        "n_blend_axis": pa.array(g(acc.n_blend_axis), _I),
        "n_blend_intent": pa.array(g(acc.n_blend_intent), _I), "n_daa_override": pa.array(c[:, D_DAA_OVERRIDE], _I),
        "n_stale": pa.array(c[:, D_STALE], _I), "n_link_lost": pa.array(c[:, D_LINK_LOST], _I),
        "n_by_map": pa.array(by[:, BY_MAP], _I), "n_by_projl": pa.array(by[:, BY_PROJL], _I),
        "n_by_both": pa.array(by[:, BY_BOTH], _I), "n_lookup_in_box": pa.array(g(acc.n_in_box), _I),
        "n_pilot_received_whole": pa.array(g(acc.n_recv_whole), _I), "n_pilot_exec_whole": pa.array(g(acc.n_exec_whole), _I),
        "intruder_turns": pa.array(np.asarray(encounters.intruder_turns, bool)),
        "preset": pa.array(np.full(n, preset), pa.string()),
        **{c: pa.array(g(acc.superseded[c]), _I) for c in SUPERSEDED_COLUMNS},
        "max_alert_level": pa.array(g(acc.max_alert), _I),
        "dev_h_tmean_m": pa.array(g(acc.dev_sum[:, 0]) / max(acc.t_sum, 1e-300)),
        "dev_v_tmean_m": pa.array(g(acc.dev_sum[:, 1]) / max(acc.t_sum, 1e-300)),
        "dev_xtrack_m": pa.array(g(acc.dev_xtrack)), "dev_h_end_m": pa.array(g(acc.dev_end)),
    }
    return pa.Table.from_arrays(list(cols.values()), schema=ENCOUNTER_SCHEMA)
