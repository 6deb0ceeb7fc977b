"""No silent failures (issue 16 §6): dropped peers, dead processes and scheduled faults are reported.

* :class:`daa_sil.sil.endpoint.DropReporter`: one warning per unexpected sender (naming it and the
  expected peer), then one line with counts per interval while drops go on (hand-worked clock);
* the ``daa-gcs --help`` example against a default vehicle: the GCS says at once which address it
  drops and which one it expects, instead of dropping every datagram silently;
* ``daa-sil run``: a shim killed mid-run (realtime and lockstep) or a killed vehicle stops the run
  long before the encounter's end, and the failure names the process that died -- in lockstep the
  dead shim is not blamed on the GCS;
* standalone nodes: a vehicle whose shim stops answering ticks, and a GCS whose ticks stop, say so
  naming the silent address;
* ``scenarios/faults/gcs_restart.yaml``: ``daa-sil run`` refuses it in lockstep with one line
  (nothing started) and, in realtime, really kills and restarts the GCS (a shortened copy here; the
  full file is the ``slow`` test in ``tests/test_link_faults.py``).

Bounded: every process gets a hang guard; ports are OS-chosen; processes are found by their
command lines (unique output directory) and killed by pid.
"""

from __future__ import annotations

import asyncio
import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from daa_sil.sil.endpoint import DropReporter, format_udp_address, open_endpoint
from daa_sil.link.codec import MavCodec, mavlink as d
from daa_sil.sil.scenario import load_scenario
from daa_sil.steplog import read_steplog
from vehicle.core import build_policy
from sil_helpers import child_pid, wait_for_vehicle_time

ROOT = Path(__file__).resolve().parents[1]
RUN = [sys.executable, "-m", "daa_sil.cli", "run"]
HEAD_ON = ROOT / "scenarios" / "head_on.yaml"
HANG_GUARD_S = 300


# ------------------------------------------------------------------------------------------------
# dropped peers

def test_drop_reporter_warns_once_per_sender_then_with_counts():
    now = [100.0]
    lines: list[str] = []
    rep = DropReporter("daa-gcs", lambda: "udp:127.0.0.1:14600 (--vehicle)", emit=lines.append, every_s=10.0,
                       clock=lambda: now[0], hint="point --vehicle at it")
    a, b = ("127.0.0.1", 40001), ("127.0.0.1", 40002)
    rep.note(a, "HEARTBEAT from system 1")
    assert lines == ["daa-gcs: warning: dropping datagrams from udp:127.0.0.1:40001 (HEARTBEAT from system 1): "
                     "not the expected peer udp:127.0.0.1:14600 (--vehicle); point --vehicle at it"]
    for _ in range(5):  # within the interval: counted, not said
        now[0] += 1.0
        rep.note(a)
    assert len(lines) == 1 and rep.total == 6
    rep.note(b)  # a new sender is named at once
    assert len(lines) == 2 and "udp:127.0.0.1:40002" in lines[1]
    now[0] = 110.5  # the interval is over: the next drop gives the counts since the last line
    rep.note(a)
    assert lines[2] == ("daa-gcs: warning: still dropping datagrams from unexpected peers: 1 in the last 10 s, "
                        "8 in all (udp:127.0.0.1:40001: 7, udp:127.0.0.1:40002: 1); expected udp:127.0.0.1:14600 "
                        "(--vehicle)")
    now[0] = 115.0
    rep.note(a)  # 4.5 s after the last line: quiet again
    assert len(lines) == 3
    assert rep.summary() == ("dropped 9 datagrams from unexpected peers (udp:127.0.0.1:40001: 8, "
                             "udp:127.0.0.1:40002: 1); expected udp:127.0.0.1:14600 (--vehicle)")


@pytest.mark.asyncio
async def test_endpoint_names_the_dropped_sender_and_the_expected_peer():
    lines: list[str] = []
    async with await open_endpoint(MavCodec(255, 190), learn_peer=False) as stranger, \
            await open_endpoint(MavCodec(1, 1)) as peer:
        async with await open_endpoint(MavCodec(255, 190), peer=peer.local_address, learn_peer=False,
                                       allow_peers=[peer.local_address], name="daa-gcs", peer_label="--vehicle",
                                       warn=lines.append) as gcs:
            hb = d.MAVLink_heartbeat_message(1, 3, 0, 0, 4, 3)
            for _ in range(3):
                stranger.send(hb, gcs.local_address)
            peer.send(hb, gcs.local_address)
            r = await gcs.recv(timeout=5)
            assert r.addr == peer.local_address
            for _ in range(100):
                if gcs.counters.datagrams_rejected_peer == 3:
                    break
                await asyncio.sleep(0.01)
    assert gcs.counters.datagrams_rejected_peer == 3 and len(lines) == 1
    assert lines[0] == (f"daa-gcs: warning: dropping datagrams from {format_udp_address(stranger.local_address)} "
                        f"(HEARTBEAT from system 255): not the expected peer "
                        f"{format_udp_address(peer.local_address)} (--vehicle)")


def _free_ports(n):
    from daa_sil.sil.supervise import free_udp_ports

    return free_udp_ports(n)


def test_gcs_pointed_at_the_wrong_vehicle_port_says_so():
    """The ``daa-gcs --help`` direct example: ``--vehicle udp:127.0.0.1:P`` while the vehicle sends from
    its OS-chosen port. The GCS never connects (correct: it accepts only --vehicle) but says why."""
    listen, wrong = _free_ports(2)
    gcs = subprocess.Popen([sys.executable, "-m", "gcs", "--listen", f"udp:127.0.0.1:{listen}", "--vehicle",
                            f"udp:127.0.0.1:{wrong}", "--scenario", str(HEAD_ON), "--no-display", "--duration", "4"],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    veh = subprocess.Popen([sys.executable, "-m", "vehicle", str(HEAD_ON), "--out", f"udp:127.0.0.1:{listen}",
                            "--speed", "10", "--quiet"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                           text=True, cwd=ROOT)
    try:
        out, err = gcs.communicate(timeout=HANG_GUARD_S)
    finally:
        veh.kill()
        veh.wait()
        if gcs.poll() is None:
            gcs.kill()
    assert gcs.returncode == 0, err
    warn = [x for x in err.splitlines() if "dropping datagrams from" in x]
    assert warn, err
    assert warn[0].startswith("daa-gcs: warning: dropping datagrams from udp:127.0.0.1:")
    assert f"not the expected peer udp:127.0.0.1:{wrong} (--vehicle)" in warn[0]
    assert f"udp:127.0.0.1:{listen}" not in warn[0].split(" (")[0]  # it names the sender, not our own socket
    stats = json.loads(out.split("daa-gcs: link stats ", 1)[1].splitlines()[0])
    assert stats["datagrams_rejected_peer"] > 0 and stats["received"] == 0
    assert f"dropped {stats['datagrams_rejected_peer']} datagrams from unexpected peers" in out


# ------------------------------------------------------------------------------------------------
# dead processes under daa-sil run

def _start_run(out: Path, *extra) -> subprocess.Popen:
    return subprocess.Popen(RUN + [str(HEAD_ON), "--out", str(out), "--json"] + list(extra),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)


def _kill_mid_run(out: Path, victim: str, extra: list, at_t: int = 10):
    proc = _start_run(out, *extra)
    try:
        wait_for_vehicle_time(out, at_t, proc, timeout=HANG_GUARD_S)
        os.kill(child_pid(out, victim), signal.SIGKILL)
        stdout, stderr = proc.communicate(timeout=HANG_GUARD_S)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return proc.returncode, stdout, stderr


@pytest.mark.parametrize("clock", [["--clock", "realtime", "--speed", "4"], ["--clock", "lockstep"]],
                         ids=["realtime", "lockstep"])
def test_a_dead_shim_stops_the_run_and_is_named(tmp_path, clock):
    out = tmp_path / "run"
    rc, stdout, stderr = _kill_mid_run(out, "shim", clock)
    assert rc == 1, stderr
    res = json.loads((out / "result.json").read_text())
    died = res["process_died"]
    assert died["process"] == "shim" and died["returncode"] == -signal.SIGKILL
    assert res["failure"].startswith(f"the shim (pid {died['pid']}) was killed by signal 9 (SIGKILL)")
    assert "gcs" not in res["failure"].split("(log:")[0].lower()  # not blamed on the GCS
    assert res["failure"] in stderr
    # found while the encounter was playing, not when the vehicle finished: the run was cut short
    assert res["steps"] < load_scenario(HEAD_ON).n_steps
    assert died["vehicle_t_s"] is not None and died["vehicle_t_s"] >= 10
    print(f"{clock[1]}: shim killed at vehicle t >= 10 s; run stopped at step {res['steps']} "
          f"(died at vehicle t = {died['vehicle_t_s']} s, {died['wall_s']} s into the run)")


def test_a_dead_vehicle_is_named(tmp_path):
    out = tmp_path / "run"
    rc, stdout, stderr = _kill_mid_run(out, "vehicle", ["--clock", "realtime", "--speed", "4"])
    assert rc == 1
    line = [x for x in stderr.splitlines() if x.startswith("daa-sil: error:")]
    assert line and line[-1].startswith("daa-sil: error: the vehicle (pid ") and "was killed by signal 9" in line[-1]


# ------------------------------------------------------------------------------------------------
# standalone nodes notice a silent partner

@pytest.mark.asyncio
async def test_standalone_vehicle_and_gcs_report_a_shim_that_stops(monkeypatch, capsys):
    """Vehicle, shim and GCS in one loop, realtime at 20x; the shim is closed at t = 6 s. The vehicle
    says the shim stopped echoing ticks (naming its address) and the GCS that ticks stopped."""
    from daa_sil.sil import silence
    from daa_sil.sil.shim import DelayShim
    from daa_sil.sil.shim_config import ShimConfig
    from daa_sil.sil.scenario import delay_models
    from gcs.node import GcsNode, GcsOptions
    from vehicle.node import VehicleNode, VehicleOptions

    monkeypatch.setitem(silence.SILENT_AFTER_S, "vehicle", 0.5)
    monkeypatch.setitem(silence.SILENT_AFTER_S, "gcs", 0.5)
    sc = load_scenario(HEAD_ON)
    up, down = delay_models(sc)
    shim = DelayShim(ShimConfig(delay_down=down, delay_up=up, listen_vehicle="udp:127.0.0.1:0",
                                listen_gcs="udp:127.0.0.1:0", seed=sc.seed, clock="realtime", speed=20.0))
    await shim.start()
    v_side, g_side = format_udp_address(shim.vehicle_side), format_udp_address(shim.gcs_side)
    g = GcsNode(sc, GcsOptions(vehicle=g_side, listen="udp:127.0.0.1:0",
                               clock="realtime", speed=20.0, display=False))
    await g.start()
    v = VehicleNode(sc, VehicleOptions(out=v_side, clock="realtime", speed=20.0,
                                       tick_sync="wait", tick_timeout_s=30.0))
    await v.start()
    await v.prepare()
    v.core.n_steps = 40  # 2 s of wall time at 20x

    def on_step(node, out):
        if node.k == 6:
            asyncio.get_running_loop().create_task(shim.close())

    gtask = asyncio.create_task(g.run())
    try:
        await asyncio.wait_for(v.run(on_step=on_step), HANG_GUARD_S)
        await asyncio.sleep(0.7)  # let the GCS notice too
    finally:
        g.stop.set()
        await asyncio.wait_for(gtask, 30)
        v.close()
        g.close()
        await shim.close()
    err = capsys.readouterr().err
    assert v.stats.silence_warnings == 1 and v.stats.sync_partner == "shim"
    assert f"daa-vehicle: warning: the shim at {v_side} has not echoed a tick " in err, err
    assert "the GCS behind the shim" not in err  # the silent shim is the news, not the GCS behind it
    assert v.stats.steps_unconfirmed >= 1 and v.stats.steps == 40  # it flew on
    assert g.ticks.silence_warnings == 1
    assert f"daa-gcs: warning: no SIM_TICK from {g_side} for" in err
    # before the shim went away every step was confirmed in time
    assert v.stats.tick_echoes >= 7


# ------------------------------------------------------------------------------------------------
# the GCS kill/restart fault

def test_gcs_restart_is_refused_in_lockstep_with_one_line(tmp_path):
    path = ROOT / "scenarios" / "faults" / "gcs_restart.yaml"
    cp = subprocess.run(RUN + [str(path), "--out", str(tmp_path / "o")], capture_output=True, text=True,
                        timeout=HANG_GUARD_S, cwd=ROOT)
    assert cp.returncode == 2
    assert cp.stderr.strip() == (
        f"daa-sil: error: {path}: faults (SIGKILL gcs at 20 s, restart at 40 s) need --clock realtime: in lockstep "
        f"the GCS is part of the clock (the vehicle waits for each tick's ack), so killing it would stop the "
        f"simulation, not just the link; run it with --clock realtime (e.g. --speed 10)")
    assert not (tmp_path / "o" / "logs").exists()  # nothing was started


def test_gcs_restart_really_kills_and_restarts_the_gcs(tmp_path):
    """A shortened copy of gcs_restart.yaml (60 s; kill at 15 s, restart at 30 s) at 5x."""
    d_ = yaml.safe_load((ROOT / "scenarios" / "faults" / "gcs_restart.yaml").read_text())
    d_.update(duration_s=60, faults=[{"kill": "gcs", "at_s": 15, "restart_s": 30}],
              expect={"nmac": False, "decisions_include": ["link_lost"]})
    d_["intruders"][0]["cpa"]["t_cpa_s"] = 55
    d_["pilot"]["commands"] = [{"t_s": 5, "until_s": 58, "track_deg": 0, "gs_mps": 55, "vs_mps": 0}]
    path = tmp_path / "gcs_restart_short.yaml"
    path.write_text(yaml.safe_dump(d_))
    sc = load_scenario(path)
    out = tmp_path / "run"
    cp = subprocess.run(RUN + [str(path), "--out", str(out), "--json", "--clock", "realtime", "--speed", "5"],
                        capture_output=True, text=True, timeout=HANG_GUARD_S, cwd=ROOT)
    assert cp.returncode == 0, cp.stderr[-3000:]
    res = json.loads(cp.stdout)
    (f,) = res["faults"]
    assert f["executed"] and f["problem"] is None and f["restart_name"] == "gcs2"
    assert 15 <= f["killed_at_t_s"] < 16 and 30 <= f["restarted_at_t_s"] < 31  # polled every 0.1 s = 0.5 sim s
    assert f["restart_ready_at_t_s"] is not None and f["restart_ready_at_t_s"] < 50
    # the SIGKILLed GCS never wrote its command log; the restarted one did, from sequence number 1
    assert res["files"]["gcs_logs"] == [str(out / "gcs_commands_gcs2.jsonl")]
    second = [json.loads(x) for x in (out / "gcs_commands_gcs2.jsonl").read_text().splitlines()]
    assert second and second[0]["seq"] == 1 and min(c["t"] for c in second) >= 30
    rows = read_steplog(out / "steplog.parquet").to_pylist()
    rx = [(r["t"], round(r["t"] - r["pilot_cmd_age_s"], 3)) for r in rows if r["pilot_cmd_received"]]
    before = [s for t, s in rx if s < 20]
    assert before and 14 <= max(before) <= 16  # the first GCS flew until it was killed at 15 s
    last_before = max(t for t, s in rx if s < 20)
    assert {s for t, s in rx if s >= 30} <= {c["t"] for c in second}  # all sent by the restarted GCS
    lost = [r["t"] for r in rows if r["decision"] == "link_lost"]
    timeout = build_policy(sc).link_timeout_s
    # the last datagram of the first GCS arrived at last_before; no data for more than 10 s -> link_lost
    assert lost and lost[0] == last_before + timeout + 1
    after = [(t, s) for t, s in rx if s >= 30]
    assert after and after[0][0] == after[0][1] + 4  # the restarted GCS's commands arrive after the 4 s delay
    assert max(lost) < after[0][0]
    assert res["expectation"]["ok"], res["expectation"]
    vlog = (out / "logs" / "vehicle.log").read_text()
    assert "the GCS behind the shim at" in vlog and "has not acknowledged a tick" in vlog
    print(f"gcs_restart (short): killed at t={f['killed_at_t_s']} s, restarted at t={f['restarted_at_t_s']} s "
          f"(ready at t={f['restart_ready_at_t_s']} s); last command before the kill received t={last_before:g} s, "
          f"link_lost from t={lost[0]:g} s to {max(lost):g} s; restarted GCS's first command received t={after[0][0]:g} s")


def test_exit_without_teardown_flushes_output_keeps_the_status_and_skips_atexit():
    """What ``python -m vehicle`` / ``gcs`` / the shim end with: buffered output (stdout is a pipe to
    ``daa-sil run``) reaches the reader, the status is the command's, the teardown is skipped."""
    code = ("import atexit, sys\nfrom daa_sil.sil.children import exit_without_teardown\n"
            "atexit.register(lambda: print('atexit ran'))\n"
            "sys.stdout.write('done, no newline')\nsys.stderr.write('a warning')\nexit_without_teardown(3)\n")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert (res.returncode, res.stdout, res.stderr) == (3, "done, no newline", "a warning")
