"""No data lost (issue 9 §5b): ``daa-sil run`` interrupted with Ctrl-C mid-encounter.

The orchestrator is started in its own session and sent SIGINT the way a terminal's Ctrl-C does
(to its process group; the vehicle, shim and GCS run in their own groups, so they are stopped by the
orchestrator, not by the terminal). Afterwards: exit 130, one ``interrupted`` line and no traceback,
the vehicle, shim and GCS processes are gone (checked by pid), the step log is a valid Parquet file
holding exactly the steps the vehicle flew (0..n-1, contiguous, the count the vehicle reported when
it stopped), ``result.json`` says ``interrupted`` and that the expectation was not checked (as the
console line does), the GCS command log holds only whole JSON lines, and no temporary file is left.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from daa_sil.files import is_temp_file
from daa_sil.steplog import read_steplog, steplog_metadata
from sil_helpers import wait_for_vehicle_time

ROOT = Path(__file__).resolve().parents[1]
HEAD_ON = ROOT / "scenarios" / "head_on.yaml"
WAIT_S = 90.0  # bound on each wait, so a hang fails instead of blocking CI


def _children(pid: int) -> list[int]:
    """Direct children of ``pid`` (from /proc/<pid>/task/*/children)."""
    out: list[int] = []
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            out += [int(x) for x in (task / "children").read_text().split()]
        except OSError:
            continue
    return out


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
    except OSError:
        return ""


def _alive(pid: int, marker: str) -> bool:
    """``pid`` still runs (not a zombie) and is ours (its command line mentions ``marker``)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state != "Z" and marker in _cmdline(pid)


def _role(cmd: str) -> str:
    if "-m daa_sil.commands.shim " in cmd or " shim " in cmd:  # daa-sil run's shim, or `daa-sil shim`
        return "shim"
    if "-m gcs" in cmd or "daa-gcs" in cmd:
        return "gcs"
    if "-m vehicle" in cmd or "daa-vehicle" in cmd:
        return "vehicle"
    return "other"


@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="needs Linux /proc")
def test_ctrl_c_mid_run_flushes_the_steplog_and_leaves_no_process(tmp_path):
    out = tmp_path / "run"
    # real time at 20x: the 180 s scenario would take ~9 s, so the interrupt lands mid-encounter
    proc = subprocess.Popen([sys.executable, "-m", "daa_sil.cli", "run", str(HEAD_ON), "--out", str(out),
                             "--clock", "realtime", "--speed", "20"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, cwd=ROOT, start_new_session=True)
    roles: dict[str, int] = {}
    try:
        wait_for_vehicle_time(out, 30, proc, WAIT_S)
        for pid in _children(proc.pid):
            roles[_role(_cmdline(pid))] = pid
        assert set(roles) >= {"vehicle", "shim", "gcs"}, roles
        assert all(_alive(p, str(out)) for p in roles.values())
        os.killpg(proc.pid, signal.SIGINT)  # Ctrl-C: the terminal signals the foreground group
        _, err = proc.communicate(timeout=WAIT_S)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
        for pid in roles.values():  # never leave anything behind, even if the test fails
            if _alive(pid, str(out)):
                os.killpg(pid, signal.SIGKILL)

    # exit status and message
    assert proc.returncode == 130, err
    assert "interrupted" in err and "Traceback" not in err, err
    # no orphans: each child pid is gone (not merely reparented)
    assert {r: _alive(p, str(out)) for r, p in roles.items()} == {"vehicle": False, "shim": False, "gcs": False}

    # the step log: valid, flushed, exactly the steps flown, marked incomplete
    table = read_steplog(out / "steplog.parquet")
    n = table.num_rows
    assert 30 <= n < 180
    assert table.column("step").to_pylist() == list(range(n))
    assert table.column("t").to_pylist() == [float(k) for k in range(n)]
    assert steplog_metadata(out / "steplog.parquet")["complete"] == "false"
    vlog = (out / "logs" / "vehicle.log").read_text()
    m = re.search(r"stopped by signal (\d+) at t = ([\d.]+) s; step log \((\d+) steps\)", vlog)
    assert m, vlog[-500:]
    assert int(m.group(1)) == signal.SIGINT and int(m.group(3)) == n

    # the result: marked interrupted and consistent with the step log
    res = json.loads((out / "result.json").read_text())
    assert res["interrupted"] is True and res["steps"] == n and res["clock"] == "realtime"
    # ... and claims no outcome (issue 20 §6: it said "checked": true, "ok": true), as the console says
    assert res["expectation"] == {"checked": False, "ok": None, "violations": [],
                                  "reason": f"interrupted by SIGINT at t = {n} s of 180 s"}
    assert res["interrupted_by"] == "SIGINT"
    assert f"interrupted by SIGINT at t = {n} s of 180 s; the expected outcome was not checked" in err, err

    # the GCS command log: whole JSON lines only
    lines = (out / "gcs_commands.jsonl").read_text().splitlines()
    assert all(isinstance(json.loads(x), dict) for x in lines if x.strip())
    for name in ("shim_stats.json",):
        if (out / name).exists():
            json.loads((out / name).read_text())

    # no temporary left anywhere
    assert [p for p in out.rglob("*") if is_temp_file(p)] == []
    print(f"\ninterrupt figures: steps logged {n} of 180, vehicle stopped at t = {m.group(2)} s, "
          f"children {sorted(roles)} gone, GCS command lines {len(lines)}")
