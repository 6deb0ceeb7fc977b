"""Every experiment's figures, from the runs of one campaign seed (:func:`analyse`): the readings of
``docs/results/regenerate.py`` under ``RUNS/<reading>`` and the experiment campaigns of
:mod:`daa_sil.study.campaign.experiments` under ``RUNS/exp-<name>-<N>``. The result is ``experiments.json``:
``{"meta": ..., "experiments": {key: {...}}}``; :mod:`daa_sil.study.report.experiment_page` prints it and
:mod:`daa_sil.study.analysis.attribution` cites it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

from daa_sil.study.analysis.experiment_analysis import PAPER_COUNTING, compare
from daa_sil.study.campaign.experiment_replays import blend_searches, executed_axes, lowc_diagnostics
from daa_sil.study.campaign.experiments import PAPER5, RUNS, run_dir

#: how to run the experiments again (``{runs}`` etc. filled in by :func:`analyse`)
COMMAND = ("python docs/results/experiments.py --runs {runs} --seed {seed} --small {small} --large {large}")
SIGNATURE_METRICS = ("no_wait", "wait", "received", "unsafe_share", "blend", "daa_override")


def _exp(title: str, why: str, result: dict, runs: list, **extra) -> dict:
    return {"title": title, "why": why, "runs": runs, **result, **extra}


def analyse(runs: "str | Path", seed: int, n_small: int, n_large: int, replicates: int = 1000,
            log: Callable[[str], None] = print) -> dict:
    """The figures of every experiment whose runs exist under ``runs`` (a missing run is skipped with a
    note in ``meta.missing``)."""
    runs = Path(runs)
    paper = runs / "paper"
    exp = {r.name: run_dir(runs, r, n_large if r.size == "large" else n_small) for r in RUNS}
    missing: list = []

    def have(*dirs) -> bool:
        gone = [str(d) for d in dirs if not (Path(d) / "campaign.json").is_file()]
        missing.extend(gone)
        return not gone

    def reading(name: str) -> Path:
        return runs / name

    out: dict = {}
    def cmp(parts, metrics, ref=None, counting=None, pairs=None):
        return compare(parts, metrics, ref, counting, replicates, pairs)
    if have(paper, exp["unmitigated"]):
        log("== severity")
        parts = [("unmitigated", exp["unmitigated"], "unmitigated")] + [(g, paper, g) for g in PAPER5]
        out["severity"] = _exp("Encounter severity and the unmitigated risk",
                               "how many encounters come close at all: the same encounters with no DAA and no pilot "
                               "maneuver, against the paper reading's groups",
                               cmp(parts, ("alert_share_1", "alert_share_2", "alert_share_3", "p_lowc", "p_lowc_step",
                                           "lowc_s_per_hr", "maneuvered_share", "dev_h_mean", "dev_v_mean"),
                                   "unmitigated"), ["paper", "unmitigated"])
    if have(paper, exp["paper-feet"]):
        log("== feet")
        parts = [(g, paper, g) for g in PAPER5] + [(f"{g} (feet)", exp["paper-feet"], g) for g in PAPER5]
        out["feet"] = _exp("The HMD/VMD table read in feet", "what the unit alone does to the encounters and the "
                           "outcomes (against the table's metres)",
                           cmp(parts, ("dev_h_mean", "dev_v_mean", "unsafe_share", "p_lowc", "p_lowc_step",
                                       "alert_share_2", "maneuvered_share", "no_wait", "received"),
                               pairs=[(f"{g} (feet)", g) for g in PAPER5]),
                           ["paper", "paper-feet"])
    if have(paper):
        log("== deviation")
        out["deviation"] = _exp("Trajectory deviation: which definition", "the largest and the time-mean distance "
                                "from the straight path, the cross-track distance, the distance at the end, over all "
                                "encounters and over those that left the plan",
                                cmp([(g, paper, g) for g in PAPER5],
                                    ("dev_h_mean", "dev_h_tmean_mean", "dev_xtrack_mean", "dev_h_end_mean",
                                     "dev_h_maneuvered_mean", "maneuvered_share", "dev_v_mean", "dev_v_tmean_mean")),
                                ["paper"])
        log("== LoWC diagnostics (replays)")
        out["lowc"] = {"title": "Each loss of well clear", "why": "the authority at its onset, the time from the first "
                       "alert, the pilot's maneuver, the intruder's turn", "runs": ["paper"],
                       "groups": lowc_diagnostics(paper, PAPER5)}
        log("== Algorithm 2's searches")
        out["blend_searches"] = {"title": "Algorithm 2's searches", "why": "which rule found the blended maneuver, "
                                 "and what the searches that missed the pilot's (axis, direction) asked for",
                                 "runs": ["paper"], "groups": blend_searches(paper, ("IC-1", "ID-1", "ID-2"))}
        out["exec_axes"] = {"title": "What the vehicle flies instead of the pilot's command", "why": "an unsafe "
                            "received command is overridden by the DAA's resolution in the baselines and blended by "
                            "Algorithm 2 in the integrated groups: the axis of what is flown instead (course kept: "
                            "the command flown keeps the current course, which the pilot's command would have "
                            "changed)", "runs": ["paper"], "groups": executed_axes(paper, PAPER5)}
    if have(exp["blend-no-wait"]):
        out["blend_waiting"] = _exp("Blends without waiting", next(r.why for r in RUNS if r.name == "blend-no-wait"),
                                    cmp([("ID-2", exp["blend-no-wait"], "ID-2"),
                                         ("ID-2-no-wait", exp["blend-no-wait"], "ID-2-no-wait")],
                                        ("exact_match", "axis_match", "neither_match", "unsafe_share", "blend",
                                         "p_lowc"), "ID-2-no-wait"), ["blend-no-wait"])
    if have(exp["blend-latency"]):
        labels = ("ID-2-lat0.2", "ID-2-lat4", "ID-2", "ID-2-lat10")
        out["blend_latency"] = _exp("Blends at other latencies", next(r.why for r in RUNS if r.name == "blend-latency"),
                                    cmp([(g, exp["blend-latency"], g) for g in labels],
                                        ("exact_match", "unsafe_share", "blend", "p_lowc"), "ID-2-lat0.2"),
                                    ["blend-latency"])
    if have(paper, reading("paper-keep-daa"), exp["no-command-pilot"], exp["no-command-pilot-keep"]):
        parts = [(g, paper, g) for g in PAPER5] + [(f"{g} (keep)", reading("paper-keep-daa"), g)
                                                   for g in ("B-2", "ID-2")]
        parts += [("ID-2 no pilot", exp["no-command-pilot"], "ID-2"),
                  ("ID-2 no pilot (keep)", exp["no-command-pilot-keep"], "ID-2")]
        out["switches"] = _exp("Authority switches per active encounter", "how often the authority changes hands, "
                               "under the paper's Algorithm 1 and with the DAA keeping its authority until clear (our "
                               "extension), also with a pilot that sends nothing",
                               cmp(parts, ("switches_per_active", "no_wait", "wait", "p_lowc", "unsafe_share"),
                                   pairs=[("B-2 (keep)", "B-2"), ("ID-2 (keep)", "ID-2"), ("ID-2 no pilot", "ID-2"),
                                          ("ID-2 no pilot (keep)", "ID-2 no pilot")]),
                               ["paper", "paper-keep-daa", "no-command-pilot", "no-command-pilot-keep"])
    for key, name, title, why, groups in (
            ("delay_draw", "paper-delay-per-encounter", "The Gaussian delay: redrawn every 10 s or once per encounter",
             "whether the delay's variation within an encounter makes B-2's and ID-2's DAA allocations",
             ("B-1", "B-2", "ID-2")),
            ("latency_rule", "paper-one-way", "A group's latency: the round trip or each link's delay",
             "B-1's no-wait decisions are the steps before its first command arrives: one round trip",
             ("B-1", "B-2", "IC-1", "ID-1", "ID-2")),
            ("outside", "paper-clamp", "The wait outside the map's box", "the map's DAA allocations when a far state "
             "reads the box edge's wait", ("IC-1", "ID-2")),
            ("outside_far", "paper-outside-far", "The wait outside the map's box: w = H", "the other rule the text "
             "allows", ("ID-2",)),
            ("h60", "paper-h60", "The maps' horizon 60 s", "the 40 s horizon (the published maximum wait) against 60 s",
             ("ID-2",)),
            ("hold", "paper-no-hold", "The 'hold' stream", "the pilot without 'hold' commands", ("B-2", "ID-2")),
            ("hold_none", "paper-hold-none", "An unsafe 'hold' as no command", "the setting Algorithm 1 contradicts",
             ("B-2", "ID-2")),
            ("active", "paper-corrective", "When the agent decides", "from the start of the encounter or from the "
             "corrective alert", ("B-1", "B-2", "ID-2"))):
        if have(paper, reading(name)):
            parts = [(g, paper, g) for g in groups] + [(f"{g} ({name})", reading(name), g) for g in groups]
            out[key] = _exp(title, why, cmp(parts, SIGNATURE_METRICS + ("map_decided_share", "in_box_share", "p_lowc"),
                                            pairs=[(f"{g} ({name})", g) for g in groups]), ["paper", name])
    if have(paper):
        a = cmp([(g, paper, g) for g in PAPER5], ("received", "pilot_exec", "blend", "daa_override"))
        b = cmp([(g, paper, g) for g in PAPER5], ("received", "pilot_exec", "blend", "daa_override"),
                counting={**PAPER_COUNTING, "superseded": "dropped"})
        for r in b["rows"]:
            r["label"] += " (one per step)"
        out["counting"] = {"title": "Counting every released command", "why": "the commands the link releases "
                           "with a newer one in the same step (after a delay drops), counted or not", "runs": ["paper"],
                           "n": a["n"], "rows": a["rows"] + b["rows"], "diffs": []}
    if have(paper, exp["sm35"], exp["sm25"]):
        parts = [(g, paper, g) for g in ("B-2", "ID-2")]
        parts += [(f"{g} (SM {h} s)", exp[f"sm{h}"], g) for h in (35, 25) for g in ("B-2", "ID-2")]
        out["sm"] = _exp("SM(u)'s horizon", "whether the unsafe-on-arrival share depends on how far SM looks",
                         cmp(parts, ("unsafe_share", "no_wait", "blend", "daa_override", "p_lowc"),
                             pairs=[(f"{g} (SM {h} s)", g) for h in (35, 25) for g in ("B-2", "ID-2")]),
                         ["paper", "sm35", "sm25"])
    meta = {"seed": seed, "n_small": n_small, "n_large": n_large, "replicates": replicates, "missing": missing,
            "command": COMMAND.format(runs="RUNS", seed=seed, small=n_small, large=n_large)}
    return {"meta": meta, "experiments": out}


__all__ = ["analyse", "COMMAND", "SIGNATURE_METRICS"]
