"""Experiments that read step logs: the encounters of a campaign flown again with their step log
(:func:`daa_sil.study.campaign.run.simulate_group`; one encounter, one answer: the replay is the
campaign's run) -- the loss-of-well-clear diagnostics and Algorithm 2's searches.

* :func:`lowc_diagnostics` -- per LoWC encounter: the authority and the decision at its onset, the
  time from the first alert (preventive, corrective) to the onset, whether (and when) a pilot maneuver
  had reached the vehicle, and the intruder's maneuver (its turn, begun before the onset or not);
* :func:`blend_searches` -- Algorithm 2's outcome per blend (the rule that found the maneuver: the
  pilot's axis and direction, the axis only, any, best effort), for blends of a maneuver and of a
  'hold', and the (axis, direction) the failed exact searches asked for.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Sequence

import numpy as np

from daa_sil.study.campaign.files import load_campaign_json, read_results


def _campaign(d: Path):
    from daa_sil.models.encounter_files import load_encounters  # lazy: start-up time
    from daa_sil.study.campaign.config import CampaignConfig  # lazy: start-up time

    cfg = CampaignConfig.from_dict(load_campaign_json(d)["config"], str(d / "campaign.json"))
    return cfg, load_encounters(d / "encounters.parquet")


def _quartiles(x) -> "list | None":
    x = np.asarray([v for v in x if v is not None and math.isfinite(v)], float)
    return [float(q) for q in np.percentile(x, (25, 50, 75))] if x.size else None


def _share(mask) -> "float | None":
    m = np.asarray(mask, bool)
    return float(m.mean()) if m.size else None


def replay(d: Path, group: str, ids: np.ndarray):
    """The step log of encounters ``ids`` of ``group`` in campaign ``d``, flown again alone (one
    encounter, one answer: the campaign's run of each; :func:`lowc_diagnostics` reports the share that
    lost well clear again, a check of that)."""
    from daa_sil.study.campaign.run import simulate_group  # lazy: start-up time

    cfg, encs = _campaign(d)
    pos = np.searchsorted(np.asarray(encs.encounter_id), ids)
    sub = encs.subset(pos)
    return simulate_group(cfg, group, sub, np.asarray(sub.seed, np.int64), record_steps=True)[2], encs


def lowc_diagnostics(d: Path, groups: Sequence[str], limit: int = 400) -> dict:
    """LoWC diagnostics of ``groups`` in campaign ``d`` (up to ``limit`` LoWC encounters per group)."""
    out = {}
    for g in groups:
        enc = read_results(d, "encounters", [g])
        ids = np.asarray(enc.column("encounter_id"))
        lowc = np.asarray(enc.column("lowc"), bool)
        pi = np.asarray(enc.column("pi_paper" if "pi_paper" in enc.column_names else "pi"), float)
        want = ids[lowc][:limit]
        if want.size == 0:
            out[g] = {"n_lowc": 0}
            continue
        log, encs = replay(d, g, want)
        eid = np.asarray(log.column("encounter_id"))
        t = np.asarray(log.column("t"), float)
        lw = np.asarray(log.column("lowc"), bool)
        alert = np.array([max(a) if a else 0 for a in log.column("alert_level").to_pylist()])
        auth = np.asarray(log.column("authority").to_pylist(), dtype=object)
        dec = np.asarray(log.column("decision").to_pylist(), dtype=object)
        pax = np.asarray(log.column("pilot_axis").to_pylist(), dtype=object)
        epos = np.searchsorted(np.asarray(encs.encounter_id), want)
        rate = np.asarray(encs.params["turn_rate_dps"])[epos, 0]
        adv = np.asarray(encs.params["advance"])[epos, 0]
        rows = []
        for k, e in enumerate(want):
            m = eid == e
            tt, ll = t[m], lw[m]
            if not ll.any():
                rows.append(None)  # the replay did not lose well clear (counted below)
                continue
            i = int(np.argmax(ll))
            onset = float(tt[i])
            first = {lvl: (float(tt[np.argmax(alert[m] >= lvl)]) if (alert[m] >= lvl).any() else math.nan)
                     for lvl in (1, 2)}
            man = np.flatnonzero(pax[m] != "none")
            t_turn = float(adv[k]) * encs.duration_s if rate[k] != 0 else math.nan
            rows.append({"authority": auth[m][i], "decision": dec[m][i], "from_alert1": onset - first[1],
                         "from_alert2": onset - first[2], "maneuver_before": bool(man.size and tt[man[0]] <= onset),
                         "maneuver_after_alert2": (float(tt[man[0]]) - first[2]) if man.size else math.nan,
                         "turning": bool(rate[k] != 0 and t_turn <= onset), "turn_to_onset": onset - t_turn,
                         "pi": float(pi[ids == e][0])})
        ok = [r for r in rows if r is not None]
        auths = [r["authority"] for r in ok]
        out[g] = {
            "n_lowc": int(lowc.sum()), "n_replayed": int(want.size), "replay_matches": _share([r is not None for r in rows]),
            "authority_at_onset": {a: _share([x == a for x in auths]) for a in ("pilot", "daa", "waiting")},
            "decision_at_onset": {v: _share([r["decision"] == v for r in ok])
                                  for v in sorted({r["decision"] for r in ok})},
            "from_alert1_s": _quartiles([r["from_alert1"] for r in ok]),
            "from_alert2_s": _quartiles([r["from_alert2"] for r in ok]),
            "maneuver_before_onset": _share([r["maneuver_before"] for r in ok]),
            "maneuver_after_alert2_s": _quartiles([r["maneuver_after_alert2"] for r in ok]),
            "turning_before_onset": _share([r["turning"] for r in ok]),
            "turn_to_onset_s": _quartiles([r["turn_to_onset"] for r in ok if r["turning"]]),
            "pi_gt_max": int(sum(r["pi"] > 3.79 for r in ok)),
            "pi_gt_max_turning": int(sum(r["pi"] > 3.79 and r["turning"] for r in ok)),
            "pi_gt_max_daa_at_onset": int(sum(r["pi"] > 3.79 and r["authority"] == "daa" for r in ok)),
        }
    return out


def blend_searches(d: Path, groups: Sequence[str]) -> dict:
    """Algorithm 2's outcomes from the decision tables of ``groups`` in campaign ``d``: blends of a
    maneuver and of a 'hold' by the rule that found the maneuver, and the requested (axis, direction)
    of the maneuver blends that did not keep it."""
    out = {}
    for g in groups:
        t = read_results(d, "decisions", [g])
        col = {c: np.asarray(t.column(c).to_pylist(), dtype=object) for c in ("decision", "rule", "pilot_axis",
                                                                              "pilot_dir", "exact_match")}
        blend = col["decision"] == "blend"
        intent = blend & (col["pilot_axis"] != "none")
        hold = blend & ~intent
        rules = sorted({r for r in col["rule"][blend]})
        failed = intent & ~col["exact_match"].astype(bool)
        asked = {}
        for a, dd in zip(col["pilot_axis"][failed], col["pilot_dir"][failed]):
            asked[f"{a}/{dd}"] = asked.get(f"{a}/{dd}", 0) + 1
        out[g] = {"blends": int(blend.sum()), "maneuver_blends": int(intent.sum()), "hold_blends": int(hold.sum()),
                  "maneuver_by_rule": {r: int((intent & (col["rule"] == r)).sum()) for r in rules},
                  "hold_by_rule": {r: int((hold & (col["rule"] == r)).sum()) for r in rules},
                  "failed_exact_asked": sorted(([k, v] for k, v in asked.items()), key=lambda kv: -kv[1])}
    return out


#: the agent's and the DAA's executions, as the decision table names them
NOT_PILOT = (("blend of a maneuver", "blend", True), ("blend of a 'hold'", "blend", False),
             ("DAA override", "daa_override", None), ("DAA allocation", "no_wait", None))


def executed_axes(d: Path, groups: Sequence[str]) -> dict:
    """What the vehicle flew when it did not fly the pilot's command as sent, from the decision tables of
    ``groups`` in campaign ``d``: per kind (:data:`NOT_PILOT`) ``{"n", "axes", "unsafe"}``, the executions,
    their count by the axis of the flown command (``none``: it keeps the current course, no maneuver)
    and how many of the flown commands SM(u) judges unsafe themselves (SM not positive)."""
    out = {}
    for g in groups:
        t = read_results(d, "decisions", [g])
        col = {c: np.asarray(t.column(c).to_pylist(), dtype=object) for c in ("decision", "pilot_axis", "exec_axis")}
        sm = np.asarray(t.column("sm_exec").to_pylist(), dtype=float) if "sm_exec" in t.column_names else None
        kinds = {}
        for name, decision, intent in NOT_PILOT:
            m = col["decision"] == decision
            if intent is not None:
                m &= (col["pilot_axis"] != "none") if intent else (col["pilot_axis"] == "none")
            if m.any():
                axes, n = np.unique(col["exec_axis"][m].astype(str), return_counts=True)
                kinds[name] = {"n": int(m.sum()), "axes": {str(a): int(k) for a, k in zip(axes, n)},
                               "unsafe": None if sm is None else int(np.count_nonzero(~(sm[m] > 0.0)))}
        out[g] = kinds
    return out


__all__ = ["replay", "lowc_diagnostics", "blend_searches", "executed_axes", "NOT_PILOT"]
