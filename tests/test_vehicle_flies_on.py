"""A vehicle that outlives its scenario, and traffic injected while it flies.

* a standalone ``daa-vehicle`` flies on past its scenario's last step (the ownship on its last command
  or its plan, the intruders straight on) until stopped; ``--exit-at-end`` ends it there (``daa-sil run``
  passes it). On main the vehicle exited at the scenario's end: a GCS never saw t > duration;
* ``daa-sil inject FILE`` places a scenario file's intruders around the ownship where it is now and sends
  them as ADSB_VEHICLE; the vehicle flies them (streamed back, in the step log, judged by the DAA). On
  main an ADSB_VEHICLE sent to the vehicle was ignored and ``daa-sil inject`` did not exist;
* at the core: traffic only from a writable link, physical, new; and the authority texts at most once per
  5 s, the last one naming the latest mode (on main a text went out at each of ~35 changes).
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

from core_helpers import PILOT, TAP, decoded, vehicle_protocol
from daa_sil.link.codec import MavCodec
from daa_sil.link.codec import mavlink as M
from daa_sil.sil.scenario import load_scenario, parse_scenario
from interop_helpers import ROOT, free_ports, recv_until, start, stop, wait_for_text
from vehicle.announce import MODE_TEXT_EVERY_S
from vehicle.traffic import MAX_INTRUDERS

SHORT = """\
name: short
seed: 3
duration_s: 20
thresholds: do365
ownship: {alt_m: 1000, gs_mps: 55, track_deg: 0}
intruders:
  - callsign: HEAD1
    cpa: {angle_deg: 180, hmd_m: 150, t_cpa_s: 18, gs_mps: 60}
link: {up: "const:1", down: "const:1"}
pilot: {mode: model, model: {response: deterministic}}
allocation: {group: ID-1}
"""
TRAFFIC = """\
name: traffic
seed: 1
duration_s: 120
ownship: {alt_m: 1000, gs_mps: 55, track_deg: 0}
intruders:
  - id: 2001
    callsign: CROSS1
    cpa: {angle_deg: 90, hmd_m: 300, t_cpa_s: 60, gs_mps: 50}
"""


def test_the_vehicle_flies_on_past_its_scenario_and_takes_injected_traffic(tmp_path):
    from pymavlink import mavutil

    (tmp_path / "short.yaml").write_text(SHORT)
    (tmp_path / "traffic.yaml").write_text(TRAFFIC)
    (port,) = free_ports(1)
    veh = start(["vehicle", tmp_path / "short.yaml", "--out", f"udpin:127.0.0.1:{port}", "--speed", "10",
                 "--steplog", tmp_path / "steps.parquet"], tmp_path / "vehicle.log")
    conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=255, source_component=190,
                                      dialect="common")
    try:
        wait_for_text(tmp_path / "vehicle.log", "READY", 120.0, veh)
        past = []
        for _ in range(200):  # say hello until the stream passes the scenario's end (t = 20 s)
            conn.mav.heartbeat_send(6, 8, 0, 0, 4)
            past = recv_until(conn, lambda m: m.get_type() == "GLOBAL_POSITION_INT" and m.time_boot_ms >= 30_000, 0.5)
            if past and past[-1].get_type() == "GLOBAL_POSITION_INT" and past[-1].time_boot_ms >= 30_000:
                break
        assert past and past[-1].time_boot_ms >= 30_000, (tmp_path / "vehicle.log").read_text()[-2000:]
        assert veh.poll() is None
        inj = subprocess.run([sys.executable, "-m", "daa_sil.cli", "inject", str(tmp_path / "traffic.yaml"),
                              "--vehicle", f"udpout:127.0.0.1:{port}"], capture_output=True, text=True, timeout=120,
                             cwd=ROOT)
        assert inj.returncode == 0 and "injected: traffic CROSS1 (2001) injected" in inj.stdout, inj.stdout + inj.stderr
        conn.mav.heartbeat_send(6, 8, 0, 0, 4)
        seen = recv_until(conn, lambda m: m.get_type() == "ADSB_VEHICLE" and m.ICAO_address == 2001, 20.0)
        assert seen and seen[-1].get_type() == "ADSB_VEHICLE" and seen[-1].callsign == "CROSS1"
        again = subprocess.run([sys.executable, "-m", "daa_sil.cli", "inject", str(tmp_path / "traffic.yaml"),
                                "--vehicle", f"udpout:127.0.0.1:{port}"], capture_output=True, text=True, timeout=120,
                               cwd=ROOT)
        assert again.returncode == 1 and "refused: traffic 2001: already flying" in again.stdout, again.stdout
    finally:
        code = stop(veh)
        conn.close()
    log = (tmp_path / "vehicle.log").read_text()
    assert code == 130 and "the scenario's last step: flying on until stopped" in log, log[-2000:]
    from daa_sil.steplog import read_steplog, steplog_metadata

    rows = read_steplog(tmp_path / "steps.parquet").to_pydict()
    n = len(rows["t"])
    assert n > 30 and rows["t"] == [float(k) for k in range(n)]  # every step past the scenario's 20 too
    for k in range(21, n - 1):  # still flying on: each step covers its ground speed
        d = math.hypot(rows["own_x"][k + 1] - rows["own_x"][k], rows["own_y"][k + 1] - rows["own_y"][k])
        assert abs(d - rows["own_gs"][k]) < 0.05 * rows["own_gs"][k] and rows["own_gs"][k] > 20.0, (k, d)
    m = [len(x) for x in rows["intr_x"]]
    first = m.index(2)
    assert first > 30 and set(m[:first]) == {1} and set(m[first:]) == {2}  # the injected intruder, from then on
    assert 3000 < rows["range_m"][first][1] < 6000  # CPA in 60 s at 50 + 55 m/s across: about 4.4 km away
    ev = json.loads(steplog_metadata(tmp_path / "steps.parquet")["settings"])
    traffic = [(e["name"], e["status"], e["link"]) for e in ev if e["kind"] == "traffic"]
    assert traffic == [("2001", "accepted", "gcs"), ("2001", "denied", "gcs")]


def test_exit_at_end_ends_the_run_with_the_scenario(tmp_path):
    (tmp_path / "short.yaml").write_text(SHORT)
    cp = subprocess.run([sys.executable, "-m", "vehicle", str(tmp_path / "short.yaml"), "--out",
                         f"udp:127.0.0.1:{free_ports(1)[0]}", "--speed", "50", "--exit-at-end", "--quiet",
                         "--steplog", str(tmp_path / "steps.parquet")], capture_output=True, text=True, timeout=300,
                        cwd=ROOT)
    assert cp.returncode == 0 and "done, 20 steps" in cp.stdout, cp.stdout + cp.stderr
    assert "flying on" not in cp.stderr


@pytest.fixture(scope="module")
def plant_factory():
    from vehicle.core import VehicleCore

    sc = parse_scenario(SHORT, "short.yaml")
    return lambda: VehicleCore(sc)


def adsb(icao: int, flags: int = 223, lat: float = 37.45, alt_mm: int = 1_000_000) -> "M.MAVLink_message":
    return M.MAVLink_adsb_vehicle_message(icao, int(lat * 1e7), int(-122.0 * 1e7), 1, alt_mm, 9000, 5000, 0, b"X",
                                          14, 0, flags, 0)


def test_traffic_is_taken_only_when_writable_physical_and_new(plant_factory):
    plant = plant_factory()
    p = vehicle_protocol(None, plant=plant)
    o = plant.sc.origin
    gcs = MavCodec(255, 190)
    p.begin_step(0)
    p.receive(0, gcs.encode_many([adsb(77, lat=o.lat_deg + 0.02), adsb(78, flags=1), adsb(1000),
                                  adsb(79, lat=o.lat_deg + 2.0), adsb(80, alt_mm=300_000_000)]), PILOT, 0.1)
    p.receive(0, gcs.encode(adsb(81, lat=o.lat_deg + 0.02)), TAP, 0.2)
    p.process()
    got = [(e.name, e.status, e.reason) for e in p.events]
    assert [(n, s) for n, s, _ in got] == [("77", "accepted"), ("78", "denied"), ("1000", "denied"), ("79", "denied"),
                                          ("80", "denied"), ("81", "denied_readonly")], got
    assert plant.icao == [1000, 77] and plant.core.m == 2
    texts = [m.text for m in decoded(p.take_sends()) if m.get_type() == "STATUSTEXT"]
    assert "traffic X (77) injected" in texts and "traffic 81: tap is read-only" in texts
    out = plant.step(0.0)
    assert out.intruders.shape == (1, 2)
    assert MAX_INTRUDERS >= 2


def test_the_authority_text_goes_out_at_most_every_5_s_and_names_the_latest_mode(plant_factory):
    """The head-on encounter with a GCS alive but sending nothing flips wait / no-wait every second from
    t = 58 s: every text at least 5 s after the one before, and the last one names the authority the
    vehicle ends with (on main one text per change: about 35)."""
    from core_helpers import fly

    from vehicle.core import VehicleCore

    sc = load_scenario(ROOT / "scenarios" / "head_on.yaml")
    p = vehicle_protocol(sc, clock="realtime", plant=VehicleCore(sc))
    gcs = MavCodec(255, 190)
    sent = fly(p, after_step=lambda pr, k, wall: pr.receive(0, gcs.encode(
        M.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3)), PILOT, wall))
    texts = [(k, m.text) for k, step in enumerate(sent) for m in decoded(step, PILOT)
             if m.get_type() == "STATUSTEXT" and "authority" in m.text]
    times = [k for k, _ in texts]
    assert len(texts) >= 3 and p.stats.authority_changes > 2 * len(texts), (len(texts), p.stats.authority_changes)
    assert all(b - a >= MODE_TEXT_EVERY_S for a, b in zip(times, times[1:])), times
    last = texts[-1][1]
    final = {"pilot": "GUIDED", "daa": "AVOID_ADSB", "waiting": "CRUISE"}[p.plant.last_authority]
    assert f"{final} authority" in last and last.split("->")[1].split()[0] == p.plant.last_authority, last
    assert all(len(t) <= 50 for _, t in texts)
