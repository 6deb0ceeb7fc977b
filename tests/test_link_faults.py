"""Link faults through the real link (issue 9 §3): the scenario set in ``scenarios/faults/``.

Each scenario is played by three real processes (vehicle, delay shim, GCS). For every run:

* the vehicle keeps flying: a complete step log (one row per step), exit status 0;
* each pilot command is applied at most once and never an older one after a newer one: the send
  times of the commands the agent received (``t - pilot_cmd_age_s`` on steps with
  ``pilot_cmd_received``) strictly increase and are all send times the GCS logged;
* link loss: on every active step the decision is ``link_lost`` exactly when no GCS packet arrived
  for more than ``allocation.link_timeout_s`` (computed from the scenario's link for deterministic
  links; loss/dup/reorder links must never lose the link: no gap reaches the timeout);
* recovery: pilot commands sent after an outage / a GCS restart are received again;
* no NMAC.

Lockstep (deterministic) for every case except the GCS kill/restart (the scenario's ``faults:``
block, carried out by ``daa-sil run``), which runs in realtime at 10x: in lockstep the GCS is part
of the clock (the vehicle waits for its SIM_TICK_ACK), so ``daa-sil run`` refuses it there.
The default run has the outage and the combined loss/dup/reorder cases; the others are ``slow``.
"""

from __future__ import annotations

import json
import math
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from daa_sil.models.delay_process import DelayProcess
from daa_sil.link.delayline import fifo_release
from daa_sil.sil.scenario import delay_models, load_scenario
from daa_sil.steplog import read_steplog
from vehicle.core import build_policy

ROOT = Path(__file__).resolve().parents[1]
FAULTS = ROOT / "scenarios" / "faults"
RUN = [sys.executable, "-m", "daa_sil.cli", "run"]
LIMIT_S = 300  # hang guard only (a hung process fails the test instead of blocking CI)
DEFAULT = ("outage_30s", "loss_dup_reorder")
SLOW = ("loss_20", "duplication", "reorder", "delay_spikes")


def _run(path: Path, out: Path) -> dict:
    cp = subprocess.run(RUN + [str(path), "--out", str(out), "--json"], capture_output=True, text=True,
                        timeout=LIMIT_S, cwd=ROOT)
    assert cp.returncode == 0, cp.stdout[-3000:] + cp.stderr[-3000:]
    return json.loads(cp.stdout)


def _gate_counts(vehicle_log: Path) -> dict:
    """The vehicle's final line: ``commands accepted A, dropped D (dup X, older Y, future F, invalid I)``."""
    text = vehicle_log.read_text()
    m = re.search(r"commands accepted (\d+), dropped (\d+) \(dup (\d+), older (\d+), future (\d+), invalid (\d+)\)",
                  text)
    assert m, text[-2000:]
    return dict(zip(("accepted", "dropped", "dup", "older", "future", "invalid"), map(int, m.groups())))


def _sent_times(gcs_logs: list) -> set:
    out = set()
    for p in gcs_logs:
        if Path(p).is_file():
            out |= {round(json.loads(x)["t"], 3) for x in Path(p).read_text().splitlines() if x.strip()}
    return out


def expected_link_lost(sc, t_steps: np.ndarray) -> np.ndarray:
    """Per step: True if no GCS datagram arrived for more than ``link_timeout_s`` (deterministic links).

    The GCS sends one datagram (HEARTBEAT + command) at every step ``t_k``; a datagram sent inside an
    outage is lost; the others are released FIFO at ``t_k + d_up(t_k)`` and taken in at the first
    step at or after that. Before the first arrival the link counts as alive (the agent's rule).
    """
    up, _ = delay_models(sc)
    proc = DelayProcess(up, 0, epoch_s=sc.link.epoch_s)
    t_send = np.asarray(t_steps, float)
    keep = np.array([not any(a <= t < b for a, b in sc.link.outage_windows()) for t in t_send])
    d = np.array([proc.delay(t) for t in t_send])
    arrive = np.ceil(fifo_release(t_send, d, keep) - 1e-9)
    arrive = arrive[np.isfinite(arrive)]
    lost = np.zeros(t_send.size, bool)
    for i, t in enumerate(t_send):
        past = arrive[arrive <= t + 1e-9]
        lost[i] = past.size > 0 and t - past.max() > build_policy(sc).link_timeout_s
    return lost


def check_common(sc, out: Path, gcs_logs: list) -> dict:
    """Checks every fault run must pass; returns the figures measured."""
    rows = read_steplog(out / "steplog.parquet").to_pylist()
    assert len(rows) == sc.n_steps, "the vehicle did not fly the whole encounter"
    assert [r["t"] for r in rows] == [float(k) for k in range(sc.n_steps)]
    assert not any(r["nmac"] for r in rows), "NMAC"
    # at most once, never older after newer: received send times strictly increase
    rx = [(r["t"], round(r["t"] - r["pilot_cmd_age_s"], 3)) for r in rows if r["pilot_cmd_received"]]
    sent_t = [s for _, s in rx]
    assert rx, "no pilot command ever reached the vehicle"
    assert all(b > a for a, b in zip(sent_t, sent_t[1:])), "a pilot command was applied twice or out of order"
    sent = _sent_times(gcs_logs)
    if sent:
        assert set(sent_t) <= sent, "the vehicle applied a command the GCS never sent"
    gate = _gate_counts(out / "logs" / "vehicle.log")
    assert gate["future"] == 0 and gate["invalid"] == 0
    stats = json.loads((out / "shim_stats.json").read_text()) if (out / "shim_stats.json").is_file() else {}
    dec = [r["decision"] for r in rows]
    return {"rows": rows, "rx": rx, "gate": gate, "shim": stats, "n_active": sum(d != "none" for d in dec),
            "link_lost_t": [r["t"] for r in rows if r["decision"] == "link_lost"],
            "lowc": any(r["lowc"] for r in rows),
            "min_range_m": min(min(r["range_m"]) for r in rows)}


def _figures(name: str, f: dict) -> str:
    sh = f["shim"]
    up, down = sh.get("up", {}), sh.get("down", {})
    keys = ("pushed", "dropped_loss", "dropped_outage", "duplicated", "reordered")
    return (f"{name}: active steps {f['n_active']}, link_lost steps {len(f['link_lost_t'])}"
            f"{' from t=%g s' % f['link_lost_t'][0] if f['link_lost_t'] else ''}, commands received by the agent "
            f"{len(f['rx'])}, gate {f['gate']}, LoWC {f['lowc']}, min range {f['min_range_m']:.0f} m; "
            f"shim up {({k: up.get(k) for k in keys})} down {({k: down.get(k) for k in keys})}")


def _check_link_lost_exact(sc, f: dict) -> None:
    rows = f["rows"]
    lost = expected_link_lost(sc, np.array([r["t"] for r in rows]))
    for r, exp in zip(rows, lost):
        if r["decision"] != "none":
            assert (r["decision"] == "link_lost") == bool(exp), (r["t"], r["decision"], exp)
            if exp:
                assert r["authority"] == "daa"


def test_outage_30s_hands_over_within_timeout_and_recovers(tmp_path):
    path = FAULTS / "outage_30s.yaml"
    sc = load_scenario(path)
    out = tmp_path / "run"
    res = _run(path, out)
    assert res["expectation"]["ok"], res["expectation"]
    f = check_common(sc, out, [out / "gcs_commands.jsonl"])
    _check_link_lost_exact(sc, f)
    (a, b), = sc.link.outage_windows()
    d = delay_models(sc)[0].mean()
    last_arrival = a - 1 + d  # last datagram sent before the outage
    assert f["link_lost_t"] and f["link_lost_t"][0] == last_arrival + build_policy(sc).link_timeout_s + 1
    # handed to the onboard DAA within the configured timeout of the last packet
    assert f["link_lost_t"][0] - last_arrival <= build_policy(sc).link_timeout_s + 1
    # recovery: the first command sent after the outage is received when it arrives, and link_lost ends
    after = [(t, s) for t, s in f["rx"] if s >= b]
    assert after and after[0] == (b + d, b)
    assert max(f["link_lost_t"]) < b + d
    assert f["shim"]["up"]["dropped_outage"] == b - a  # one GCS datagram per step was lost
    print(_figures("outage_30s", f))


def _check_random_link(name: str, tmp_path) -> dict:
    path = FAULTS / f"{name}.yaml"
    sc = load_scenario(path)
    out = tmp_path / name
    res = _run(path, out)
    assert res["expectation"]["ok"], res["expectation"]
    f = check_common(sc, out, [out / "gcs_commands.jsonl"])
    assert not f["link_lost_t"], "a loss/dup/reorder link must not trip the link timeout"
    link, up = sc.link, f["shim"]["up"]
    if link.loss:
        assert up["dropped_loss"] > 0.1 * up["pushed"]
        # lost commands are never received: fewer received than sent
        assert len(f["rx"]) < len(_sent_times([out / "gcs_commands.jsonl"]))
    if link.dup:
        assert up["duplicated"] > 0 and f["gate"]["dup"] > 0  # duplicates reached the gate and were dropped
    if link.reorder:
        assert up["reordered"] > 0 and f["gate"]["older"] > 0  # overtaken commands were dropped, not applied
    print(_figures(name, f))
    return f


def test_loss_dup_reorder_applies_each_command_once_in_order(tmp_path):
    _check_random_link("loss_dup_reorder", tmp_path)


@pytest.mark.slow
@pytest.mark.parametrize("name", SLOW)
def test_each_link_fault_alone(name, tmp_path):
    f = _check_random_link(name, tmp_path) if name != "delay_spikes" else None
    if name == "delay_spikes":
        path = FAULTS / "delay_spikes.yaml"
        sc = load_scenario(path)
        out = tmp_path / name
        res = _run(path, out)
        assert res["expectation"]["ok"], res["expectation"]
        f = check_common(sc, out, [out / "gcs_commands.jsonl"])
        _check_link_lost_exact(sc, f)
        # the spikes were really there: effective uplink delays up to 10 s
        assert f["shim"]["up"]["delay_sampled_mean_s"] > 4.0
        ages = [r["pilot_cmd_age_s"] for r in f["rows"] if r["pilot_cmd_received"]]
        assert max(ages) == pytest.approx(10.0) and min(ages) == pytest.approx(4.0)
        print(_figures(name, f))


# ------------------------------------------------------------------------------------------------
# GCS killed and restarted (realtime, 10x): the scenario's `faults:` block, carried out by daa-sil run

SPEED = 10.0


@pytest.mark.slow
def test_gcs_killed_and_restarted_mid_encounter(tmp_path):
    path = FAULTS / "gcs_restart.yaml"
    sc = load_scenario(path)
    (fault,) = sc.faults
    out = tmp_path / "run"
    cp = subprocess.run(RUN + [str(path), "--out", str(out), "--json", "--clock", "realtime", "--speed", f"{SPEED:g}"],
                        capture_output=True, text=True, timeout=LIMIT_S, cwd=ROOT)
    assert cp.returncode == 0, cp.stdout[-3000:] + cp.stderr[-3000:]
    res = json.loads(cp.stdout)
    assert res["expectation"]["ok"], res["expectation"]
    (rec,) = res["faults"]
    assert rec["executed"] and rec["problem"] is None
    assert fault.at_s <= rec["killed_at_t_s"] < fault.at_s + 2 and fault.restart_s <= rec["restarted_at_t_s"] < fault.restart_s + 2
    gcs2 = out / "gcs_commands_gcs2.jsonl"  # the killed GCS never wrote its log; the restarted one did
    f = check_common(sc, out, [])
    rows = f["rows"]
    sent2 = sorted(_sent_times([gcs2]))
    assert sent2, "the restarted GCS sent nothing"
    assert {s for _, s in f["rx"] if s >= sent2[0]} <= set(sent2), "applied a command the restarted GCS never sent"
    kill_t = fault.at_s
    before = [(t, s) for t, s in f["rx"] if s < kill_t + 5]
    after = [(t, s) for t, s in f["rx"] if s >= sent2[0]]
    assert before and after, "pilot commands before the kill and after the restart must both be received"
    last_rx = before[-1][0]  # the last command of the first GCS arrived here (HEARTBEAT in the same datagram)
    timeout = build_policy(sc).link_timeout_s
    # handed to the onboard DAA exactly when no GCS datagram arrived for more than the timeout
    lost = f["link_lost_t"]
    assert lost, "no link_lost while the GCS was dead"
    assert lost[0] == last_rx + timeout + 1
    # the link recovers: no link_lost once the restarted GCS's packets arrive
    assert max(lost) < after[0][0] + 1
    assert all(r["decision"] != "link_lost" for r in rows if r["t"] > after[0][0] + 1)
    st = json.loads((out / "shim_stats.json").read_text())
    print(f"gcs_restart: killed at vehicle t={rec['killed_at_t_s']} s (last command received t={last_rx:g} s), "
          f"link_lost from t={lost[0]:g} s, restarted at t={rec['restarted_at_t_s']} s (ready t="
          f"{rec['restart_ready_at_t_s']} s), its first command sent t={sent2[0]:g} s received t={after[0][0]:g} s; "
          f"gate {f['gate']}; shim counters {st['counters']}")
