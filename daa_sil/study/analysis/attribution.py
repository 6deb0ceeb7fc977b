"""The attribution table: every miss of a reading (a finding *not reproduced*, or reproduced only in
direction) in a cluster, with its named cause, the experiment that tests the cause and what the
experiment showed -- filled from ``experiments.json`` (:mod:`daa_sil.study.analysis.experiment_suite`).

:data:`CLUSTERS` is the one definition: each cluster lists its finding ids, one of :data:`CAUSES`, the
cause in words, the experiments (keys of ``experiments.json``) and a function that words what they
showed from their figures. Every finding of ``paper_findings.yaml`` that is not true by construction
belongs to exactly one cluster (``tests/test_attribution.py``), so no miss is left without a row;
:func:`attribution_rows` lists any miss outside every cluster as *unattributed* (a defect of this table).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

from daa_sil.study.analysis.experiment_analysis import diff, value
from daa_sil.study.analysis.findings import DIRECTION, NOT_REPRODUCED, fmt

#: the named causes a miss can have
CAUSES = ("our DAA", "our pilot", "the encounter set", "the paper's vagueness", "the paper's inconsistency",
          "a defect")
#: the verdicts that are misses
MISSES = (NOT_REPRODUCED, DIRECTION)


def _f(x, kind: str = "g3") -> str:
    return "–" if x is None or (isinstance(x, float) and not math.isfinite(x)) else fmt(x, kind)


def _ci(e: dict, label: str, metric: str, kind: str = "g3", which=value) -> str:
    v = which(e, label, metric)
    if v is None:
        return "–"
    lo, hi = which(e, label, metric, "lo"), which(e, label, metric, "hi")
    return f"{_f(v, kind)} [{_f(lo, kind)}, {_f(hi, kind)}]" if lo is not None and hi is not None else _f(v, kind)


def _not_run(*keys) -> str:
    return f"not run ({', '.join(keys)} missing from experiments.json)"


def _allocation(x: dict) -> str:
    lr, dd, out = x.get("latency_rule"), x.get("delay_draw"), x.get("outside")
    if not (lr and dd and out):
        return _not_run("latency_rule", "delay_draw", "outside")
    return (f"B-1's DAA allocations are the steps before its first command arrives: {_ci(lr, 'B-1', 'no_wait')} per "
            f"encounter with the 4 s round trip, {_ci(lr, 'B-1 (paper-one-way)', 'no_wait')} with 4 s on each link "
            f"(the paper: 7.88). B-2: {_ci(dd, 'B-2', 'no_wait')}, with one draw per encounter "
            f"{_ci(dd, 'B-2 (paper-delay-per-encounter)', 'no_wait')} (the paper: 8.72). IC-1 and ID-1 almost never "
            f"allocate: {_ci(lr, 'IC-1', 'no_wait')} and {_ci(lr, 'ID-1', 'no_wait')} (the paper: 1.02, 2.11), "
            f"{_ci(lr, 'IC-1 (paper-one-way)', 'no_wait')} and {_ci(lr, 'ID-1 (paper-one-way)', 'no_wait')} with "
            f"each link's delay: with a constant delay a gap in the commands ends within the wait, so neither reading "
            f"gives the paper's counts. ID-2: {_ci(out, 'ID-2', 'no_wait')}, with the box's edge read for a far state "
            f"{_ci(out, 'ID-2 (paper-clamp)', 'no_wait')} (the paper: 1.03). No single reading matches every group: "
            f"the paper's counts fit neither rule for what its latency measures")


def _reception(x: dict) -> str:
    h, c = x.get("hold"), x.get("counting")
    if not (h and c):
        return _not_run("hold", "counting")
    return (f"received per encounter (B-2): {_ci(h, 'B-2', 'received')}; without the 'hold' stream "
            f"{_ci(h, 'B-2 (paper-no-hold)', 'received')}; counting one command per step "
            f"{_ci(c, 'B-2 (one per step)', 'received')} (the paper: 79.4). At one command a second, the paper's "
            f"79.4 is a stream of about 80 s an encounter; ours runs from the first telemetry until our test of safe "
            f"avoidance, about 112 s: the stream's length, which the paper does not give, sets every count of "
            f"this cluster. DAA overrides (B-2): {_ci(h, 'B-2', 'daa_override')} per encounter, "
            f"{_ci(x.get('hold_none') or {}, 'B-2 (paper-hold-none)', 'daa_override')} with an unsafe 'hold' as no "
            f"command (the paper: 0.76): the paper's override count is closer to the reading Algorithm 1 "
            f"contradicts; {_f(_axes_share(x, 'B-2', 'DAA override', ('none',)), 'pct')} of our overrides keep the "
            f"current course against a pilot's 'hold' that would turn back toward the intruder")
def _blend_match(x: dict) -> str:
    w, lat, s = x.get("blend_waiting"), x.get("blend_latency"), x.get("blend_searches")
    if not (w and lat and s):
        return _not_run("blend_waiting", "blend_latency", "blend_searches")
    d = s["groups"].get("ID-2", {})
    asked = d.get("failed_exact_asked", ())
    asked = sorted(asked.items(), key=lambda kv: -kv[1]) if isinstance(asked, dict) else [tuple(x) for x in asked]
    tot = sum(v for _, v in asked) or 1
    asked = ", ".join(f"{k} ({100 * v / tot:.0f} %)" for k, v in asked[:2]) or "–"
    return (f"exact (axis, direction) in ID-2 {_ci(w, 'ID-2', 'exact_match', 'pct')}, with no waiting "
            f"{_ci(w, 'ID-2-no-wait', 'exact_match', 'pct')} (difference {_ci(w, 'ID-2', 'exact_match', 'pct', diff)}): "
            f"waiting {'does not measurably lower' if _zero_in(w, 'ID-2', 'exact_match') else 'changes'} the exact "
            f"match. Latency: {_ci(lat, 'ID-2-lat0.2', 'exact_match', 'pct')} at 0.2 s, "
            f"{_ci(lat, 'ID-2-lat10', 'exact_match', 'pct')} at 10 s (difference "
            f"{_ci(lat, 'ID-2-lat10', 'exact_match', 'pct', diff)}). The searches that missed the pilot's direction "
            f"asked for {asked} of them: no candidate of our DAA on that side was safe")


def _zero_in(e: dict, label: str, metric: str) -> bool:
    lo, hi = diff(e, label, metric, "lo"), diff(e, label, metric, "hi")
    return lo is not None and hi is not None and lo <= 0.0 <= hi


def _safety(x: dict) -> str:
    s, lw = x.get("severity"), x.get("lowc")
    if not (s and lw):
        return _not_run("severity", "lowc")
    auth = lw["groups"].get("ID-2", {}).get("authority_at_onset", {})
    blend_unsafe = _unsafe_share(x, "IC-1", "blend of a maneuver")

    def q(g):
        return (lw["groups"].get(g, {}).get("from_alert2_s") or [None, None, None])[1]

    return (f"unmitigated, {_ci(s, 'unmitigated', 'p_lowc', 'pct')} of our encounters lose well clear and "
            f"{_ci(s, 'unmitigated', 'alert_share_2', 'pct')} reach a corrective alert; the paper reading's ID-2 "
            f"{_ci(s, 'ID-2', 'p_lowc', 'pct')}, {_ci(s, 'ID-2', 'p_lowc_step', 'sci')} of the time (the paper: "
            f"2.81e-7 x 666.67 h = 1.87e-4). The paper gives no unmitigated rate, so no experiment can calibrate our "
            f"encounter set to its. In ID-2, a LoWC begins under the DAA's authority in {_f(auth.get('daa'), 'pct')} "
            f"of cases, the pilot's in {_f(auth.get('pilot'), 'pct')}. The integrated groups lose well clear less than "
            f"the baselines (B-1 {_ci(s, 'B-1', 'p_lowc', 'pct')}, IC-1 {_ci(s, 'IC-1', 'p_lowc', 'pct')}), against "
            f"the paper's slight increase: a baseline LoWC begins a median {_f(q('B-1'), 'f1')} s after the "
            f"corrective alert, an integrated one {_f(q('IC-1'), 'f1')} s; the DAA's resolution flown as an override "
            f"is itself unsafe by SM in {_f(_unsafe_share(x, 'B-1', 'DAA override'), 'pct')} of the overrides, "
            f"Algorithm 2's blend in {_f(blend_unsafe, 'pct')} of the blends of "
            f"a maneuver. The paper's pair (ID-2 the fewest LoWC encounters, yet a higher P(LoWC)/h than B-2) holds "
            f"only if ID-2's LoWCs last longer: appendix-provenance.md")


def _pi(x: dict) -> str:
    lw = x.get("lowc")
    if not lw:
        return _not_run("lowc")
    g = lw["groups"]
    n = sum(d.get("pi_gt_max", 0) for d in g.values())
    turn = sum(d.get("pi_gt_max_turning", 0) for d in g.values())
    daa = sum(d.get("pi_gt_max_daa_at_onset", 0) for d in g.values())
    q = g.get("B-2", {}).get("from_alert2_s")
    tq = g.get("B-2", {}).get("turn_to_onset_s")
    share = g.get("B-2", {}).get("turning_before_onset")
    return (f"{n} replayed LoWCs with PI above 3.79 over the five groups: {turn} with the intruder turning before the "
            f"onset, {daa} begun under the DAA's authority. In B-2, {_f(share, 'pct')} of the LoWCs follow an intruder's "
            f"turn (a median {_f(tq[1] if tq else None, 'f1')} s before the onset) and begin a median "
            f"{_f(q[1] if q else None, 'f1')} s after the corrective alert: a late turn of the intruder (our turns "
            f"last up to 90° of heading, a choice) leaves our DAA and pilot a few seconds")


def _per_leaving(x: dict, label: str, metric: str) -> "float | None":
    """Mean deviation per encounter that left the plan: the mean over all encounters over the share that
    left it (an encounter that never leaves the plan deviates 0)."""
    v, share = value(x, label, metric), value(x, label, "maneuvered_share")
    return v / share if v is not None and share else None


def _deviation(x: dict) -> str:
    d, s, ft = x.get("deviation"), x.get("severity"), x.get("feet")
    if not (d and s and ft):
        return _not_run("deviation", "severity", "feet")
    left = value(d, "B-1", "maneuvered_share")
    man = value(d, "B-1", "dev_h_maneuvered_mean")
    if man is None:
        reach = "–"
    elif man >= 1690.0:
        reach = (f"the paper's mean needs {_f(1690.0 / man, 'pct')} of the encounters to maneuver as far as ours that "
                 f"do")
    else:
        reach = ("even if every encounter maneuvered as far as ours that do, the mean would stay below the paper's "
                 "1,690 m: no definition we tried gives its size, so the definition is not the cause")
    return (f"B-1: {_ci(d, 'B-1', 'dev_h_mean', 'f0')} m (largest distance from the straight path, over all "
            f"encounters), {_ci(d, 'B-1', 'dev_h_tmean_mean', 'f0')} m as a time mean, "
            f"{_ci(d, 'B-1', 'dev_h_maneuvered_mean', 'f0')} m over the {_f(left, 'pct')} that left the plan "
            f"(the paper: 1,690 m). {reach[0].upper()}{reach[1:]}; {_ci(s, 'unmitigated', 'alert_share_2', 'pct')} "
            f"of our encounters reach a corrective alert. With the intruder table read in feet, "
            f"{_f(value(ft, 'B-1 (feet)', 'maneuvered_share'), 'pct')} leave the plan and B-1 deviates "
            f"{_ci(ft, 'B-1 (feet)', 'dev_h_mean', 'f0')} m, {_f(_per_leaving(ft, 'B-1 (feet)', 'dev_h_mean'), 'f0')} m "
            f"per encounter that left it: the baselines' horizontal size follows the share that maneuvers. It does "
            f"not settle the rest: in feet IC-1 and ID-2 deviate {_ci(ft, 'IC-1 (feet)', 'dev_h_mean', 'f0')} and "
            f"{_ci(ft, 'ID-2 (feet)', 'dev_h_mean', 'f0')} m horizontally, and vertically B-1 "
            f"{_ci(ft, 'B-1 (feet)', 'dev_v_mean', 'f1')} m, ID-2 {_ci(ft, 'ID-2 (feet)', 'dev_v_mean', 'f1')} m "
            f"(the paper: about 183 m in every group)")


def _kind(x: dict, group: str, kind: str) -> dict:
    return ((x.get("exec_axes") or {}).get("groups", {}).get(group) or {}).get(kind) or {}


def _axes_share(x: dict, group: str, kind: str, axes: tuple) -> "float | None":
    k = _kind(x, group, kind)
    return sum(k["axes"].get(a, 0) for a in axes) / k["n"] if k.get("n") else None


def _unsafe_share(x: dict, group: str, kind: str) -> "float | None":
    k = _kind(x, group, kind)
    return k["unsafe"] / k["n"] if k.get("n") and k.get("unsafe") is not None else None


def _deviation_setups(x: dict) -> str:
    d, a = x.get("deviation"), x.get("exec_axes")
    if not (d and a):
        return _not_run("deviation", "exec_axes")
    hold_kept = _axes_share(x, "ID-2", "blend of a 'hold'", ("none",))
    return (f"an unsafe received command is overridden in B-2 by the DAA's resolution, a turn in "
            f"{_f(_axes_share(x, 'B-2', 'DAA override', ('horizontal',)), 'pct')} of the overrides (the current course "
            f"kept in {_f(_axes_share(x, 'B-2', 'DAA override', ('none',)), 'pct')}); in ID-2 Algorithm 2 blends it to "
            f"the safe candidate closest to it: a blended maneuver is a climb or descent in "
            f"{_f(_axes_share(x, 'ID-2', 'blend of a maneuver', ('vertical',)), 'pct')}, a blended 'hold' keeps the "
            f"course in {_f(hold_kept, 'pct')}. Paired over the same "
            f"encounters, ID-2 deviates {_ci(d, 'ID-2', 'dev_h_mean', 'f0', diff)} m horizontally and "
            f"{_ci(d, 'ID-2', 'dev_v_mean', 'f1', diff)} m vertically against B-1, with the same share leaving the plan "
            f"({_ci(d, 'ID-2', 'maneuvered_share', 'pct', diff)})")


@dataclass(frozen=True)
class Cluster:
    """One cluster of findings with its named cause (see the module docstring)."""

    key: str
    title: str
    findings: tuple
    causes: tuple  #: of :data:`CAUSES`
    because: str
    experiments: tuple  #: keys of experiments.json
    showed: Callable[[dict], str]

    def __post_init__(self):
        bad = [c for c in self.causes if c not in CAUSES]
        if bad:
            raise ValueError(f"cluster {self.key}: unknown cause {bad[0]!r}; allowed: {', '.join(CAUSES)}")


CLUSTERS: tuple[Cluster, ...] = (
    Cluster("allocation", "waiting status (waits, DAA allocations, their reduction)",
            ("wait", "no-wait", "no-wait-reduction", "no-wait-reduction-average"), ("the paper's vagueness",),
            "what a group's latency value measures and how the Gaussian delay varies in time decide how many steps pass "
            "without a command; the text gives neither", ("latency_rule", "delay_draw", "outside"), _allocation),
    Cluster("reception", "command reception and execution counts",
            ("received", "received-increase", "received-increase-average", "received-ic1-over-id2", "pilot-executed",
             "override", "blend"), ("our pilot", "the paper's vagueness"),
            "the counts are the pilot's stream: one command a second from its first telemetry till safe avoidance "
            "(the paper: 'from the beginning of an encounter till safe avoidance', its length not given)",
            ("hold", "counting", "hold_none"), _reception),
    Cluster("blend-match", "Algorithm 2's (axis, direction) match",
            ("exact-match", "axis-match", "neither-match"), ("our DAA",),
            "Algorithm 2 searches our DAA's candidates; where none in the pilot's direction is safe it takes the axis "
            "or any safe maneuver", ("blend_searches", "blend_waiting", "blend_latency"), _blend_match),
    Cluster("safety", "LoWC and NMAC: counts, orderings, the turning share, P(LoWC) per flight hour",
            ("nmac", "lowc-fewest-id2", "lowc-most-b2", "lowc-turning", "p-lowc-hr", "p-lowc-hr-remote",
             "p-lowc-hr-increase"), ("the encounter set", "the paper's inconsistency"),
            "how many encounters come close is the encounter set's (the paper gives only its parameter table); the "
            "paper's P(LoWC) per flight hour divides by its own campaign's hours, and its LoWC statements fit "
            "together only if ID-2's LoWCs last longer; our baselines' DAA overrides lose well clear more often than "
            "the integrated groups' blends", ("severity", "lowc", "exec_axes"), _safety),
    Cluster("pi", "penetration integral", ("pi-mean", "pi-max", "pi-severe"),
            ("the encounter set", "our DAA", "our pilot"),
            "the severe LoWCs are late turns of fast intruders: what our DAA and pilot do in the last seconds",
            ("lowc",), _pi),
    Cluster("deviation", "trajectory deviation: its size", ("dev-h", "dev-v"),
            ("the encounter set", "our DAA"),
            "the encounter set for the baselines' horizontal size: few of our encounters maneuver at all, no "
            "definition of the deviation makes up for it, and where most maneuver (the intruder table read in feet) "
            "B-1 and B-2 deviate about the paper's size per encounter that maneuvers. Our DAA for the integrated "
            "groups' horizontal size: their blends climb or descend instead of turning (next row). Not settled by "
            "these runs: the vertical size of every group, far below the paper's in either unit; the experiment that "
            "would settle it is the deviation definitions and the flown axes on the paper-feet encounters "
            "(the deviation and exec_axes figures of run paper-feet, not yet in the experiment suite)",
            ("deviation", "severity", "feet"), _deviation),
    Cluster("deviation-setups", "trajectory deviation: 'almost the same for every setup'",
            ("dev-h-change", "dev-v-change"), ("our DAA",),
            "the setups fly different maneuvers instead of an unsafe command: the baselines the DAA's resolution "
            "(when it maneuvers, a turn); the integrated groups Algorithm 2's safe candidate closest to the command "
            "(when it maneuvers, mostly a climb or descent). The paper does not say which safe maneuver its "
            "Algorithm 2 takes. Not settled by these runs: whether an Algorithm 2 that prefers a turn would give "
            "the paper's 'almost the same'; the experiment that would is such a variant on the same encounters "
            "(not built)",
            ("exec_axes", "deviation"), _deviation_setups),
)


def cluster_of(finding_id: str) -> "Cluster | None":
    return next((c for c in CLUSTERS if finding_id in c.findings), None)


def row_commands(keys, experiments: dict, meta: "dict | None") -> list[str]:
    """The commands behind the experiments ``keys`` of one row: the campaigns they read and the
    experiments command (:func:`daa_sil.study.campaign.experiments.commands_for`); empty without ``meta``."""
    from daa_sil.study.campaign.experiments import commands_for  # lazy: start-up time

    runs = [r for k in keys for r in (experiments.get(k) or {}).get("runs", ())]
    return commands_for(runs, meta) if meta and runs else []


def attribution_rows(rows, label: str, experiments: "dict | None", meta: "dict | None" = None) -> list[dict]:
    """One row per cluster (its misses under reading ``label``: ``id — group``), plus one per miss that no
    cluster holds (cause *unattributed*). ``rows`` from :func:`daa_sil.study.analysis.verdicts.evaluate_all`;
    ``experiments`` the ``experiments`` mapping of ``experiments.json`` (None: not run), ``meta`` its
    ``meta`` (seed and sizes: each row's ``commands``)."""
    exps = experiments or {}
    out, seen = [], set()
    for c in CLUSTERS:
        misses = [f"{f.id}" + (f" — {f.group}" if f.group else "") + f" ({outs[label].verdict})"
                  for f, outs in rows if f.id in c.findings and outs[label].verdict in MISSES]
        seen.update(c.findings)
        out.append({"cluster": c.title, "key": c.key, "misses": misses, "causes": list(c.causes),
                    "because": c.because, "experiments": list(c.experiments),
                    "commands": row_commands(c.experiments, exps, meta),
                    "showed": c.showed(exps) if exps else _not_run(*c.experiments)})
    for f, outs in rows:
        if f.id not in seen and not f.by_construction and outs[label].verdict in MISSES:
            out.append({"cluster": "unattributed", "key": "unattributed", "misses": [f"{f.id} — {f.group}"],
                        "causes": [], "because": "no cluster holds this finding: a defect of the attribution table",
                        "experiments": [], "commands": [], "showed": ""})
    return out


__all__ = ["CAUSES", "MISSES", "Cluster", "CLUSTERS", "cluster_of", "attribution_rows", "row_commands"]
