"""Step-log columns into Rerun ``send_columns`` calls (:class:`StepEmitter`); positions in m (ENU), times in s.

Entities (ENU, ``rr.ViewCoordinates.RIGHT_HAND_Z_UP``; timelines ``sim_time`` (duration) and ``step``)
-------------------------------------------------------------------------------------------------
``world/ownship`` (Transform3D; children move with it): ``body`` (point, label = authority),
``velocity``, ``well_clear`` (cylinder radius DTHR, height 2 ZTHR; red while any intruder is in
violation), ``cmd/pilot``, ``cmd/daa``, ``cmd/exec`` (commanded tracks as arrows), ``bands``
(track bands as coloured arcs: near red, mid orange, far yellow, recovery cyan, none green).
``world/ownship_trail``, ``world/intruders/<id>`` (+ ``/trail``, ``/velocity``); ``<id>`` is the
intruder's index in the step log's list columns; its label and series names are its callsign (``names``,
from the step log's ``intruders`` metadata or the scenario; ``#<id>`` without one) and its range. ``decisions`` (text log: one line per decision with
its reason, plus LoWC/NMAC events). ``status/decision``, ``status/authority`` (state lanes).
``plots/range/<id>``, ``plots/hmd/<id>``, ``plots/dh/<id>``, ``plots/tau_mod/<id>``,
``plots/alert/<id>``, ``plots/wait/wait_s`` (wait-map value used), ``plots/wait/map/<id>`` (with
``wait_lookup``), ``plots/delay/up``, ``plots/delay/down``, ``plots/sm/pilot``, ``plots/sm/exec``.
"""

from __future__ import annotations

import collections
from typing import Callable

import numpy as np

from daa_sil.geometry.thresholds import Thresholds
from .draw import track_arc, fmt_value, track_unit_enu, decision_text
from .records import StepColumns
from .style import (ALERT_COLORS, BAND_RADIUS_FACTOR, DAA_COLOR, EXEC_COLOR, LEAD_S, OWN_COLOR, PILOT_COLOR,
                    REGION_COLORS, REGION_WIDTH, TRAIL_S, WC_OK, WC_VIOLATED)
from daa_sil.geometry.frames import to_paper_state

class StepEmitter:
    """Turns :class:`StepColumns` batches into ``send_columns`` calls; keeps trails across batches."""

    def __init__(self, rec, th: Thresholds, wait_lookup: "Callable[[np.ndarray], np.ndarray] | None" = None,
                 trail_s: float = TRAIL_S, names: "list[str] | None" = None):
        self.rec, self.th, self.wait_lookup, self.trail_s = rec, th, wait_lookup, trail_s
        #: each intruder's name (its callsign), by index; ``#j`` where there is none
        self.names: "list[str]" = [str(n) for n in names] if names else []
        self.band_radius = BAND_RADIUS_FACTOR * th.dthr
        self.cmd_len = 1.15 * self.band_radius
        self.hist_t: collections.deque = collections.deque()
        self.hist_own: collections.deque = collections.deque()
        self.hist_intr: collections.deque = collections.deque()
        self.known_intruders: set[int] = set()
        self.prev_lowc = False
        self.prev_nmac = False
        self.steps_logged = 0
        self._static()

    # static -----------------------------------------------------------------------------
    def _static(self) -> None:
        rr = rerun_module()
        r, th = self.rec, self.th
        r.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        r.log("world/ownship/well_clear",
              rr.Cylinders3D.from_fields(lengths=[2.0 * th.zthr], radii=[th.dthr],
                                         fill_mode=rr.components.FillMode.TransparentFillMajorWireframe,
                                         labels=[f"well clear {th.name}: {th.dthr:.0f} m, ±{th.zthr:.0f} m"],
                                         show_labels=False), static=True)
        r.log("world/ownship/body", rr.Points3D.from_fields(positions=[[0.0, 0.0, 0.0]], radii=[-8.0],
                                                            colors=[OWN_COLOR]), static=True)
        for name, color, label in (("pilot", PILOT_COLOR, "pilot cmd"), ("daa", DAA_COLOR, "DAA resolution"),
                                   ("exec", EXEC_COLOR, "executed cmd")):
            r.log(f"world/ownship/cmd/{name}", rr.Arrows3D.from_fields(colors=[color], radii=[-2.0], labels=[label],
                                                                       show_labels=False), static=True)
        r.log("world/ownship/velocity", rr.Arrows3D.from_fields(colors=[OWN_COLOR], radii=[-1.5]), static=True)
        r.log("world/ownship_trail", rr.LineStrips3D.from_fields(colors=[OWN_COLOR], radii=[-1.5]), static=True)
        styles = {"plots/hmd/threshold": ("HMD* [m]", (150, 150, 150)),
                  "plots/tau_mod/threshold": ("tau_mod* [s]", (150, 150, 150)),
                  "plots/dh/zthr_up": ("+ZTHR [m]", (150, 150, 150)), "plots/dh/zthr_down": ("-ZTHR [m]", (150, 150, 150)),
                  "plots/wait/wait_s": ("wait-map value used [s]", (255, 200, 0)),
                  "plots/delay/up": ("uplink delay [s]", PILOT_COLOR), "plots/delay/down": ("downlink delay [s]", OWN_COLOR),
                  "plots/sm/pilot": ("SM(pilot cmd) [s]", PILOT_COLOR), "plots/sm/exec": ("SM(executed) [s]", EXEC_COLOR)}
        for path, (name, color) in styles.items():
            r.log(path, rr.SeriesLines(names=name, colors=[color], widths=2), static=True)

    def name(self, j: int) -> str:
        """Intruder ``j``'s label: its callsign, or ``#j``."""
        return self.names[j] if j < len(self.names) and self.names[j] else f"#{j}"

    def _intruder_static(self, j: int) -> None:
        rr = rerun_module()
        r = self.rec
        name = self.name(j)
        color = [(255, 80, 80), (255, 160, 60), (200, 100, 255), (80, 200, 255)][j % 4]
        r.log(f"world/intruders/{j}/trail", rr.LineStrips3D.from_fields(colors=[color], radii=[-1.5]), static=True)
        r.log(f"world/intruders/{j}/velocity", rr.Arrows3D.from_fields(colors=[color], radii=[-1.5]), static=True)
        for q, unit in (("range", "m"), ("hmd", "m"), ("dh", "m"), ("tau_mod", "s"), ("alert", "level")):
            r.log(f"plots/{q}/{j}", rr.SeriesLines(names=f"{q} {name} [{unit}]", colors=[color], widths=2), static=True)
        if self.wait_lookup is not None:
            r.log(f"plots/wait/map/{j}", rr.SeriesLines(names=f"w(S) {name} [s]", colors=[color], widths=2), static=True)
        self.known_intruders.add(j)

    # per batch -----------------------------------------------------------------------------
    def _send(self, path: str, mask: "np.ndarray | None", columns) -> None:
        rr = rerun_module()
        t, step = self._t, self._step
        if mask is not None:
            t, step = t[mask], step[mask]
            if t.size == 0:
                return
        self.rec.send_columns(path, indexes=[rr.TimeColumn("sim_time", duration=t),
                                             rr.TimeColumn("step", sequence=step)], columns=columns)

    def _scalar(self, path: str, values: np.ndarray) -> None:
        rr = rerun_module()
        ok = np.isfinite(values)
        if ok.any():
            self._send(path, ok, rr.Scalars.columns(scalars=values[ok]))

    def _arrows(self, path: str, origins: np.ndarray, vectors: np.ndarray) -> None:
        """Arrows with an empty row (nothing shown) where the vector is not finite."""
        rr = rerun_module()
        ok = np.all(np.isfinite(vectors), axis=-1) & np.all(np.isfinite(origins), axis=-1)
        lengths = ok.astype(np.int64)
        self._send(path, None, rr.Arrows3D.columns(origins=origins[ok], vectors=vectors[ok]).partition(lengths))

    def emit(self, c: StepColumns) -> None:
        """Log one batch of rows (consecutive steps of one encounter)."""
        rr = rerun_module()
        n, th = c.n, self.th
        if n == 0:
            return
        t = c.f("t")
        step = c.f("step")
        if np.isnan(step).all():
            step = np.arange(self.steps_logged, self.steps_logged + n, dtype=float)
        if np.isnan(t).any():
            t = np.where(np.isnan(t), step, t)
        self._t, self._step = t, step.astype(np.int64)
        own = np.stack([c.f("own_x"), c.f("own_y"), c.f("own_z")], axis=-1)
        gs, trk, vs = c.f("own_gs"), c.f("own_trk_deg"), c.f("own_vs")
        own_v = track_unit_enu(trk) * gs[:, None]
        own_v[:, 2] = vs

        # ownship
        self._send("world/ownship", None, rr.Transform3D.columns(translation=np.nan_to_num(own)))
        auth = c.s("authority", "pilot")
        self._send("world/ownship/body", None, rr.Points3D.columns(labels=[f"ownship ({a})" for a in auth]))
        self._arrows("world/ownship/velocity", np.zeros((n, 3)), own_v * LEAD_S)
        for name in ("pilot", "daa", "cmd"):
            ctrk, cvs, cgs = c.f(f"{name}_trk_deg"), c.f(f"{name}_vs"), c.f(f"{name}_gs")
            cgs = np.where(np.isfinite(cgs), cgs, gs)
            cvs = np.where(np.isfinite(cvs), cvs, vs)
            vec = track_unit_enu(ctrk) * self.cmd_len
            with np.errstate(invalid="ignore", divide="ignore"):
                vec[:, 2] = np.where(cgs > 0, cvs * self.cmd_len / cgs, 0.0)
            self._arrows(f"world/ownship/cmd/{'exec' if name == 'cmd' else name}", np.zeros((n, 3)), vec)

        # intruders, per-intruder plots
        m = c.m
        ipos = np.stack([c.i("intr_x"), c.i("intr_y"), c.i("intr_z")], axis=-1)  # (n, M, 3)
        igs, itrk, ivs = c.i("intr_gs"), c.i("intr_trk_deg"), c.i("intr_vs")
        ivel = track_unit_enu(itrk) * igs[..., None]
        ivel[..., 2] = ivs
        alert = np.nan_to_num(c.i("alert_level")).astype(np.int64).clip(0, 3)
        wcv = np.nan_to_num(c.i("wcv")).astype(bool)
        rng = c.i("range_m")
        for j in range(m):
            if j not in self.known_intruders:
                self._intruder_static(j)
            ok = np.all(np.isfinite(ipos[:, j]), axis=-1)
            colors = np.where(wcv[:, j, None], ALERT_COLORS[3], ALERT_COLORS[alert[:, j]])
            labels = [f"{self.name(j)} {fmt_value(x / 1000.0, ' km')}" for x in rng[:, j]]
            self._send(f"world/intruders/{j}", None,
                       rr.Points3D.columns(positions=ipos[ok, j], colors=colors[ok], radii=np.full(ok.sum(), -7.0),
                                           labels=[lb for lb, o in zip(labels, ok) if o]).partition(ok.astype(np.int64)))
            self._arrows(f"world/intruders/{j}/velocity", ipos[:, j], ivel[:, j] * LEAD_S)
            self._scalar(f"plots/range/{j}", rng[:, j])
            self._scalar(f"plots/hmd/{j}", c.i("hmd_m")[:, j])
            self._scalar(f"plots/dh/{j}", c.i("dh_m")[:, j])
            self._scalar(f"plots/tau_mod/{j}", c.i("tau_mod_s")[:, j])
            self._scalar(f"plots/alert/{j}", c.i("alert_level")[:, j])
            if self.wait_lookup is not None:
                self._wait_lookup(j, own, own_v, ipos[:, j], ivel[:, j])
        self._scalar("plots/hmd/threshold", np.full(n, th.dthr))
        self._scalar("plots/tau_mod/threshold", np.full(n, th.tthr))
        self._scalar("plots/dh/zthr_up", np.full(n, th.zthr))
        self._scalar("plots/dh/zthr_down", np.full(n, -th.zthr))

        # trails (last trail_s seconds, carried across batches)
        self._trails(t, own, ipos)

        # well clear volume colour, bands
        any_wcv = wcv.any(axis=1) if m else np.zeros(n, bool)
        self._send("world/ownship/well_clear", None,
                   rr.Cylinders3D.columns(colors=np.where(any_wcv[:, None], WC_VIOLATED, WC_OK).astype(np.uint8)))
        self._bands(c)

        # decisions, state lanes, scalars
        self._decisions(c, t)
        self._send("status/authority", None, rr.StateChange.columns(state=auth))
        self._send("status/decision", None, rr.StateChange.columns(state=c.s("decision")))
        self._scalar("plots/wait/wait_s", c.f("wait_s"))
        self._scalar("plots/delay/up", c.f("delay_up_s"))
        self._scalar("plots/delay/down", c.f("delay_down_s"))
        self._scalar("plots/sm/pilot", c.f("sm_pilot"))
        self._scalar("plots/sm/exec", c.f("sm_exec"))
        self.steps_logged += n

    def _wait_lookup(self, j: int, own, own_v, ipos, ivel) -> None:
        ok = np.all(np.isfinite(ipos), axis=-1) & np.all(np.isfinite(own_v), axis=-1)
        w = np.full(len(ok), np.nan)
        if ok.any():
            w[ok] = np.asarray(self.wait_lookup(to_paper_state(own[ok], own_v[ok], ipos[ok], ivel[ok])), float)
        self._scalar(f"plots/wait/map/{j}", w)

    def _trails(self, t: np.ndarray, own: np.ndarray, ipos: np.ndarray) -> None:
        rr = rerun_module()
        n, m = ipos.shape[0], ipos.shape[1]
        own_strips, intr_strips = [], [[] for _ in range(m)]
        for k in range(n):
            self.hist_t.append(t[k])
            self.hist_own.append(own[k].astype(np.float32))
            self.hist_intr.append(ipos[k].astype(np.float32))
            while self.hist_t and self.hist_t[0] < t[k] - self.trail_s:
                self.hist_t.popleft()
                self.hist_own.popleft()
                self.hist_intr.popleft()
            o = np.array(self.hist_own)
            own_strips.append(o[np.all(np.isfinite(o), axis=-1)])
            for j in range(m):
                p = np.array([h[j] if j < len(h) else (np.nan,) * 3 for h in self.hist_intr], np.float32)
                intr_strips[j].append(p[np.all(np.isfinite(p), axis=-1)])
        self._send("world/ownship_trail", None, rr.LineStrips3D.columns(strips=own_strips))
        for j in range(m):
            self._send(f"world/intruders/{j}/trail", None, rr.LineStrips3D.columns(strips=intr_strips[j]))

    def _bands(self, c: StepColumns) -> None:
        rr = rerun_module()
        strips, colors, radii, lengths = [], [], [], []
        for row in c.bands:
            lengths.append(len(row))
            for lo, hi, region in row:
                strips.append(track_arc(lo, hi, self.band_radius))
                colors.append(REGION_COLORS.get(region, REGION_COLORS["none"]))
                radii.append(REGION_WIDTH.get(region, -1.5))
        cols = rr.LineStrips3D.columns(strips=strips, colors=np.array(colors, np.uint8).reshape(-1, 4),
                                       radii=np.array(radii, np.float32))
        self._send("world/ownship/bands", None, cols.partition(np.array(lengths, np.int64)))

    def _decisions(self, c: StepColumns, t: np.ndarray) -> None:
        rr = rerun_module()
        texts, levels, idx = [], [], []
        seg_lowc, seg_nmac = c.b("lowc"), c.b("nmac")
        for k in range(c.n):
            text, level = decision_text(c, k)
            if text:
                texts.append(text)
                levels.append(level)
                idx.append(k)
            for flag, prev, what in ((seg_lowc[k], self.prev_lowc, "LoWC: well clear lost"),
                                     (seg_nmac[k], self.prev_nmac, "NMAC")):
                if flag and not prev:
                    texts.append(f"{what} on [{t[k]:.0f} s, {t[k] + 1:.0f} s]")
                    levels.append("CRITICAL")
                    idx.append(k)
            self.prev_lowc, self.prev_nmac = bool(seg_lowc[k]), bool(seg_nmac[k])
        if idx:
            ix = np.array(idx)
            self.rec.send_columns("decisions", indexes=[rr.TimeColumn("sim_time", duration=self._t[ix]),
                                                        rr.TimeColumn("step", sequence=self._step[ix])],
                                  columns=rr.TextLog.columns(text=texts, level=levels))


def rerun_module():
    """The ``rerun`` module, imported on first use (so that importing the viewer code does not load Rerun)."""
    import rerun as rr  # lazy: start-up time

    return rr
