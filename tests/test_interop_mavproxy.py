"""MAVProxy, headless on stdin, as the remote pilot's ground station behind the delay shim (slow).

Population: one realtime run (head-on scenario lengthened, 2x, 1 s delay each way through a real
``daa-sil shim``) with a stock MAVProxy (the ``interop`` extra) attached to the shim's GCS side as
``--master udpout:``. Typed commands and MAVProxy's own console output are the check: it must
detect the ArduPlane, show GUIDED and later the agent's CRUISE / AVOID_ADSB, list the ADS-B
intruder, download the parameters, ``param set DAA_WT 6`` (through the delayed link, logged in
the vehicle's step log) and get ACCEPTED / DENIED for ``mode GUIDED`` / ``mode RTL``.

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

from interop_helpers import ROOT, free_ports, start, stop, wait_for_text
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
        veh = start(["vehicle", long_scenario(tmp_path), "--out", f"udp:127.0.0.1:{pv}", "--speed", "2",
                     "--steplog", tmp_path / "steplog.parquet"], tmp_path / "vehicle.log")
        procs.append(veh)
        wait_for_text(tmp_path / "vehicle.log", "READY", 30.0, veh)
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
        # the adsb module counts the intruder; its per-vehicle lines then fail inside MAVProxy 1.8.75 itself
        # ("must be real number": the module never computes a distance without its map), so the intruder's
        # own message is read with `status` too
        cmd("adsb status", "total threat count: 1")
        out = cmd("status ADSB_VEHICLE", "ADSB_VEHICLE {")
        assert "callsign : HEAD1" in out and "ICAO_address : 1000" in out
        out = cmd("status GLOBAL_POSITION_INT", "GLOBAL_POSITION_INT {")
        cmd("param set DAA_WT 6", "AP: DAA_WT 4 -> 6")
        out = cmd("param show DAA_WT", "DAA_WT           6.0")
        cmd("mode GUIDED", "DO_SET_MODE: ACCEPTED")
        cmd("mode RTL", "DO_SET_MODE: DENIED")
        cmd("param set DAA_WT 500", "out of range")
        # later the agent takes authority: MAVProxy names the mode it shows
        out = wait_for_text(log, "Mode ", 60.0, mp)
        out = _wait_any(log, ("Mode CRUISE", "Mode AVOID_ADSB"), 60.0, mp)
        out = cmd("param show DAA_WT", "DAA_WT           6.0")
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
        "accepted", 4.0, 6.0, "gcs", [255, 230])  # MAVProxy's ids
    assert first["t_applied"] >= first["t_received"] >= 1.0  # came through the 1 s uplink
    assert {e["status"] for e in wt} <= {"accepted", "unchanged", "out_of_range"}  # MAVProxy retries its sets
    assert "out_of_range" in {e["status"] for e in wt}
    modes = [(e["name"], e["status"]) for e in ev if e["kind"] == "mode"]
    assert ("GUIDED", "accepted") in modes and ("RTL", "denied") in modes


def _wait_any(path: Path, texts, timeout: float, proc) -> str:
    import time

    end = time.monotonic() + timeout
    while time.monotonic() < end and proc.poll() is None:
        content = path.read_text()
        if any(t in content for t in texts):
            return content
        time.sleep(0.1)
    raise AssertionError(f"none of {texts} in {path.name} within {timeout} s:\n{path.read_text()[-3000:]}")
