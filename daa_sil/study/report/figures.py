"""The report's PNG figures (matplotlib, Agg): allocation counts (paper Fig. 9), safety (Fig. 10)
and the exact-match share, one set per reading."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from daa_sil.files import atomic_path
from daa_sil.study.analysis.study import Study
from daa_sil.study.analysis.metrics import paper_results

FIGURES = ("fig9_allocation.png", "fig10_safety.png", "fig_exact_match.png")


def _save(fig, path: Path) -> None:
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110, bbox_inches="tight")


def group_figures(st: Study, out: Path, suffix: str = "") -> list[Path]:
    """Draw the report's figures of ``st`` into ``out`` (names end in ``suffix``); the paths written."""
    import matplotlib  # lazy: start-up time

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt  # lazy: start-up time

    pr = paper_results()
    groups = list(st.groups)
    x = np.arange(len(groups))
    w = 0.38
    paper_n = float(pr.get("encounters_per_group", 10000))

    def err(metric):
        es = [st.estimate(g, metric) if st.available(g, metric) else None for g in groups]
        v = np.array([e.value if e else np.nan for e in es], float)
        lo = np.array([e.lo if e else np.nan for e in es], float)
        hi = np.array([e.hi if e else np.nan for e in es], float)
        lo = np.where(np.isfinite(lo), lo, v)
        hi = np.where(np.isfinite(hi), hi, v)
        return np.nan_to_num(v), np.nan_to_num(np.vstack([np.clip(v - lo, 0, None), np.clip(hi - v, 0, None)]))

    def paper_vals(section, key, per_enc=False):
        v = np.array([float(pr.get(section, {}).get(g, {}).get(key, np.nan)) if g in pr.get(section, {}) else np.nan
                      for g in groups])
        return v / paper_n if per_enc else v

    name = lambda i: out / (FIGURES[i].replace(".png", f"{suffix}.png"))  # noqa: E731
    paths = []
    fig, ax = plt.subplots(1, 3, figsize=(15, 4.2))
    for k, (key, col) in enumerate((("wait", "tab:orange"), ("no_wait", "tab:red"))):
        v, e = err(key)
        ax[0].bar(x + (k - 0.5) * w, v, w, yerr=e, color=col, label=f"ours: {key.replace('_', '-')}", capsize=3)
        ax[0].scatter(x + (k - 0.5) * w, paper_vals("waiting_status", key, True), marker="x",
                      color="k", zorder=3, label="the paper (published)" if k == 0 else None)
    ax[0].set_title("(a) wait / no-wait (allocate to DAA)")
    v, e = err("received")
    ax[1].bar(x, v, 0.6, yerr=e, color="tab:blue", capsize=3, label="ours")
    ax[1].scatter(x, paper_vals("pilot_command_reception", "received", True), marker="x", color="k", zorder=3,
                  label="the paper (published)")
    ax[1].set_title("(b) pilot commands received")
    bottom = np.zeros(len(groups))
    pbottom = np.zeros(len(groups))
    for key, col, pk in (("pilot_exec", "tab:green", "pilot"), ("blend", "tab:purple", "blending"),
                         ("daa_override", "tab:red", "daa_override")):
        v, _ = err(key)
        ax[2].bar(x - w / 2, v, w, bottom=bottom, color=col, label=f"ours: {pk}")
        pv = np.nan_to_num(paper_vals("command_execution", pk, True))
        ax[2].bar(x + w / 2, pv, w, bottom=pbottom, color=col, alpha=0.45, hatch="//", label=f"paper: {pk}")
        bottom = bottom + v
        pbottom = pbottom + pv
    ax[2].set_title("(c) command execution")
    for a in ax:
        a.set_xticks(x, groups, rotation=30, ha="right")
        a.legend(fontsize=7)
        a.set_ylabel("instances (steps) per encounter, 95 % CI")
    p = name(0)
    _save(fig, p)
    plt.close(fig)
    paths.append(p)

    fig, ax = plt.subplots(1, 3, figsize=(15, 4.2))
    v, e = err("p_lowc")
    ax[0].bar(x, 100 * v, 0.6, yerr=100 * e, color="tab:red", capsize=3)
    ax[0].set_title("(a) LoWC encounters (% of encounters)")
    ax[0].set_ylabel("% of encounters")
    v, e = err("p_lowc_per_hr_paper_h")
    ax[1].bar(x, np.where(v > 0, v, np.nan), 0.6, yerr=e, color="tab:red", capsize=3,
              label="ours (paper Eq. at 666.67 h)")
    ax[1].scatter(x, paper_vals("lowc_per_flight_hour", "p"), marker="x", color="k", zorder=3, label="the paper (published)")
    for _, (lo, _hi) in pr["faa_likelihood"].items():
        if lo > 0:
            ax[1].axhline(lo, color="0.6", lw=0.6, ls="--")
    ax[1].set_yscale("log")
    ax[1].set_ylim(1e-10, 1e-3)
    ax[1].set_title("(b) P(LoWC) per flight hour (dashed: FAA bands)")
    ax[1].legend(fontsize=7)
    v, e = err("pi_paper_mean" if st.has_pi_paper else "pi_mean")
    ax[2].bar(x - w / 2, v, w, yerr=e, color="tab:gray", capsize=3, label="mean PI")
    ax[2].bar(x + w / 2, np.nan_to_num([st.pi_max(g) for g in groups]), w, color="k", label="max PI")
    ax[2].axhline(1.0, color="tab:blue", ls="--", lw=0.8, label="the paper: mean < 1")
    ax[2].set_title("(c) penetration integral of LoWC encounters (s)")
    ax[2].legend(fontsize=7)
    for a in ax:
        a.set_xticks(x, groups, rotation=30, ha="right")
    p = name(1)
    _save(fig, p)
    plt.close(fig)
    paths.append(p)

    fig, ax = plt.subplots(figsize=(6, 4))
    v, e = err("exact_match")
    ax.bar(x, 100 * v, 0.6, yerr=100 * e, color="tab:purple", capsize=3, label="ours")
    ax.axhline(pr.get("blending_exact_match_pct", 84), color="k", ls="--", label="the paper (84 %)")
    ax.set_xticks(x, groups, rotation=30, ha="right")
    ax.set_ylim(0, 105)
    ax.set_ylabel("% of blends with the pilot's (axis, direction)")
    ax.legend(fontsize=7)
    p = name(2)
    _save(fig, p)
    plt.close(fig)
    paths.append(p)
    return paths


def file_slug(label: str) -> str:
    """``label`` made safe for a file name (letters, digits, ``-`` and ``_``)."""
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in label)
