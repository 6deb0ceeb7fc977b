"""MAVProxy, headless on stdin, as the remote pilot's ground station behind the delay shim (slow).

Population: one realtime run (head-on scenario lengthened, 2x, 1 s delay each way through a real
``daa-sil shim``) with a stock MAVProxy (the ``interop`` extra) attached to the shim's GCS side as
``--master udpout:``. Typed commands and MAVProxy's own console output are the check: it must
detect the ArduPlane, show GUIDED, list the ADS-B intruder, download the parameters, ``param set
DAA_WT 60`` through the delayed link before the first decision and then show the agent using it
(AVOID_ADSB and "authority pilot->daa (no_wait)" where the default W_T would have waited in CRUISE),
``param set DAA_WT 6``, and get ACCEPTED / DENIED for ``mode GUIDED`` / ``mode RTL``; the vehicle's
step log holds every write.

No network but loopback: MAVProxy runs with its default modules minus ``terrain`` (the only one
that would fetch elevation tiles), HOME in the test's directory (no ~/.mavinit.scr), and
``--state-basedir`` there too.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from interop_helpers import corrective_reading, free_ports, start, stop, wait_for_text
from test_interop_mavutil import long_scenario

pytestmark = pytest.mark.slow
MODULES = ("log,signing,wp,rally,fence,ftp,param,relay,tuneopt,arm,mode,calibration,rc,auxopt,misc,cmdlong,"
           "battery,output,adsb,layout")  # MAVProxy's --default-modules without terrain


def _mavproxy() -> str:
    exe = shutil.which("mavproxy.py", path=str(Path(sys.executable).parent)) or shutil.which("mavproxy.py")
    if exe is None:
        if os.environ.get("DAA_SIL_REQUIRE_INTEROP"):
            pytest.fail("MAVProxy is not installed but DAA_SIL_REQUIRE_INTEROP is set (pip install -e '.[interop]')")
        pytest.skip("MAVProxy is in the interop extra: pip install -e '.[interop]'")
    return exe


def test_mavproxy_attaches_shows_the_picture_and_sets_wt(tmp_path):
    exe = _mavproxy()
    pv, pg = free_ports(2)
    procs = []
    log = tmp_path / "mavproxy.log"
    try:
        shim = start(["daa_sil.cli", "shim", "--listen-vehicle", f"udp:127.0.0.1:{pv}", "--listen-gcs",
                      f"udp:127.0.0.1:{pg}", "--delay", "const:1", "--clock", "realtime", "--speed", "2"],
                     tmp_path / "shim.log")
        procs.append(shim)
        wait_for_text(tmp_path / "shim.log", "vehicle side", 30.0, shim)
        veh = start(["vehicle", long_scenario(tmp_path), *corrective_reading(tmp_path), "--out", f"udp:127.0.0.1:{pv}",
                     "--speed", "2",
                     "--steplog", tmp_path / "steplog.parquet"], tmp_path / "vehicle.log")
        procs.append(veh)
        # CI runs this first on a fresh machine: the vehicle then builds and caches the default alerting
        # maps before it is READY (about a minute of CPU; the assertions below need those maps' values)
        wait_for_text(tmp_path / "vehicle.log", "READY", 300.0, veh)
        env = dict(os.environ, HOME=str(tmp_path))
        mp = subprocess.Popen([exe, f"--master=udpout:127.0.0.1:{pg}", f"--state-basedir={tmp_path}",
                               f"--default-modules={MODULES}"], stdin=subprocess.PIPE, stdout=open(log, "w"),
                              stderr=subprocess.STDOUT, text=True, cwd=tmp_path, env=env, start_new_session=True)
        procs.append(mp)

        def cmd(line: str, expect: str, timeout: float = 20.0) -> str:
            mp.stdin.write(line + "\n")
            mp.stdin.flush()
            return wait_for_text(log, expect, timeout, mp)

        wait_for_text(log, "Detected vehicle 1:1", 30.0, mp)
        wait_for_text(log, "Mode GUIDED", 20.0, mp)  # the pilot's authority, by ArduPlane's name
        wait_for_text(log, "Received 8 parameters", 30.0, mp)  # FTP refused with a NAK, then PARAM_REQUEST_LIST
        # W_T up to 60 s before the first decision (t = 28 s, where the map says wait 54 s): the agent must
        # then hand control to the onboard DAA instead of waiting, and MAVProxy shows it
        cmd("param set DAA_WT 60", "AP: DAA_WT 4 -> 60")
        # the adsb module counts the intruder; its per-vehicle lines then fail inside MAVProxy 1.8.75 itself
        # ("must be real number": the module never computes a distance without its map), so the intruder's
        # own message is read with `status` too
        cmd("adsb status", "total threat count: 1")
        out = cmd("status ADSB_VEHICLE", "ADSB_VEHICLE {")
        assert "callsign : HEAD1" in out and "ICAO_address : 1000" in out
        out = cmd("status GLOBAL_POSITION_INT", "GLOBAL_POSITION_INT {")
        cmd("mode GUIDED", "DO_SET_MODE: ACCEPTED")
        cmd("mode RTL", "DO_SET_MODE: DENIED")
        out = wait_for_text(log, "authority pilot->daa (no_wait)", 60.0, mp)
        assert "Mode AVOID_ADSB" in out and "Mode CRUISE" not in out and "(wait)" not in out
        cmd("param set DAA_WT 6", "AP: DAA_WT 60 -> 6")  # the example, after the fact
        out = cmd("param show DAA_WT", "DAA_WT           6.0")
        cmd("param set DAA_WT 500", "out of range")
    finally:
        for p in reversed(procs):
            stop(p)
    text = log.read_text()
    assert "Traceback" not in text and "fence breach" not in text, text[-3000:]
    from daa_sil.steplog import steplog_metadata

    ev = json.loads(steplog_metadata(tmp_path / "steplog.parquet")["settings"])
    wt = [e for e in ev if e["name"] == "DAA_WT"]
    first = wt[0]
    assert (first["status"], first["old"], first["new"], first["link"], first["source"]) == (
        "accepted", 4.0, 60.0, "gcs", [255, 230])  # MAVProxy's ids
    assert first["t_applied"] >= first["t_received"] >= 1.0  # came through the 1 s uplink
    assert [(e["old"], e["new"]) for e in wt if e["status"] == "accepted"] == [(4.0, 60.0), (60.0, 6.0)]
    assert {e["status"] for e in wt} <= {"accepted", "unchanged", "out_of_range"}  # MAVProxy retries its sets
    assert "out_of_range" in {e["status"] for e in wt}
    from daa_sil.steplog import read_steplog

    rows = read_steplog(tmp_path / "steplog.parquet").to_pydict()
    i = next(k for k, d in enumerate(rows["decision"]) if d != "none")
    assert rows["t"][i] > first["t_applied"] and rows["decision"][i] == "no_wait"
    assert 4.0 <= rows["wait_s"][i] < 60.0 and not rows["projl"][i]  # the default W_T would have waited
    modes = [(e["name"], e["status"]) for e in ev if e["kind"] == "mode"]
    assert ("GUIDED", "accepted") in modes and ("RTL", "denied") in modes



def _text_after(path: Path, start: int, text: str, timeout: float, proc=None) -> int:
    """Wait until ``text`` appears in ``path`` at or after character ``start``; returns where it ends."""
    import time

    end = time.monotonic() + timeout
    content = ""
    while time.monotonic() < end:
        content = path.read_text() if path.exists() else ""
        i = content.find(text, start)
        if i >= 0:
            return i + len(text)
        if proc is not None and proc.poll() is not None:
            break
        time.sleep(0.05)
    raise AssertionError(f"{text!r} not in {path.name} after {start} within {timeout} s; it holds:\n{content[-3000:]}")


def test_mavproxy_guided_is_accepted_while_the_agent_waits_and_while_daa_flies(tmp_path):
    """The pilot's flow in a stock MAVProxy attached straight to the vehicle over ``udpin:`` (as SITL):
    ``mode GUIDED`` and ``guided LAT LON ALT`` (DO_REPOSITION) while the agent waits (CRUISE) and while the
    DAA flies (AVOID_ADSB): both ACCEPTED, and the step log shows each command received and judged by
    SM(u). On main ``mode GUIDED`` was TEMPORARILY_REJECTED in both states."""
    from daa_sil.geometry.frames import enu_to_geodetic
    from daa_sil.sil.scenario import load_scenario
    from daa_sil.steplog import read_steplog, steplog_metadata
    from test_interop_mavutil import SCENARIO

    exe = _mavproxy()
    (port,) = free_ports(1)
    sc = load_scenario(SCENARIO)
    lat, lon, _ = enu_to_geodetic(0.0, 40000.0, 1000.0, sc.origin.lat_deg, sc.origin.lon_deg, sc.origin.alt_m)
    log = tmp_path / "mavproxy.log"
    procs = []
    try:
        veh = start(["vehicle", long_scenario(tmp_path), *corrective_reading(tmp_path), "--out",
                     f"udpin:127.0.0.1:{port}", "--speed", "2",
                     "--wait-gcs", "--steplog", tmp_path / "steplog.parquet"], tmp_path / "vehicle.log")
        procs.append(veh)
        wait_for_text(tmp_path / "vehicle.log", "READY", 300.0, veh)
        env = dict(os.environ, HOME=str(tmp_path))
        mp = subprocess.Popen([exe, f"--master=udpout:127.0.0.1:{port}", f"--state-basedir={tmp_path}",
                               f"--default-modules={MODULES}"], stdin=subprocess.PIPE, stdout=open(log, "w"),
                              stderr=subprocess.STDOUT, text=True, cwd=tmp_path, env=env, start_new_session=True)
        procs.append(mp)
        at = _text_after(log, 0, "Detected vehicle 1:1", 60.0, mp)
        for mode in ("CRUISE", "AVOID_ADSB"):
            at = _text_after(log, at, f"{mode} authority", 120.0, mp)
            for line, answer in (("mode GUIDED", "DO_SET_MODE: ACCEPTED"),
                                 (f"guided {float(lat):.7f} {float(lon):.7f} 1000", "DO_REPOSITION: ACCEPTED")):
                mp.stdin.write(line + "\n")
                mp.stdin.flush()
                at = _text_after(log, at, answer, 30.0, mp)
        _text_after(log, at, "AP: ", 60.0, mp)  # a few steps more (the next text), so the last one is logged
    finally:
        for p in reversed(procs):
            stop(p)
    text = log.read_text()
    assert "Traceback" not in text, text[-3000:]
    rows = read_steplog(tmp_path / "steplog.parquet").to_pydict()
    got = [i for i, r in enumerate(rows["pilot_cmd_received"]) if r]
    assert len(got) == 2, got
    for i, before in zip(got, ("waiting", "daa")):
        assert rows["authority"][i - 1] == before, (i, rows["authority"][i - 3:i + 1])
        assert rows["decision"][i] in ("pilot", "blend", "daa_override") and rows["sm_pilot"][i] == rows["sm_pilot"][i]
    ev = json.loads(steplog_metadata(tmp_path / "steplog.parquet")["settings"])
    assert [e["status"] for e in ev if e["kind"] == "mode"] == ["accepted", "accepted"]
