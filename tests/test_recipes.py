"""The SIL run by hand, as a user would: ``daa-gcs`` with its default display, and the docs/sil.md
three-terminal recipe verbatim (only the port numbers replaced by OS-chosen ones).

Both are realtime and bounded: the processes run until the GCS has shown delayed telemetry and the
vehicle has flown 20 s without losing the link, then they are stopped with SIGINT (as Ctrl-C).
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
import time
from pathlib import Path

import pytest

from interop_helpers import ROOT, free_ports, recv_until, start, stop, wait_for_text

BIN = Path(sys.executable).parent


def recipe_commands(name: str) -> list[str]:
    """The command lines of the docs/sil.md code block after ``<!-- recipe: NAME -->``."""
    text = (ROOT / "docs" / "sil.md").read_text()
    m = re.search(rf"<!-- recipe: {re.escape(name)} -->\s*```bash\n(.*?)```", text, re.S)
    assert m, f"docs/sil.md has no recipe {name!r}"
    return [ln.strip() for ln in m.group(1).splitlines() if ln.strip() and not ln.lstrip().startswith("#")]


def _popen(argv: list, log: Path) -> subprocess.Popen:
    fh = open(log, "w")
    exe = BIN / argv[0]
    assert exe.exists(), f"console script {argv[0]} is not installed in {BIN}"
    return subprocess.Popen([str(exe), *argv[1:]], stdout=fh, stderr=subprocess.STDOUT, text=True, cwd=ROOT,
                            start_new_session=True)


def test_docs_three_terminal_recipe_runs_verbatim(tmp_path):
    os.environ["MAVLINK20"] = "1"
    from pymavlink import mavutil

    cmds = recipe_commands("three terminals")
    assert [c.split()[0] for c in cmds] == ["daa-sil", "daa-gcs", "daa-vehicle"]
    ports = sorted({int(p) for c in cmds for p in re.findall(r"127\.0\.0\.1:(\d+)", c)})
    assert len(ports) == 4  # shim x2, GCS, tap
    new = dict(zip(ports, free_ports(len(ports))))
    argvs = [shlex.split(re.sub(r"127\.0\.0\.1:(\d+)", lambda m: f"127.0.0.1:{new[int(m.group(1))]}", c)) for c in cmds]
    tap_port = new[int(re.search(r"--tap udp:127\.0\.0\.1:(\d+)", cmds[2]).group(1))]
    tap = mavutil.mavlink_connection(f"udpin:127.0.0.1:{tap_port}", source_system=250, dialect="common")
    logs = [tmp_path / f"{n}.log" for n in ("shim", "gcs", "vehicle")]
    procs = []
    try:
        for argv, log, ready in zip(argvs, logs, ("vehicle side udp:", "READY", "READY")):
            procs.append(_popen(argv, log))
            wait_for_text(log, ready, 30.0, procs[-1])
        # the GCS shows the pilot's delayed picture (4 s behind), the vehicle flies 20 s with the link up
        gcs_out = wait_for_text(logs[1], "seen@", 30.0, procs[1])
        veh_out = wait_for_text(logs[2], "t=   20s", 40.0, procs[2])
        # the newest heartbeat (the first ones buffered are from the start, when the agent waited for the
        # pilot's first command: CRUISE): by t = 20 s the pilot's commands fly, GUIDED
        beats = [m for m in recv_until(tap, lambda m: False, 2.5) if m.get_type() == "HEARTBEAT"]
        assert beats and beats[-1].custom_mode == 15 and tap.flightmode == "GUIDED"
        assert all(p.poll() is None for p in procs), [p.poll() for p in procs]
    finally:
        codes = [stop(p) for p in reversed(procs)]
        tap.close()
    gcs_out, veh_out = logs[1].read_text(), logs[2].read_text()
    assert "Traceback" not in gcs_out and "daa-gcs: error" not in gcs_out, gcs_out[-2000:]
    assert "link_lost" not in veh_out, veh_out
    lines = [ln for ln in gcs_out.splitlines() if "seen@" in ln]
    t_gcs, t_seen = map(int, re.search(r"t=\s*(\d+)s\s+seen@\s*(\d+)s", lines[-1]).groups())
    assert 3 <= t_gcs - t_seen <= 6  # the 4 s downlink delay, +- a step
    assert "GUIDED" in lines[-1] and "nearest" in lines[-1]
    assert codes[-1] == 0 and codes[0] in (0, 130)  # GCS exits 0 on Ctrl-C; vehicle 130


@pytest.mark.parametrize("tty", [False, True], ids=["pipe", "tty"])
def test_gcs_default_display_against_a_vehicle(tmp_path, tty):
    """``daa-gcs`` straight at a vehicle (no shim), display on: plain lines on a pipe, rich on a TTY."""
    gport, vport = free_ports(2)
    sc = ROOT / "scenarios" / "head_on.yaml"
    veh = start(["vehicle", sc, "--out", f"udp:127.0.0.1:{gport}", "--listen", f"udp:127.0.0.1:{vport}",
                 "--speed", "10"], tmp_path / "vehicle.log")
    gcs_argv = [str(BIN / "daa-gcs"), "--listen", f"udp:127.0.0.1:{gport}", "--vehicle", f"udp:127.0.0.1:{vport}",
                "--scenario", str(sc), "--speed", "10"]
    out_path = tmp_path / "gcs.log"
    try:
        if tty:
            import pty

            master, slave = pty.openpty()
            gcs = subprocess.Popen(gcs_argv, stdout=slave, stderr=slave, cwd=ROOT, start_new_session=True)
            os.close(slave)
            buf, end = b"", time.monotonic() + 60
            os.set_blocking(master, False)
            while time.monotonic() < end and b"t=   60s" not in buf and gcs.poll() is None:
                try:
                    buf += os.read(master, 65536)
                except BlockingIOError:
                    time.sleep(0.05)
                except OSError:
                    break
            out_path.write_bytes(buf)
        else:
            fh = open(out_path, "w")
            gcs = subprocess.Popen(gcs_argv, stdout=fh, stderr=subprocess.STDOUT, text=True, cwd=ROOT,
                                   start_new_session=True)
            wait_for_text(out_path, "t=   60s", 60.0, gcs)
        assert gcs.poll() is None, out_path.read_text(errors="replace")[-2000:]
        code = stop(gcs)
        if tty:
            os.close(master)
    finally:
        stop(veh)
    text = out_path.read_text(errors="replace")
    assert code == 130 and "Traceback" not in text, text[-2000:]  # Ctrl-C, as daa-vehicle (0 before)
    shown = [ln for ln in text.splitlines() if "seen@" in ln and "nearest" in ln]
    assert len(shown) >= 30, text[-2000:]
    if tty:
        assert "\x1b[" in text  # rich styled the lines
    else:
        assert "\x1b[" not in text
