"""What a user sees around a SIL run (issue 20 §2, §9, §14, §15).

* ``daa-vehicle --steplog`` into a directory that cannot hold it: one line, exit 2, before the
  vehicle binds a socket (it used to fly the whole scenario and fail at the end);
* ``--serve-web`` with a port taken: one line naming the flag, exit 2, for ``viz steplog`` (it used
  to warn and exit 0 serving nothing) and for ``run`` (which now has the option the
  ``--spawn-viewer`` advice names);
* ``viz steplog --serve-web`` stopped by SIGTERM, or SIGKILLed: the ``rerun`` web viewer is gone
  and its ports are free within 5 s (SIGTERM used to leave it holding them);
* ``daa-sil demo --serve-web``: the summary's legend (the decisions it shows, the pilot's
  ``hold``, LoWC, NMAC) and the command that opens the recording; the web viewer serves the run;
  SIGTERM ends serving as Ctrl-C does;
* the GCS display: its ``alert`` is the vehicle's own alert level of the vehicle time it shows
  (``seen@``), i.e. the onboard alert delayed by the downlink -- checked line by line against
  the step log of the demo -- and, when the agent keeps control below the corrective alert, the
  line says why;
* the progress line (bounded rate, what it says) and a summary that does not claim an outcome it
  did not check.

Bounded: every wait has a deadline; processes are killed in ``finally`` blocks; ports are
OS-chosen.
"""

from __future__ import annotations

import math
import os
import re
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest

from daa_sil.steplog import read_steplog, write_steplog, STEP_SCHEMA

ROOT = Path(__file__).resolve().parents[1]
HEAD_ON = ROOT / "scenarios" / "head_on.yaml"
DAA_SIL = [sys.executable, "-m", "daa_sil.cli"]
WAIT_S = 300.0  # bound on each wait (a first run may build the wait maps)
GONE_S = 5.0  # the bound for a child to be gone after its parent


def _free_tcp_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _port_free(port: int) -> bool:
    with socket.socket() as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(("127.0.0.1", port))
            return True
        except OSError:
            return False


def _children_named(pid: int, comm: str) -> list[int]:
    out = []
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            kids = (task / "children").read_text().split()
        except OSError:
            continue
        for k in kids:
            try:
                if Path(f"/proc/{k}/comm").read_text().strip() == comm:
                    out.append(int(k))
            except OSError:
                continue
    return out


def _alive(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except (OSError, IndexError):
        return False


def _wait_until(pred, deadline_s: float, proc=None) -> bool:
    end = time.monotonic() + deadline_s
    while time.monotonic() < end:
        if pred():
            return True
        if proc is not None and proc.poll() is not None:
            return pred()
        time.sleep(0.05)
    return pred()


def _one_line_error(err: str) -> str:
    lines = [x for x in err.strip().splitlines() if x.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


# ------------------------------------------------------------------------------------------------
# §9: daa-vehicle --steplog is probed at start-up

@pytest.mark.parametrize("case", ["parent-is-a-file", "read-only-fs", "a-directory"])
def test_vehicle_steplog_that_cannot_be_written_fails_at_start_up(tmp_path, case):
    blocker = tmp_path / "a-file"
    blocker.write_text("x")
    target = {"parent-is-a-file": blocker / "run" / "steps.parquet",
              "read-only-fs": Path("/proc/daa-sil-test/steps.parquet"),  # not writable, even for root
              "a-directory": tmp_path}[case]
    # --speed 100: before the fix the vehicle flew the whole scenario (1.8 s of wall time) first
    cp = subprocess.run([sys.executable, "-m", "vehicle", str(HEAD_ON), "--steplog", str(target), "--speed", "100",
                         "--out", "udp:127.0.0.1:9", "--quiet"], capture_output=True, text=True, timeout=WAIT_S,
                        cwd=ROOT)
    assert cp.returncode == 2, cp.stdout + cp.stderr
    line = _one_line_error(cp.stderr)
    assert line.startswith(f"daa-vehicle: error: --steplog {target}"), line
    assert "READY" not in cp.stdout and "CLOCK" not in cp.stdout, "the vehicle started flying"


# ------------------------------------------------------------------------------------------------
# §14: --serve-web with a port taken

@pytest.fixture(scope="module")
def small_steplog(tmp_path_factory) -> Path:
    from viz_encounter import make_steplog

    path = tmp_path_factory.mktemp("steplog") / "steps.parquet"
    write_steplog(make_steplog(n_steps=60, encounter_id=0).cast(STEP_SCHEMA), path, metadata={"preset": "do365"})
    return path


@pytest.mark.parametrize("flag", ["--web-port", "--grpc-port"])
@pytest.mark.parametrize("command", ["viz", "run"])
def test_serve_web_with_a_port_taken_exits_2_with_one_line(tmp_path, small_steplog, command, flag):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        ports = {"--web-port": _free_tcp_port(), "--grpc-port": _free_tcp_port(), flag: port}
        port_args = [a for f, p in ports.items() for a in (f, str(p))]
        argv = (["viz", "steplog", str(small_steplog), "--serve-web"] if command == "viz"
                else ["run", str(HEAD_ON), "--out", str(tmp_path / "run"), "--serve-web"])
        cp = subprocess.run(DAA_SIL + argv + port_args, capture_output=True, text=True, timeout=WAIT_S, cwd=ROOT)
    assert cp.returncode == 2, cp.stdout + cp.stderr
    line = _one_line_error(cp.stderr)
    assert line.startswith(f"daa-sil: error: {flag} {port}: cannot serve the web viewer on 127.0.0.1:{port}"), line
    assert "web viewer:" not in cp.stdout
    if command == "run":
        assert not (tmp_path / "run").exists(), "the run started before the port was checked"


def test_spawn_viewer_without_a_display_advises_an_option_run_has(monkeypatch):
    """The warning of ``--spawn-viewer`` without a display advises ``--serve-web`` (or ``--rrd``):
    ``daa-sil run`` now accepts both (it rejected ``--serve-web``)."""
    from daa_sil.cli import build_parser
    from daa_sil.viz import Recording, SinkOptions, VizWarning

    for var in ("DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET"):
        monkeypatch.delenv(var, raising=False)
    monkeypatch.delenv("RERUN", raising=False)
    with pytest.warns(VizWarning) as got:
        Recording(SinkOptions(spawn=True)).close()
    advice = re.search(r"use (--[\w-]+) or (--[\w-]+) instead", " ".join(str(w.message) for w in got))
    assert advice, [str(w.message) for w in got]
    for flag in advice.groups():
        args = build_parser().parse_args(["run", str(HEAD_ON), flag] + (["x.rrd"] if flag == "--rrd" else []))
        assert getattr(args, flag[2:].replace("-", "_"))


# ------------------------------------------------------------------------------------------------
# §2 for viz: the rerun web viewer dies with `viz steplog --serve-web`

@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL], ids=["SIGTERM", "SIGKILL"])
def test_viz_serve_web_leaves_no_rerun_behind(small_steplog, sig):
    web, grpc = _free_tcp_port(), _free_tcp_port()
    proc = subprocess.Popen(DAA_SIL + ["viz", "steplog", str(small_steplog), "--serve-web", "--web-port", str(web),
                                       "--grpc-port", str(grpc)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, cwd=ROOT, start_new_session=True)
    rerun: list[int] = []
    try:
        line = proc.stdout.readline()  # blocks until the viewer serves (or the command ended)
        assert line.startswith("web viewer: http://127.0.0.1:"), line + proc.stderr.read()
        rerun = _children_named(proc.pid, "rerun") + _children_named(proc.pid, "rerun-watch")
        assert len(rerun) == 1 and not _port_free(web) and not _port_free(grpc)
        t_sig = time.monotonic()
        os.kill(proc.pid, sig)
        proc.wait(timeout=WAIT_S)
        gone = _wait_until(lambda: not _alive(rerun[0]) and _port_free(web) and _port_free(grpc), GONE_S)
        gone_s = time.monotonic() - t_sig
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        for p in rerun:
            if _alive(p):
                os.kill(p, signal.SIGKILL)
    assert gone, f"rerun {rerun} alive or ports {web}/{grpc} held {GONE_S} s after {signal.Signals(sig).name}"
    if sig == signal.SIGTERM:
        assert proc.returncode == 0  # as Ctrl-C: the documented way to stop serving
    print(f"\nviz steplog --serve-web, {signal.Signals(sig).name}: rerun gone and both ports free {gone_s:.2f} s later")


# ------------------------------------------------------------------------------------------------
# §15 + §14: the demo, its legend, the GCS display, `--serve-web` on a run

@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    """``daa-sil demo --serve-web`` played to the end, the web viewer fetched, then SIGTERM."""
    out = tmp_path_factory.mktemp("demo") / "out"
    web, grpc = _free_tcp_port(), _free_tcp_port()
    stdout = out.parent / "stdout.txt"
    with open(stdout, "w") as fh:
        proc = subprocess.Popen(DAA_SIL + ["demo", "--out", str(out), "--serve-web", "--web-port", str(web),
                                           "--grpc-port", str(grpc)], stdout=fh, stderr=subprocess.PIPE, text=True,
                                cwd=ROOT, start_new_session=True)
    rerun: list[int] = []
    try:
        assert _wait_until(lambda: "web viewer:" in stdout.read_text(), WAIT_S, proc), (
            stdout.read_text() + (proc.stderr.read() if proc.poll() is not None else ""))
        with urllib.request.urlopen(f"http://127.0.0.1:{web}/", timeout=30) as resp:
            status, body = resp.status, resp.read()
        rerun = _children_named(proc.pid, "rerun")
        os.kill(proc.pid, signal.SIGTERM)
        _, err = proc.communicate(timeout=WAIT_S)
        gone = _wait_until(lambda: not any(map(_alive, rerun)) and _port_free(web), GONE_S)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
        for p in rerun:
            if _alive(p):
                os.kill(p, signal.SIGKILL)
    return {"out": out, "stdout": stdout.read_text(), "stderr": err, "rc": proc.returncode, "http": (status, body),
            "rerun": rerun, "gone": gone, "web": web}


def test_demo_summary_has_a_legend_and_the_command_that_opens_the_recording(demo):
    text = demo["stdout"]
    assert demo["rc"] == 0, text + demo["stderr"]
    legend = text[text.index("  legend:"):]
    timeline = re.search(r"timeline: (.*)", text).group(1)
    shown = {d for d in re.findall(r"([a-z_]+) \d+(?:-\d+)?s", timeline)}
    assert shown >= {"wait", "blend"}
    for word in sorted(shown) + ["hold", "LoWC", "NMAC"]:
        assert re.search(rf"^    {word}\s+\S", legend, re.M), f"{word} missing from the legend:\n{legend}"
    assert "hold (" in text, "the pilot line uses 'hold'"
    # LoWC / NMAC figures are the scenario's preset (do365), not typed in twice
    assert "1219 m" in legend and "137 m" in legend and "152 m" in legend and "30 m" in legend
    cmd = re.search(r"open the recording: (daa-sil viz steplog (\S+) --serve-web)", legend)
    assert cmd and Path(cmd.group(2)) == demo["out"] / "steplog.parquet"


def test_demo_serve_web_serves_the_run_and_sigterm_stops_it(demo):
    status, body = demo["http"]
    assert status == 200 and b"Rerun" in body
    assert re.search(rf"web viewer: http://127\.0\.0\.1:{demo['web']}/\?url=", demo["stdout"])
    assert len(demo["rerun"]) == 1 and demo["gone"]


def test_gcs_display_alert_is_the_onboard_alert_as_delayed(demo):
    """Each display line's ``alert`` equals the vehicle's own alert level (step log) at the vehicle time
    the line shows (``seen@``: 4 s behind the GCS here, the downlink delay). In the demo the display
    showed ``alert 0`` at t = 42-49 s while the vehicle was blending: that is the vehicle's alert
    of t = 38-45 s (0: the agent keeps control until its blend is flown), and the line says so."""
    rows = {r["t"]: r for r in read_steplog(demo["out"] / "steplog.parquet").to_pylist()}
    lines = [x for x in (demo["out"] / "logs" / "gcs.log").read_text().splitlines() if x.startswith("t=")]
    assert len(lines) >= 170
    checked = explained = 0
    for line in lines:
        m = re.match(r"t=\s*(\d+)s\s+seen@\s*(\d+)s .*?  alert (\d)(@\d+s)? bands (\S+)\s+\S+ (\w+)/(\w+)", line)
        if m is None:
            assert "no telemetry yet" in line, line
            continue
        t, seen, alert = int(m.group(1)), float(m.group(2)), int(m.group(3))
        assert m.group(4) is None, f"the alert is of another vehicle time than the state shown: {line}"
        assert t - seen == 4, line  # head_on.yaml: const:4 down
        assert alert == max(rows[seen]["alert_level"]), (line, rows[seen]["alert_level"])
        assert m.group(5) == _highest_region(rows[seen]["bands_trk_region"]), line
        checked += 1
        if m.group(6) != "pilot" and alert < 2:
            assert "(alert < 2: manoeuvre in progress or pilot's course unsafe)" in line, line
            explained += 1
    assert checked >= 170
    print(f"\nGCS display: {checked} lines, alert = onboard alert at seen@ (t - 4 s) in all; {explained} lines "
          f"with the agent in control below alert 2, each explained")
    blending_quiet = [x for x in lines if re.match(r"t=\s*4[2-9]s", x)]
    assert all(" alert 0 " in x and "daa/blend" in x and "manoeuvre in progress" in x for x in blending_quiet[:8])
    assert explained >= 8


def _highest_region(regions: list) -> str:
    order = ["none", "far", "mid", "near"]
    return max((r for r in regions if r in order), key=order.index, default="none")


# ------------------------------------------------------------------------------------------------
# §15: the display line, the progress line, the summary (units)

def test_display_shows_the_onboard_alert_not_the_band_region():
    """A vehicle at alert 1 with no band painted (and authority daa): the line said ``alert 0`` (it
    showed the highest band region); now ``alert 1 bands none`` plus why the agent keeps control."""
    from daa_sil.link.codec import MavCodec
    from daa_sil.sil.intake import Intake
    from daa_sil.sil.scenario import load_scenario
    from gcs.display import format_line
    from gcs.pilot import make_pilot
    from gcs.protocol import READ_IDS, GcsOptions, GcsProtocol
    from vehicle import telemetry as T

    sc = load_scenario(HEAD_ON)
    vehicle, veh = ("127.0.0.1", 14601), MavCodec(1, 1)
    codec = MavCodec(255, 190, read_ids=READ_IDS)
    core = GcsProtocol(sc, GcsOptions(clock="lockstep", display=False), codec,
                       Intake(codec, peer=vehicle, allow_peers=[vehicle], allow_sysids=[1]),
                       make_pilot(sc, "scripted", None))
    own = T.Kin(0.0, 2000.0, 1000.0, 55.0, 0.0, 0.0)
    intr = T.Kin(150.0, 9000.0, 1000.0, 60.0, math.pi, 0.0)

    def step(t, level, region, authority, decision):
        msgs = [T.local_position(t, own), T.adsb_vehicle(1000, "HEAD1", intr, sc.origin), T.alert_level(t, level),
                *T.track_bands(t, [0.0], [360.0], [region]),
                T.allocation_decision(t, {"authority": authority, "decision": decision}, 0, math.nan)]
        core.receive(veh.encode_many(msgs), vehicle, 0.0)
        return format_line(core, t + 4.0, 0)

    quiet = step(57.0, 1, "none", "daa", "blend")
    assert re.search(r"  alert 1 bands none  \S+ daa/blend  \(alert < 2: manoeuvre in progress or pilot's "
                     r"course unsafe\)$", quiet), quiet
    loud = step(58.0, 2, "mid", "daa", "blend")
    assert re.search(r"  alert 2 bands mid  \S+ daa/blend$", loud), loud
    calm = step(59.0, 0, "none", "pilot", "none")
    assert re.search(r"  alert 0 bands none  \S+ pilot/none$", calm), calm


def test_progress_line_rate_and_text():
    from daa_sil.sil.summary import ProgressLine

    now = [100.0]
    said: list[str] = []
    p = ProgressLine(said.append, 180.0, every_s=5.0, clock=lambda: now[0])
    p.update("t=    0s authority=pilot decision=none range=17236m")  # at once: not yet 5 s
    assert said == []
    for k, line in enumerate(["t=   10s authority=pilot decision=none range=16091m",
                              "t=   20s authority=waiting decision=wait range=14941m",
                              "t=   30s authority=daa   decision=blend range=13791m"]):
        now[0] += 2.5  # a new vehicle line every 2.5 s of wall time (4x): only every second one is said
        p.update(line)
        p.update(line)  # the same line again: nothing new
    assert said == ["t = 20 s of 180 s: authority waiting, decision wait, nearest intruder 14941 m"]
    now[0] += 5.0
    p.update("t=   40s authority=daa   decision=blend range=n/a")
    assert said[-1] == "t = 40 s of 180 s: authority daa, decision blend"

    def closed_terminal(_):
        raise OSError(5, "Input/output error")

    q = ProgressLine(closed_terminal, 180.0, every_s=0.0, clock=lambda: now[0])
    q.update("t=   10s authority=pilot decision=none range=1m")  # says nothing more, raises nothing
    q.update("t=   20s authority=pilot decision=none range=1m")
    assert q.say is None


def test_summary_of_an_interrupted_run_does_not_claim_an_outcome():
    from daa_sil.sil.summary import human_summary

    res = {"decision_counts": {"wait": 3}, "n_active_steps": 3, "decision_sequence": [], "min_range_m": 9000.0,
           "min_range_t_s": 52.0, "vsep_at_min_range_m": 0.0, "lowc": False, "nmac": False,
           "expectation": {"checked": False, "ok": None, "violations": [],
                           "reason": "interrupted by SIGINT at t = 53 s of 180 s"}}
    text = human_summary(res)
    assert "expected outcome: not checked (interrupted by SIGINT at t = 53 s of 180 s)" in text
    assert "OK" not in text and "VIOLATED" not in text
