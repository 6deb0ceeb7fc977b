"""The paper's stated properties of its wait maps (Tabassum & Bai Sec. IV, Figs. 3-7), checked on a map.

Each check runs over a stated population of grid nodes and counts only **non-trivial** values
(0 < W < H: neither "act now" nor "no constraint"), so a map of zeros cannot pass:

* :func:`head_on_vs_overtaking` -- "the wait time is lower in head-to-head encounters than in
  overtaking encounters": on the ownship's centre line (the dy node nearest 0, vh node nearest 0),
  every (dh, vi) and every |dx| node pair, head-on (dx > 0, theta = 180 deg) vs overtaking (dx < 0,
  theta = 0).
* :func:`converging_lines` -- "the decrease in the wait time is observed as the relative X
  distance reduces": along the same centre lines, head-on from ahead and overtaking from behind
  (intruder faster than the ownship), W must not grow as |dx| shrinks.
* :func:`mirror_error` -- the +-omega maps are mirror images and the 0 map is symmetric (Fig. 5).
* :func:`speed_trend` -- how W changes with the intruder speed vi along node lines (all other
  coordinates fixed): the paper says W falls with speed for a turning intruder (Fig. 5b vs 6a) and
  grows with speed for a non-turning one (Sec. IV); we report the shares.
* :func:`histogram` -- the wait times of the threatening states (wait-optimal, not in LoWC,
  P(LoWC within H) >= p_min) against the paper's Fig. 3. The text: "The histogram mirrors a left
  skewed Gaussian distribution. The maximum wait time is 40 seconds and the minimum wait time is 1
  second. In most of the states the wait time ranges between 5 and 10 seconds."
  :func:`shape_checks` tests each of those four statements (:data:`SHAPE_RULES`) and
  :func:`paper_shape` is true only if all four hold.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .lookup import WaitMap, WaitMapFamily


@dataclass
class OracleResult:
    """``n`` non-trivial cases checked, ``held`` of them satisfied the property, the failures."""

    n: int
    held: int
    failures: list = field(default_factory=list)

    @property
    def holds(self) -> bool:
        """True when every one of at least one non-trivial case holds."""
        return self.n > 0 and self.held == self.n

    def to_dict(self) -> dict:
        return {"n": self.n, "held": self.held, "holds": self.holds, "failures": self.failures[:10]}


def _nontrivial(w, horizon):
    return (w > 0) & (w < horizon)


def _centre(wm: WaitMap) -> tuple[int, int, int, int]:
    g = wm.grid
    th = g.axis("theta").values
    return (int(np.argmin(np.abs(g.axis("dy").values))), int(np.argmin(np.abs(g.axis("vh").values))),
            int(np.argmin(np.abs(th - np.pi))), int(np.argmin(np.abs(th))))


def head_on_vs_overtaking(wm: WaitMap) -> OracleResult:
    """Head-on waits shorter than overtaking waits at equal range (see the module docstring)."""
    g, W, H = wm.grid, wm.wait_s, wm.params.horizon
    iy, iv, ith_h, ith_o = _centre(wm)
    dx = g.axis("dx").values
    res = OracleResult(0, 0)
    for ix in np.flatnonzero(dx > 0):
        jx = int(np.argmin(np.abs(dx + dx[ix])))
        if not np.isclose(dx[jx], -dx[ix]):
            continue
        for ih in range(g.shape[2]):
            for ivi in range(g.shape[3]):
                ho, ov = float(W[ix, iy, ih, ivi, iv, ith_h]), float(W[jx, iy, ih, ivi, iv, ith_o])
                if _nontrivial(ho, H) and _nontrivial(ov, H):
                    res.n += 1
                    if ho < ov:
                        res.held += 1
                    else:
                        res.failures.append({"range_m": float(dx[ix]), "dh_m": float(g.axis("dh").values[ih]),
                                             "vi_mps": float(g.axis("vi").values[ivi]), "head_on_s": ho,
                                             "overtaking_s": ov})
    return res


def converging_lines(wm: WaitMap, tol: float = 1e-4) -> OracleResult:
    """W does not grow as |dx| shrinks along converging centre lines (see the module docstring)."""
    g, W, H = wm.grid, wm.wait_s, wm.params.horizon
    iy, iv, ith_h, ith_o = _centre(wm)
    dx = g.axis("dx").values
    ahead = np.flatnonzero(dx > 0)  # |dx| increasing
    behind = np.flatnonzero(dx < 0)[::-1]  # |dx| increasing
    res = OracleResult(0, 0)
    for ih in range(g.shape[2]):
        for ivi in range(g.shape[3]):
            lines = [("head-on", W[ahead, iy, ih, ivi, iv, ith_h])]
            if g.axis("vi").values[ivi] > wm.params.v_own:
                lines.append(("overtaking", W[behind, iy, ih, ivi, iv, ith_o]))
            for kind, line in lines:
                v = np.asarray(line[_nontrivial(line, H)], float)
                if v.size < 2:
                    continue
                res.n += 1
                if np.all(np.diff(v) >= -tol):
                    res.held += 1
                else:
                    res.failures.append({"kind": kind, "dh_m": float(g.axis("dh").values[ih]),
                                         "vi_mps": float(g.axis("vi").values[ivi]), "waits_s": v.round(2).tolist()})
    return res


def mirror_error(fam: WaitMapFamily) -> dict:
    """Max |W| difference (s) between each +-omega pair under the mirror (dy, theta) -> (-dy, -theta),
    and the asymmetry of the omega = 0 map; ``None`` where the family lacks the maps."""
    mi = fam.grid.mirror_index()
    out: dict = {"pairs": {}, "zero_map": None}
    rates = list(fam.turn_rates_deg)
    for m in fam.maps:
        w = m.wait_s.ravel()
        if m.turn_rate_deg == 0:
            out["zero_map"] = float(np.max(np.abs(w - w[mi])))
        elif m.turn_rate_deg > 0 and -m.turn_rate_deg in rates:
            other = fam.maps[rates.index(-m.turn_rate_deg)].wait_s.ravel()
            out["pairs"][f"{m.turn_rate_deg:+g}"] = {"mirror_error_s": float(np.max(np.abs(w - other[mi]))),
                                                     "plain_difference_s": float(np.max(np.abs(w - other)))}
    return out


def speed_trend(wm: WaitMap) -> dict:
    """Shares of non-trivial vi node lines (every other coordinate fixed) along which W strictly
    decreases / increases with the intruder speed."""
    g, H = wm.grid, wm.params.horizon
    lines = np.moveaxis(np.asarray(wm.wait_s, float), 3, -1).reshape(-1, g.shape[3])
    lines = lines[np.all(_nontrivial(lines, H), axis=1)]
    d = np.diff(lines, axis=1)
    n = int(lines.shape[0])
    return {"turn_rate_deg": wm.turn_rate_deg, "lines": n,
            "decreasing": float(np.mean(np.all(d < 0, axis=1))) if n else float("nan"),
            "increasing": float(np.mean(np.all(d > 0, axis=1))) if n else float("nan")}


def threatening(wm: WaitMap) -> np.ndarray:
    """Wait times (s) of the threatening states of one map (see the module docstring)."""
    sel = ~wm.evade & (wm.p_lowc >= wm.params.p_min)
    return np.asarray(wm.wait_s[sel], float)


def histogram(fam: WaitMapFamily) -> dict:
    """Histogram (5 s bins), quartiles and shape figures of the threatening states' waits over every map."""
    return histogram_of(np.concatenate([threatening(m) for m in fam.maps]), fam.params.horizon)


def histogram_of(w: np.ndarray, horizon: float) -> dict:
    """Histogram (5 s bins up to ``horizon``), quartiles, the share within 5-10 s and the quartile
    skewness ((Q3 + Q1 - 2 Q2) / (Q3 - Q1): negative = left skewed) of the waits ``w`` (s)."""
    w = np.asarray(w, float)
    edges = np.arange(0.0, horizon + 5.0, 5.0)
    counts, _ = np.histogram(w, bins=edges)
    mode = int(np.argmax(counts)) if w.size else -1
    q = [float(x) for x in np.percentile(w, [25, 50, 75])] if w.size else []
    return {"n": int(w.size), "min_s": float(w.min()) if w.size else float("nan"),
            "max_s": float(w.max()) if w.size else float("nan"), "quartiles_s": q,
            "bin_edges_s": edges.tolist(), "counts": counts.tolist(),
            "mode_bin_s": [float(edges[mode]), float(edges[mode + 1])] if mode >= 0 else None,
            "share_5_10": float(np.mean((w >= 5.0) & (w <= 10.0))) if w.size else float("nan"),
            "quartile_skew": (q[2] + q[0] - 2.0 * q[1]) / (q[2] - q[0]) if q and q[2] > q[0] else float("nan")}


#: the paper's four statements about its wait-time histogram (Sec. IV, Fig. 3), each as a test of a
#: :func:`histogram_of` dict; the tolerances allow the print rounding of "1 second" and "40 seconds"
SHAPE_RULES = {
    "min about 1 s (<= 2 s)": lambda h: h["min_s"] <= 2.0,
    "max about 40 s (35-45 s)": lambda h: 35.0 <= h["max_s"] <= 45.0,
    "most states within 5-10 s (> 50 %)": lambda h: h["share_5_10"] > 0.5,
    "left skewed (quartile skewness < 0)": lambda h: h["quartile_skew"] < 0.0,
}


def shape_checks(h: dict) -> dict:
    """Each of :data:`SHAPE_RULES` on a :func:`histogram_of` dict: rule -> held (False for no states)."""
    return {k: bool(h["n"] > 0 and rule(h)) for k, rule in SHAPE_RULES.items()}


def paper_shape(h: dict) -> bool:
    """True only if every statement of the paper about its Fig. 3 holds (:func:`shape_checks`)."""
    return all(shape_checks(h).values())


def check_family(fam: WaitMapFamily) -> dict:
    """Every oracle on a family, as one JSON-able dict (``daa-sil waitmap check``)."""
    zero = fam.map_for(0.0)
    h = histogram(fam)
    return {"head_on_vs_overtaking": head_on_vs_overtaking(zero).to_dict(),
            "converging_lines": converging_lines(zero).to_dict(), "mirror": mirror_error(fam),
            "speed_trend": [speed_trend(m) for m in fam.maps], "histogram": h, "shape_checks": shape_checks(h),
            "paper_shape": paper_shape(h)}


__all__ = ["OracleResult", "head_on_vs_overtaking", "converging_lines", "mirror_error", "speed_trend", "threatening",
           "histogram", "histogram_of", "SHAPE_RULES", "shape_checks", "paper_shape", "check_family"]
