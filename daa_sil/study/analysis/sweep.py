"""Sensitivity sweeps: the study at several values of one setting, into one directory, resumably.

``daa-sil campaign sweep --vary wt=2,4,8,16 --groups B-2,ID-2 --out DIR`` runs one campaign per
value (``DIR/points/<name>=<value>/``, each an ordinary campaign directory, resumable) on the same
campaign seed, so every point flies the same encounters, and writes

* ``DIR/sweep.json``: what was varied, the values, the base configuration and each point's directory;
* ``DIR/sweep.csv`` and ``DIR/sweep.md``: per value and group, DAA allocations and pilot commands
  received per encounter, the exact (axis, direction) match share of blends, the LoWC rate (share
  of encounters) and the mean PI of LoWC encounters, each with its encounter-level 95 % CI
  (:class:`daa_sil.study.analysis.study.Study`: cluster bootstrap, Clopper-Pearson for the LoWC share);
* ``DIR/sensitivity_<metric>.png``: each metric against the varied value, one line per group.

Variables (:data:`VARIABLES`): ``wt`` (W_T, s), ``gamma`` (MDP discount), ``grid`` (a map preset or
grid spec for ``--waitmap``), ``intruders`` (per encounter), ``latency`` (a delay spec; values
that contain commas are separated by ``;``, e.g. ``latency=const:0.2;const:1;gauss:5,3``),
``projl`` (the ProjL look-ahead, s), ``reading`` (a named reading) and ``pilot`` (the pilot model's
response mode, :data:`daa_sil.models.pilot_config.MODES`, e.g. ``pilot=guendel,nasa_rayleigh5``: the
paper does not give its pilot's response time). Under a reading that sets its own wait-map grid (such
as ``paper``), ``grid`` sets the reading's grid.
"""

from __future__ import annotations

import csv
import io
import json
import math
import re
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable, Sequence

from daa_sil.errors import FileFormatError, UsageError
import shutil

#: variable -> (CampaignConfig field or per-group setting, value parser, numeric axis?)
VARIABLES: dict[str, tuple[str, Callable[[str], object], bool]] = {
    "wt": ("wait_threshold_s", float, True),
    "gamma": ("gamma", float, True),
    "grid": ("waitmap", str, False),
    "intruders": ("n_intruders", int, True),
    "latency": ("latency", str, False),
    "projl": ("projl_horizon_s", float, True),
    "reading": ("reading", str, False),
    "pilot": ("pilot", str, False),
}
#: (metric of daa_sil.study.analysis.metrics, axis label, scale for display)
METRICS = (("no_wait", "DAA allocations (no-wait decisions) per encounter", 1.0),
           ("received", "pilot commands received per encounter", 1.0),
           ("exact_match", "exact (axis, direction) match among blends of a maneuver, %", 100.0),
           ("p_lowc", "LoWC encounters, % of encounters", 100.0),
           ("pi_mean", "mean PI of LoWC encounters, s", 1.0))
SWEEP_FORMAT = 1


@dataclass(frozen=True)
class Vary:
    """What a sweep varies: a :data:`VARIABLES` name and its values (as typed)."""

    name: str
    values: tuple

    @property
    def field(self) -> str:
        return VARIABLES[self.name][0]

    @property
    def setting(self):
        """The per-group :class:`~daa_sil.config.settings.Setting` it varies (None: a campaign field)."""
        from daa_sil.config.overrides import setting_for_key  # lazy: start-up time

        return setting_for_key(self.field)

    @property
    def numeric(self) -> bool:
        return VARIABLES[self.name][2]

    def slug(self, value) -> str:
        text = re.sub(r"[^A-Za-z0-9.+-]+", "_", f"{value:g}" if isinstance(value, float) else str(value))
        return f"{self.name}={text}"


def parse_vary(text: str) -> Vary:
    """``wt=2,4,8`` / ``latency=const:0.2;gauss:5,3`` -> :class:`Vary` (one-line UsageError)."""
    name, sep, body = str(text).partition("=")
    name = name.strip().lower()
    if not sep or name not in VARIABLES:
        raise UsageError(f"--vary {text!r} must be NAME=V1,V2,... with NAME one of {', '.join(VARIABLES)}")
    sep_char = ";" if (";" in body or name == "latency") else ","
    raw = [v.strip() for v in body.split(sep_char) if v.strip()]
    if len(raw) < 2:
        raise UsageError(f"--vary {text!r}: give at least two values (separated by '{sep_char}')")
    conv = VARIABLES[name][1]
    try:
        vals = tuple(conv(v) for v in raw)
    except ValueError:
        raise UsageError(f"--vary {text!r}: {name} values must be {conv.__name__}s") from None
    if len(set(vals)) != len(vals):
        raise UsageError(f"--vary {text!r}: a value is given twice")
    return Vary(name, vals)


def point_configs(base, vary: Vary) -> list:
    """One validated :class:`~daa_sil.study.campaign.config.CampaignConfig` per value (errors name the value)."""
    out = []
    for v in vary.values:
        try:
            out.append(_point(base, vary, v).validate())
        except UsageError as exc:
            raise UsageError(f"--vary {vary.name}={v}: {exc}") from None
    return out


def _point(base, vary: Vary, value):
    """The configuration of one sweep point: ``pilot`` sets the pilot's response mode (keeping the
    base's other pilot settings); ``grid`` under a reading with its own grid sets the reading's grid."""
    if vary.name == "pilot":
        from daa_sil.models.pilot_config import PilotConfig  # lazy: start-up time

        pilot = {**base.pilot, "mode": value}
        PilotConfig(**pilot).validate()
        return replace(base, pilot=pilot)
    if vary.name == "grid" and base.effective_reading.waitmap is not None:
        return replace(base, reading_set={**base.reading_set, "waitmap": value})
    if vary.setting is not None:
        return replace(base, settings=base.settings.with_(vary.setting, value))
    return replace(base, **{vary.field: value})


def run_sweep(base, vary: Vary, out_dir: "str | Path", *, workers: int = 1, scheduler: "str | None" = None,
              resume: bool = False, progress: bool = True, say: "Callable[[str], None] | None" = None,
              batch_rows: "int | None" = None, allow_large: bool = False, force: bool = False) -> dict:
    """Run (or resume) every point of a sweep, then write its table and figures. Returns sweep.json.
    ``batch_rows``: encounter rows per task of each campaign (default the campaign runner's). Every
    point's memory estimate is checked before the first starts (``allow_large`` as in
    :func:`~daa_sil.study.campaign.run.run_campaign`); ``force`` replaces a previous sweep in ``out_dir``."""
    from daa_sil.study.campaign.run import run_campaign  # lazy: start-up time
    from daa_sil.study.campaign.memory import campaign_memory  # lazy: start-up time
    from daa_sil.study.campaign.plan import DEFAULT_BATCH_ROWS  # lazy: start-up time
    from daa_sil.out_dir import claim_out_dir, contents  # lazy: start-up time
    from daa_sil.study.campaign.files import check_out_dir  # lazy: start-up time
    from daa_sil.files import atomic_write_json, to_jsonable  # lazy: start-up time

    configs = point_configs(base, vary)
    out = Path(out_dir)
    check_out_dir(out, resume, force)
    remote = bool(scheduler) and scheduler != "local-dask"
    for cfg, v in zip(configs, vary.values):
        try:
            campaign_memory(cfg, workers, batch_rows or DEFAULT_BATCH_ROWS, remote=remote).check(
                allow_large, "use fewer --encounters, --intruders, --workers or --batch-rows")
        except UsageError as exc:
            raise UsageError(f"--vary {vary.name}={v}: {exc}") from None
    meta_path = out / "sweep.json"
    meta = {"format": SWEEP_FORMAT, "vary": vary.name, "field": vary.field, "values": list(vary.values),
            "base": base.to_dict(), "points": [{"value": v, "dir": f"points/{vary.slug(v)}"} for v in vary.values]}
    meta = json.loads(json.dumps(to_jsonable(meta)))
    if meta_path.is_file() and not force:
        stored = json.loads(meta_path.read_text(encoding="utf-8"))
        diff = [k for k in ("vary", "values") if stored.get(k) != meta[k]]
        if not same_base(stored.get("base"), meta["base"]):
            diff.append("base")
        if diff:
            raise UsageError(f"--resume: {meta_path} was made with different settings ({', '.join(diff)}); "
                             f"pass the same --vary and options or choose a new --out")
    with claim_out_dir(out, keep=resume, replace=remove_sweep if force else None,
                       hint="pass --resume to continue the sweep there, --force to replace it, or choose a new directory"):
        atomic_write_json(meta_path, meta)
        for cfg, point in zip(configs, meta["points"]):
            d = out / point["dir"]
            again = bool(contents(d))
            if say:
                say(f"{vary.name} = {point['value']}: {'resuming' if again else 'running'} {d}")
            run_campaign(cfg, d, workers=workers, scheduler=scheduler, resume=again, progress=progress,
                         allow_large=True,  # checked above, every point
                         **({"batch_rows": batch_rows} if batch_rows is not None else {}))
        write_summary(out)
    return meta


def same_base(stored: "dict | None", base: dict) -> bool:
    """Whether a sweep.json's recorded base configuration is ``base`` (both as ``to_dict`` gives them),
    read as a configuration: a sweep started by an earlier version records the same campaign under its
    older keys (``wt``, ``projl_lookahead``, ``link``)."""
    if stored == base:
        return True
    from daa_sil.files import to_jsonable  # lazy: start-up time
    from daa_sil.study.campaign.config import CampaignConfig  # lazy: start-up time

    try:
        again = CampaignConfig.from_dict(stored, "sweep.json base").to_dict()
    except (FileFormatError, AttributeError):  # not a configuration at all: it differs
        return False
    return json.loads(json.dumps(to_jsonable(again))) == base


def remove_sweep(out: Path) -> None:
    """``--force``: remove a previous sweep's files from ``out`` (``sweep.json``, its table and figures,
    ``points/``); anything else stays."""

    for f in ("sweep.json", "sweep.csv", "sweep.md", *(p.name for p in out.glob("sensitivity_*.png"))):
        (out / f).unlink(missing_ok=True)
    shutil.rmtree(out / "points", ignore_errors=True)


def _load(out: Path) -> dict:
    path = out / "sweep.json"
    try:
        meta = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise FileFormatError(f"{path} does not exist; not a sweep directory") from None
    except (OSError, ValueError) as exc:
        raise FileFormatError(f"{path} is not readable JSON: {exc}") from None
    if not isinstance(meta, dict) or meta.get("format") != SWEEP_FORMAT:
        raise FileFormatError(f"{path}: not a daa-sil sweep file (format {SWEEP_FORMAT} expected)")
    return meta


def summarize(out: "str | Path", replicates: "int | None" = None, seed: "int | None" = None) -> list[dict]:
    """Rows ``{value, group, metric, estimate, lo, hi, method}`` for every point, group and metric."""
    from daa_sil.study.analysis.study import Study  # lazy: start-up time
    from daa_sil.study.analysis.report_input import load_block  # lazy: start-up time
    from daa_sil.study.analysis.stats import DEFAULT_REPLICATES, DEFAULT_SEED  # lazy: start-up time

    out = Path(out)
    meta = _load(out)
    rows = []
    for point in meta["points"]:
        b = load_block(out / point["dir"])
        st = Study(b.enc, b.reading, dec=b.dec, replicates=replicates or DEFAULT_REPLICATES,
                   seed=DEFAULT_SEED if seed is None else seed)
        for g in st.groups:
            for metric, _, scale in METRICS:
                if not st.available(g, metric):
                    continue
                e = st.estimate(g, metric)
                rows.append({"vary": meta["vary"], "value": point["value"], "group": g, "metric": metric,
                             "estimate": e.value * scale, "lo": e.lo * scale, "hi": e.hi * scale,
                             "method": e.method, "n_encounters": st.n_encounters(g)})
    return rows


def _fmt(x: float) -> str:
    return "–" if x is None or not math.isfinite(x) else f"{x:.3g}"


def write_summary(out: "str | Path") -> list[Path]:
    """``sweep.csv``, ``sweep.md`` and one PNG per metric into the sweep directory."""
    from daa_sil.files import atomic_write_text  # lazy: start-up time

    out = Path(out)
    meta = _load(out)
    rows = summarize(out)
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(rows[0]) if rows else ["vary"])
    w.writeheader()
    w.writerows(rows)
    paths = [atomic_write_text(out / "sweep.csv", buf.getvalue())]
    paths += _figures(out, meta, rows)
    paths.append(atomic_write_text(out / "sweep.md", render(meta, rows)))
    return paths


def render(meta: dict, rows: Sequence[dict], image_prefix: str = "") -> str:
    """The sweep as Markdown: one table per metric (value x group, estimate [95 % CI]) and its figure."""
    base = meta["base"]
    from daa_sil.study.campaign.config import CampaignConfig  # lazy: start-up time

    # the maps the points read: a reading with its own grid (e.g. paper) overrides the campaign's --waitmap
    maps = CampaignConfig.from_dict(base, "sweep base").map_source
    groups = list(dict.fromkeys(r["group"] for r in rows))
    n = {r["group"]: r["n_encounters"] for r in rows}
    L = [f"## Sensitivity to `{meta['vary']}`", "",
         f"Values {', '.join(str(v) for v in meta['values'])}; groups {', '.join(groups)}; "
         f"{', '.join(f'{g}: {n[g]:,}' for g in groups)} encounters per point, campaign seed {base['seed']} "
         f"(every point flies the same encounters); wait maps `{maps}`, reading `{base['reading']}`. "
         "Each cell: our value [encounter-level 95 % CI].", ""]
    for metric, label, _ in METRICS:
        sel = [r for r in rows if r["metric"] == metric]
        if not sel:
            continue
        L += [f"### {label}", "", "| " + meta["vary"] + " | " + " | ".join(groups) + " |",
              "|---|" + "---|" * len(groups)]
        for v in meta["values"]:
            cells = []
            for g in groups:
                r = next((r for r in sel if r["value"] == v and r["group"] == g), None)
                if r is None or not math.isfinite(r["estimate"]):
                    cells.append("–")
                else:
                    cells.append(f"{_fmt(r['estimate'])} [{_fmt(r['lo'])}, {_fmt(r['hi'])}]")
            L.append(f"| {v} | " + " | ".join(cells) + " |")
        L += ["", f"![{label}]({image_prefix}sensitivity_{metric}.png)", ""]
    return "\n".join(L)


def _figures(out: Path, meta: dict, rows: Sequence[dict]) -> list[Path]:
    import matplotlib  # lazy: start-up time

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt  # lazy: start-up time
    import numpy as np  # lazy: start-up time

    from daa_sil.files import atomic_path  # lazy: start-up time

    values = meta["values"]
    numeric = VARIABLES[meta["vary"]][2]
    x = np.asarray(values, float) if numeric else np.arange(len(values), dtype=float)
    groups = list(dict.fromkeys(r["group"] for r in rows))
    paths = []
    for metric, label, _ in METRICS:
        sel = [r for r in rows if r["metric"] == metric]
        if not sel:
            continue
        fig, ax = plt.subplots(figsize=(6, 4))
        for k, g in enumerate(groups):
            est = np.array([next((r["estimate"] for r in sel if r["value"] == v and r["group"] == g), np.nan)
                            for v in values], float)
            lo = np.array([next((r["lo"] for r in sel if r["value"] == v and r["group"] == g), np.nan)
                           for v in values], float)
            hi = np.array([next((r["hi"] for r in sel if r["value"] == v and r["group"] == g), np.nan)
                           for v in values], float)
            off = (k - (len(groups) - 1) / 2) * (0.015 * (np.ptp(x) or 1.0))
            err = np.vstack([np.clip(est - lo, 0, None), np.clip(hi - est, 0, None)])
            ax.errorbar(x + off, est, yerr=np.nan_to_num(err), marker="o", capsize=3, label=g)
        if not numeric:
            ax.set_xticks(x, [str(v) for v in values], rotation=20)
        ax.set_xlabel(meta["vary"])
        ax.set_ylabel(label, fontsize=8)
        ax.set_title(f"{label} vs {meta['vary']} (95 % CI)", fontsize=9)
        ax.legend(fontsize=7)
        p = out / f"sensitivity_{metric}.png"
        with atomic_path(p) as tmp:
            fig.savefig(tmp, format="png", dpi=110, bbox_inches="tight")
        plt.close(fig)
        paths.append(p)
    return paths


def collate(sweeps: Sequence["str | Path"], out_dir: "str | Path", title: str = "Sensitivity beyond the paper") -> Path:
    """One Markdown page (``out_dir/sensitivity.md``) from several sweep directories; their figures are
    copied next to it as ``<vary>_<metric>.png``."""

    from daa_sil.files import atomic_write_text, ensure_dir  # lazy: start-up time

    out = ensure_dir(out_dir)
    parts = [f"# {title}", "", "Generated by `daa-sil campaign sweep` (one directory per varied setting) and "
             "`daa-sil campaign sweep --collate`. Intervals are encounter-level (cluster bootstrap, "
             "`docs/statistics.md`).", ""]
    for d in sweeps:
        d = Path(d)
        meta = _load(d)
        rows = summarize(d)
        prefix = f"{meta['vary']}_"
        for metric, _, _ in METRICS:
            src = d / f"sensitivity_{metric}.png"
            if src.is_file():
                shutil.copyfile(src, out / f"{prefix}sensitivity_{metric}.png")
        parts.append(render(meta, rows, image_prefix=prefix))
    return atomic_write_text(out / "sensitivity.md", "\n".join(parts) + "\n")


__all__ = ["VARIABLES", "METRICS", "Vary", "parse_vary", "point_configs", "run_sweep", "summarize", "write_summary",
           "render", "collate"]
