"""Parameters set over the delayed GCS link change what the agent decides, from the step they arrive.

Population: the head-on scenario (ID-1 wait map, 4 s each way) in lockstep through three real
processes (shim, GCS, vehicle), with the GCS sending ``DAA_WT`` 40 at t = 20 s and ``DAA_ENABLE``
0 at t = 70 s. Oracle: the agent's wait rule (paper Eq. 11, ``wait iff w >= W_T and no ProjL``)
evaluated on the step log with the W_T in force at each step; probed where the two thresholds
disagree (4 <= w < 40), which must occur. Plus sans-IO unit tests of the parameter table.
"""

from __future__ import annotations

import json
import math
import struct

import pytest

from interop_helpers import ROOT, free_ports, start, stop, wait_for_text, corrective_reading
from vehicle.params import ParamTable, float32


def _policy():
    from daa_sil.config.groups import policy_for_group

    return policy_for_group("ID-1")


def test_param_table_accepts_and_refuses_by_the_protocol():
    pt = ParamTable("paper")
    pol = _policy()
    r = pt.set("DAA_WT", 6.0, pol)
    assert r.status == "accepted" and r.policy.wait_threshold_s == 6.0 and pol.wait_threshold_s == 4.0
    assert pt.set("DAA_WT", 6.0, r.policy).status == "unchanged"
    for bad in (120.5, -0.1, math.nan, math.inf):
        r2 = pt.set("DAA_WT", bad, pol)
        assert r2.status == "out_of_range" and r2.value == 4.0 and r2.policy is None
    assert pt.set("DAA_LINK_TO", 0.0, pol).status == "out_of_range"  # [1, 120]: 0 excluded
    assert pt.set("DAA_LINK_TO", 120.0, pol).policy.link_timeout_s == 120.0
    assert pt.set("DAA_ENABLE", 0.5, pol).status == "not_integer"
    assert pt.set("DAA_ENABLE", 0.0, pol).policy.enabled is False
    assert pt.set("DAA_PRESET", 0.0, pol).status == "read_only"
    assert pt.set("DAA_WAIT_MODE", 0.0, pol).status == "read_only"
    assert pt.set(b"DAA_WT\0\0\0\0", 7.0, pol).policy.wait_threshold_s == 7.0  # NUL-padded char[16]
    assert pt.set("daa_wt", 7.0, pol).status == "unknown"  # names are case sensitive
    r3 = pt.set("DAA_WT", 4.2, pol)
    assert r3.value == float32(4.2) != 4.2 and r3.policy.wait_threshold_s == float32(4.2)  # what travelled
    assert pt.value(pt.find("DAA_PRESET")[1], pol) == 1.0  # "paper" is preset 1
    assert pt.find(index=len(pt)) is None and pt.find("DAA_PROJL_S")[1].field == "projl_horizon_s"


def test_timeouts_have_a_practical_minimum_and_minus_zero_is_plain_zero():
    """Issue 20 §8: DAA_LINK_TO and DAA_STALE_S took 1.4e-45 s (the smallest float32); the GCS sends at most
    once per 1 s step, so anything under one step is refused. -0.0 is stored and reported as 0.0."""
    pt = ParamTable("paper")
    pol = _policy()
    tiny = struct.unpack("<f", struct.pack("<I", 1))[0]  # 1.4e-45, the value the issue sent
    for name in ("DAA_LINK_TO", "DAA_STALE_S"):
        for bad in (tiny, 0.5, 0.999, -0.0):
            r = pt.set(name, bad, pol)
            assert r.status == "out_of_range" and r.policy is None, (name, bad, r)
            assert "[1, 120]" in r.reason
        ok = pt.set(name, 1.0, pol)
        assert ok.status == "accepted" and ok.value == 1.0
    for name, field in (("DAA_WT", "wait_threshold_s"), ("DAA_PROJL_S", "projl_horizon_s")):
        r = pt.set(name, -0.0, pol)
        assert r.status == "accepted" and math.copysign(1.0, r.value) == 1.0
        assert math.copysign(1.0, getattr(r.policy, field)) == 1.0  # the policy holds +0.0 ...
        assert math.copysign(1.0, pt.value(r.spec, r.policy)) == 1.0  # ... and PARAM_VALUE reports it
        assert pt.set(name, -0.0, r.policy).status == "unchanged"
    # a policy that already holds -0.0 (e.g. from a scenario file) is reported as 0.0
    from dataclasses import replace

    assert math.copysign(1.0, pt.value(pt.find("DAA_WT")[1], replace(pol, wait_threshold_s=-0.0))) == 1.0
    r = pt.set("DAA_ENABLE", -0.0, pol)
    assert r.status == "accepted" and r.policy.enabled is False and math.copysign(1.0, r.value) == 1.0


def _lockstep_run(tmp, settings: list[str]) -> "tuple[dict, list]":
    from daa_sil.steplog import read_steplog, steplog_metadata

    sc = ROOT / "scenarios" / "head_on.yaml"
    pv, pg = free_ports(2)
    shim = start(["daa_sil.cli", "shim", "--listen-vehicle", f"udp:127.0.0.1:{pv}", "--listen-gcs", f"udp:127.0.0.1:{pg}",
                  "--delay", "const:4", "--clock", "lockstep", "--seed", "11"], tmp / "shim.log")
    procs = [shim]
    try:
        wait_for_text(tmp / "shim.log", "vehicle side", 30.0, shim)
        gcs = start(["gcs", *corrective_reading(tmp), "--listen", "udp:127.0.0.1:0", "--vehicle", f"udp:127.0.0.1:{pg}",
                     "--scenario", sc,
                     "--clock", "lockstep", "--no-display", "--log", tmp / "gcs.jsonl",
                     *[a for s in settings for a in ("--set", s)]], tmp / "gcs.log")
        procs.append(gcs)
        wait_for_text(tmp / "gcs.log", "READY", 30.0, gcs)
        veh = start(["vehicle", sc, *corrective_reading(tmp), "--out", f"udp:127.0.0.1:{pv}", "--clock", "lockstep",
                     "--exit-at-end", "--steplog", tmp / "steplog.parquet"], tmp / "vehicle.log")
        procs.append(veh)
        veh.wait(120)
        assert veh.returncode == 0, (tmp / "vehicle.log").read_text()[-3000:]
    finally:
        for p in reversed(procs):
            stop(p)
    rows = read_steplog(tmp / "steplog.parquet").to_pydict()
    return rows, json.loads(steplog_metadata(tmp / "steplog.parquet")["settings"])


def test_wt_set_over_the_delayed_link_changes_the_decisions_from_its_arrival(tmp_path):
    rows, events = _lockstep_run(tmp_path, ["20:DAA_WT=40", "70:DAA_ENABLE=0"])
    wt, en = events
    # sent at 20 s (the GCS stamped it), through the 4 s uplink: arrives and holds from t = 24 s
    assert (wt["name"], wt["status"], wt["old"], wt["new"], wt["t_sent"]) == ("DAA_WT", "accepted", 4.0, 40.0, 20.0)
    assert wt["t_received"] == wt["t_applied"] == 24.0 and wt["link"] == "gcs"
    assert (en["name"], en["status"], en["new"], en["t_sent"], en["t_applied"]) == ("DAA_ENABLE", "accepted", 0.0,
                                                                                   70.0, 74.0)
    n_probe = 0
    for t, d, w, projl in zip(rows["t"], rows["decision"], rows["wait_s"], rows["projl"]):
        if d not in ("wait", "no_wait"):
            continue
        w_t = 40.0 if t >= 24.0 else 4.0
        assert (d == "wait") == (w >= w_t and not projl), (t, d, w, projl, w_t)
        if t >= 24.0 and d == "no_wait" and 4.0 <= w < 40.0 and not projl:
            n_probe += 1  # the old W_T would have waited here
    assert n_probe >= 3, "no step where W_T 40 and 4 disagree: the probe is trivial"
    after = [(d, a) for t, d, a in zip(rows["t"], rows["decision"], rows["authority"]) if t >= 74.0]
    before = [d for t, d in zip(rows["t"], rows["decision"]) if 24.0 <= t < 74.0]
    assert set(after) == {("none", "pilot")} and len(after) == 180 - 74  # agent off: the pilot flies
    assert set(before) - {"none"}, "the agent decided nothing before it was switched off"
    sent = [json.loads(x) for x in (tmp_path / "gcs.jsonl").read_text().splitlines()]
    assert [(s["t"], s["name"], s["value"]) for s in sent if s["kind"] == "param"] == [(20.0, "DAA_WT", 40.0),
                                                                                       (70.0, "DAA_ENABLE", 0.0)]


@pytest.mark.parametrize("text,err", [("x", "T:NAME=VALUE"), ("-1:DAA_WT=6", "sim time"), ("5:DAA_WT=abc", "number"),
                                      ("5:MODE=NOPE", "unknown mode")])
def test_gcs_set_option_errors_are_one_line(text, err):
    from daa_sil.errors import UsageError
    from gcs.cli import parse_setting

    with pytest.raises(UsageError) as ei:
        parse_setting(text)
    assert err in str(ei.value) and "\n" not in str(ei.value)
    assert parse_setting("90:MODE=guided") == (90.0, "MODE", 15.0)
