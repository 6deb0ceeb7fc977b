"""PNG figures of wait maps (matplotlib, Agg backend): the paper's Fig. 3-7 kinds of views."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from daa_sil.files import atomic_path
from .lookup import WaitMap, WaitMapFamily
from .model import DEG

GEOMETRIES = (("head-on", 180.0), ("crossing-from-right", 90.0), ("crossing-from-left", 270.0), ("overtaking", 0.0))


def _plt():
    import matplotlib  # lazy: start-up time

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # lazy: start-up time

    return plt


def _slice(wm: WaitMap, theta_deg: float, vi: float, dh: float, vh: float, n: int = 121):
    """Wait time over an (dx, dy) mesh at fixed (dh, vi, vh, theta), by lookup (s)."""
    ax = np.linspace(wm.grid.axis("dx").lo, wm.grid.axis("dx").hi, n)
    ay = np.linspace(wm.grid.axis("dy").lo, wm.grid.axis("dy").hi, n)
    X, Y = np.meshgrid(ax, ay, indexing="xy")
    st = np.stack([X, Y, np.full_like(X, dh), np.full_like(X, vi), np.full_like(X, vh),
                   np.full_like(X, theta_deg * DEG)], axis=-1)
    return X, Y, wm.lookup(st).wait_s


def _save(fig, path: Path, overwrite: bool) -> Path:
    with atomic_path(path, overwrite=overwrite) as tmp:
        fig.savefig(tmp, format="png", dpi=110, bbox_inches="tight")
    _plt().close(fig)
    return path


def _top(ax, wm, theta, vi, dh, vh, title):
    X, Y, W = _slice(wm, theta, vi, dh, vh)
    m = ax.pcolormesh(X, Y, W, shading="auto", cmap="viridis", vmin=0, vmax=wm.params.horizon)
    ax.plot([0], [0], "r^", ms=8)
    ax.set_xlabel("dx ahead (m)")
    ax.set_ylabel("dy left (m)")
    ax.set_title(title, fontsize=9)
    ax.set_aspect("equal")
    return m


def write_plots(fam: WaitMapFamily, out: Path, vi: float = 155.0, dh: float = 200.0, vh: float = -2.5,
                overwrite: bool = False) -> list[Path]:
    """Write the standard figures for a family (or a one-map family); returns the PNG paths."""
    plt = _plt()
    paths = []
    base = fam.map_for(0.0)
    tag = f"vi={vi:g} m/s, dh={dh:g} m, vh={vh:g} m/s"
    fig, axs = plt.subplots(1, 4, figsize=(18, 4.6))
    for ax, (name, th) in zip(axs, GEOMETRIES):
        m = _top(ax, base, th, vi, dh, vh, f"{name} (theta {th:g} deg), turn {base.turn_rate_deg:+g} deg/s\n{tag}")
    fig.colorbar(m, ax=axs, label="wait time (s)")
    paths.append(_save(fig, out / "slices_geometries.png", overwrite))

    rates = fam.turn_rates_deg
    if rates.min() < 0 < rates.max():
        lo, hi = fam.maps[int(np.argmin(rates))], fam.maps[int(np.argmax(rates))]
        fig, axs = plt.subplots(1, 2, figsize=(10, 4.6))
        for ax, wm in zip(axs, (lo, hi)):
            m = _top(ax, wm, 180.0, vi, dh, vh, f"turn {wm.turn_rate_deg:+g} deg/s, head-on\n{tag}")
        fig.colorbar(m, ax=axs, label="wait time (s)")
        paths.append(_save(fig, out / "mirror_pair.png", overwrite))

    paths.append(_histogram(plt, fam, out / "histogram.png", overwrite))

    fig = plt.figure(figsize=(7, 5.5))
    ax = fig.add_subplot(projection="3d")
    X, Y, W = _slice(base, 180.0, vi, dh, vh, n=61)
    ax.plot_surface(X, Y, W, cmap="viridis", linewidth=0)
    ax.set_xlabel("dx (m)")
    ax.set_ylabel("dy (m)")
    ax.set_zlabel("wait (s)")
    ax.set_title(f"head-on wait map, turn {base.turn_rate_deg:+g} deg/s, {tag}", fontsize=9)
    paths.append(_save(fig, out / "map_3d.png", overwrite))
    return paths


def _histogram(plt, fam: WaitMapFamily, path: Path, overwrite: bool) -> Path:
    """The paper's Fig. 3 kind: wait times of the threatening states, next to the paper's description."""
    from .oracles import histogram, paper_shape, shape_checks, threatening  # lazy: start-up time

    h = histogram(fam)
    w = np.concatenate([threatening(m) for m in fam.maps])
    fig, (ax, tx) = plt.subplots(1, 2, figsize=(10, 4), gridspec_kw={"width_ratios": [3, 2]})
    ax.hist(w, bins=h["bin_edges_s"], color="tab:blue", edgecolor="k")
    ax.axvspan(5, 10, color="tab:orange", alpha=0.25, label="paper: most states 5-10 s")
    ax.axvline(1, color="k", ls=":", lw=1)
    ax.axvline(40, color="k", ls=":", lw=1, label="paper: min 1 s, max 40 s")
    ax.set_xlabel("wait time (s)")
    ax.set_ylabel("states")
    ax.legend(fontsize=7)
    ax.set_title(f"wait time over threatening states (n={w.size:,}, all maps)", fontsize=9)
    tx.axis("off")
    lines = ["Paper (Sec. IV, Fig. 3): left skewed,", "  min 1 s, max 40 s, most states 5-10 s", "",
             f"This family: {fam.grid.name} grid, H = {fam.params.horizon:g} s,",
             f"  wait = {fam.params.wait_definition}, p_min = {fam.params.p_min:g}"]
    if w.size:
        q = h["quartiles_s"]
        lines += [f"  min {h['min_s']:.1f} s, max {h['max_s']:.1f} s", f"  quartiles {q[0]:.1f} / {q[1]:.1f} / {q[2]:.1f} s",
                  f"  {100 * h['share_5_10']:.0f} % within 5-10 s, quartile skew {h['quartile_skew']:+.2f}", "",
                  "The paper's statements, tested:"]
        lines += [f"  {'holds' if ok else 'FAILS'}: {rule}" for rule, ok in shape_checks(h).items()]
        lines += [f"  the paper's shape: {'yes' if paper_shape(h) else 'no'}"]
    tx.text(0.0, 1.0, "\n".join(lines), va="top", family="monospace", fontsize=8)
    return _save(fig, path, overwrite)


