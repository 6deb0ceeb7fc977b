"""Summaries of a SIL run: LoWC/NMAC, separation, decision counts, what the pilot sent, the
realtime run's lockstep-equivalence report (a step-log table and the children's counters in, a
dict or text out), the legend of the words they use, and the progress line while it plays."""

from __future__ import annotations

import json
import re
import time
from pathlib import Path
from typing import Callable

#: ``daa-sil run`` prints the vehicle's progress at most once per this many wall seconds
PROGRESS_EVERY_S = 5.0


def summarize_steplog(table, scenario=None) -> dict:
    """LoWC, NMAC, minimum separation and the decision counts/sequence of one SIL run.

    ``decision_sequence`` lists every active step's decision as ``{t, decision, rule, authority}``
    (decision != ``none``), in step order. Distances in m, times in s.
    """
    import numpy as np  # lazy: start-up time

    from daa_sil.sil.scenario import DECISIONS, check_expectation  # lazy: start-up time

    n = table.num_rows
    col = {name: table.column(name).to_pylist() for name in
           ("t", "decision", "rule", "authority", "lowc", "nmac", "range_m", "dh_m", "wait_s")}
    counts = {d: 0 for d in DECISIONS}
    seq = []
    for i in range(n):
        d = col["decision"][i]
        counts[d] = counts.get(d, 0) + 1
        if d != "none":
            w = col["wait_s"][i]
            seq.append({"t": col["t"][i], "decision": d, "rule": col["rule"][i],
                        "authority": col["authority"][i],
                        "wait_s": None if w is None or not np.isfinite(w) else round(float(w), 3)})
    counts.pop("none", None)
    rng = np.array([min(r) if r else np.inf for r in col["range_m"]], dtype=float) if n else np.array([np.inf])
    k = int(np.argmin(rng)) if n else 0
    dh_at = None
    if n and col["dh_m"][k]:
        j = int(np.argmin(col["range_m"][k]))
        dh_at = float(col["dh_m"][k][j])
    lowc_t = [col["t"][i] for i in range(n) if col["lowc"][i]]
    link_lost_t = [e["t"] for e in seq if e["decision"] == "link_lost"]
    handed = [e["t"] for e in seq if e["authority"] == "daa"]
    result = {
        "steps": n,
        "duration_s": (col["t"][-1] + 1.0) if n else 0.0,
        "lowc": bool(any(col["lowc"])),
        "nmac": bool(any(col["nmac"])),
        "lowc_steps": len(lowc_t),
        "first_lowc_s": lowc_t[0] if lowc_t else None,
        "min_range_m": float(rng[k]) if n and np.isfinite(rng[k]) else None,
        "min_range_t_s": col["t"][k] if n else None,
        "vsep_at_min_range_m": abs(dh_at) if dh_at is not None else None,
        "n_active_steps": len(seq),
        "decision_counts": counts,
        "decision_sequence": seq,
        "first_link_lost_s": link_lost_t[0] if link_lost_t else None,
        "first_daa_authority_s": handed[0] if handed else None,
    }
    if scenario is not None:
        violations = check_expectation(scenario.expect, result)
        result["expectation"] = {"checked": True, "ok": not violations, "violations": violations}
    return result


def human_summary(result: dict, scenario=None, out_dir: "Path | None" = None) -> str:
    """A few lines for people: what happened, when control moved, separation, outcome."""
    lines = []
    if scenario is not None:
        lines.append(f"scenario {scenario.name}: {scenario.description.strip().splitlines()[0] if scenario.description.strip() else ''}".rstrip(": "))
    c = result["decision_counts"]
    active = ", ".join(f"{k} {v}" for k, v in c.items() if v) or "none"
    lines.append(f"  active steps: {result['n_active_steps']}  decisions: {active}")
    seq = result["decision_sequence"]
    if seq:
        runs = []
        for e in seq:
            if runs and runs[-1][0] == e["decision"] and e["t"] - runs[-1][2] <= 1.0 + 1e-9:
                runs[-1][2] = e["t"]
            else:
                runs.append([e["decision"], e["t"], e["t"]])
        parts = [f"{d} {a:.0f}s" if a == b else f"{d} {a:.0f}-{b:.0f}s" for d, a, b in runs[:12]]
        more = f" ... (+{len(runs) - 12} more)" if len(runs) > 12 else ""
        lines.append("  timeline: " + ", ".join(parts) + more)
    if result.get("first_daa_authority_s") is not None:
        lines.append(f"  onboard DAA first took control at t = {result['first_daa_authority_s']:.0f} s")
    mr = result["min_range_m"]
    vs = result["vsep_at_min_range_m"]
    lines.append(f"  min horizontal range {mr:.0f} m at t = {result['min_range_t_s']:.0f} s"
                 + (f" (vertical separation {vs:.0f} m)" if vs is not None else "") if mr is not None
                 else "  min horizontal range: n/a")
    lines.append(f"  LoWC: {'YES' if result['lowc'] else 'no'}   NMAC: {'YES' if result['nmac'] else 'no'}")
    exp = result.get("expectation")
    if exp and not exp.get("checked", True):
        lines.append(f"  expected outcome: not checked ({exp.get('reason', 'the run was cut short')})")
    elif exp:
        lines.append("  expected outcome: " + ("OK" if exp["ok"] else "VIOLATED: " + "; ".join(exp["violations"])))
    if out_dir is not None:
        saved = result.get("rescued") or {}  # saved elsewhere: the directory could not take them
        lines.append(f"  results: {saved.get('result') or out_dir / 'result.json'}  "
                     f"step log: {saved.get('steplog') or out_dir / 'steplog.parquet'}")
    return "\n".join(lines)


def realtime_report(steplog_meta: dict, shim_stats: "dict | None", gcs_skipped: "int | None") -> dict:
    """Whether a realtime run kept lockstep semantics, from the vehicle's and the shim's counters.

    ``lockstep_equivalent`` is true when every tick was answered by the shim before its step ran
    (``steps_unconfirmed`` 0), no GCS datagram missed the tick that lockstep releases it at
    (``released_late`` 0), the GCS never fell ``MAX_GCS_LAG_TICKS`` behind (``gcs_unresponsive``
    0) and it stepped on every tick (``gcs_ticks_skipped`` 0): then each step of the vehicle and of
    the GCS had the same input as in lockstep.
    """
    try:
        veh = json.loads(steplog_meta.get("vehicle") or "{}")
    except ValueError:
        veh = {}
    c = (shim_stats or {}).get("counters", {})
    rep = {"sync_partner": veh.get("sync_partner"), "steps_unconfirmed": veh.get("steps_unconfirmed"),
           "gcs_acks_late": veh.get("acks_late"), "late_mean_ms": veh.get("late_mean_ms"),
           "late_max_ms": veh.get("late_max_ms"), "late_p99_ms": veh.get("late_p99_ms"), "shim_release": (shim_stats or {}).get("release"),
           "released_late": c.get("released_late"), "gcs_lagged": c.get("gcs_lagged"),
           "gcs_unresponsive": c.get("gcs_unresponsive"), "gcs_ticks_skipped": gcs_skipped,
           "shim_release_lateness_ms": (shim_stats or {}).get("release_lateness_ms"),
           "tick_schedule": (shim_stats or {}).get("tick_schedule")}
    rep["lockstep_equivalent"] = bool(
        rep["sync_partner"] == "shim" and rep["shim_release"] == "ticks" and rep["steps_unconfirmed"] == 0
        and rep["released_late"] == 0 and rep["gcs_unresponsive"] == 0 and gcs_skipped == 0)
    return rep


_SKIPPED = re.compile(r"ticks skipped (\d+)")


def gcs_ticks_skipped(log_path: Path) -> "int | None":
    try:
        m = _SKIPPED.findall(log_path.read_text(errors="replace"))
    except OSError:
        return None
    return int(m[-1]) if m else None


def pilot_story(out_dir: Path) -> str:
    """One line on what the (model) pilot sent, from the GCS command log."""
    path = out_dir / "gcs_commands.jsonl"
    try:
        rows = [json.loads(x) for x in path.read_text().splitlines() if x.strip()]
    except (OSError, ValueError):
        return "  pilot: (no GCS command log)"
    if not rows:
        return "  pilot: sent no command"
    firsts, last = [], None
    for r in rows:
        key = (r.get("track_deg"), r.get("vs_mps"), r.get("gs_mps"))
        if key != last:
            firsts.append(r)
            last = key
    parts = []
    for r in firsts[:4]:
        what = ", ".join(f"{k} {r[k]:.0f}" for k in ("track_deg", "vs_mps", "gs_mps")
                         if isinstance(r.get(k), (int, float)))
        parts.append(f"t={r['t']:.0f}s {r.get('kind', 'cmd')} ({what})")
    return (f"  pilot: {len(rows)} command packets; " + "; ".join(parts)
            + (" ..." if len(firsts) > 4 else ""))


_VEHICLE_PROGRESS = re.compile(r"^t=\s*([0-9.]+)s\s+authority=(\S+)\s+decision=(\S+)(?:\s+range=(\S+))?")


class ProgressLine:
    """The run's progress for people: the vehicle's latest progress line (``t=  30s authority=waiting
    decision=wait range=4660m``, every 10 sim s) as ``t = 30 s of 180 s: authority waiting, decision
    wait, nearest intruder 4660 m``, at most once per ``every_s`` wall seconds (the first after
    ``every_s``: a lockstep run that ends sooner prints none). ``say`` gets each line; if it raises
    OSError (a closed terminal) the lines stop."""

    def __init__(self, say: Callable[[str], None], duration_s: float, every_s: float = PROGRESS_EVERY_S,
                 clock: Callable[[], float] = time.monotonic):
        self.say, self.duration_s, self.every_s, self.clock = say, float(duration_s), float(every_s), clock
        self.last_said = clock()
        self.last_line: "str | None" = None
        self.lines: list[str] = []

    def update(self, vehicle_line: "str | None") -> None:
        if not vehicle_line or vehicle_line == self.last_line or self.say is None:
            return
        now = self.clock()
        if now - self.last_said < self.every_s:
            return
        m = _VEHICLE_PROGRESS.match(vehicle_line)
        if m is None:
            return
        self.last_line, self.last_said = vehicle_line, now
        rng = m.group(4)
        text = (f"t = {float(m.group(1)):.0f} s of {self.duration_s:g} s: authority {m.group(2)}, decision "
                f"{m.group(3)}" + (f", nearest intruder {rng[:-1]} m" if rng and rng.endswith("m") else ""))
        self.lines.append(text)
        try:
            self.say(text)
        except OSError:
            self.say = None


#: what each allocation decision of the timeline means (one line each, for the demo's legend)
DECISION_MEANINGS = {
    "wait": "no new pilot command; the wait map says the delayed pilot is worth waiting for, so the "
            "pilot's last command is kept",
    "no_wait": "no new pilot command and waiting is unsafe (wait map below W_T, or a loss of well clear "
               "projected within the ProjL look-ahead): the onboard DAA resolves",
    "pilot": "a new pilot command that is safe: it is flown",
    "blend": "a new pilot command that is unsafe: the onboard DAA flies the safe manoeuvre closest to it",
    "daa_override": "a new pilot command that is unsafe: the onboard DAA resolution is flown instead",
    "daa": "the onboard DAA resolution is flown",
    "stale": "a pilot command that arrived too old to fly: decided as if none came",
    "link_lost": "nothing heard from the GCS for the link timeout: the onboard DAA resolves",
}


def demo_legend(result: dict, scenario, out_dir: Path) -> str:
    """The words of the summary (the timeline's decisions, the pilot's ``hold``, LoWC, NMAC) and the
    command that opens the run's recording."""
    from daa_sil.geometry.thresholds import get_thresholds  # lazy: start-up time

    th = get_thresholds(getattr(scenario, "thresholds", None))
    seen = [d for d in DECISION_MEANINGS if (result.get("decision_counts") or {}).get(d)]
    lines = ["  legend:"]
    lines += [f"    {d:<9s} {DECISION_MEANINGS[d]}" for d in seen]
    lines += [f"    {'hold':<9s} (pilot line) the pilot's 'keep flying as you are' command (the track, climb rate and "
              f"speed it sees), sent while it decides on a manoeuvre",
              f"    {'LoWC':<9s} loss of well clear: the intruder inside the {th.name} well-clear volume "
              f"(horizontal {th.dthr:.0f} m or modified tau {th.tthr:g} s, and vertical {th.zthr:.0f} m)",
              f"    {'NMAC':<9s} near mid-air collision: within {th.nmac_h:.0f} m horizontally and "
              f"{th.nmac_v:.0f} m vertically"]
    steplog = Path(out_dir) / "steplog.parquet"
    lines.append(f"  open the recording: daa-sil viz steplog {steplog} --serve-web   (a browser; with a display: "
                 f"--spawn-viewer)")
    return "\n".join(lines)
