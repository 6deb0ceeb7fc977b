"""Measuring a ``daa-sil run`` from outside: per-process start-up, CPU per step, with and without .pyc.

Used by ``bench_sil.py --part lockstep`` to compare this checkout with a baseline checkout (e.g.
bba2fd8 installed apart) in the same run, the same way, with no help from the code measured:

* :func:`prepare_tree` copies a checkout's packages (``daa_sil``, ``vehicle``, ``gcs``) into a
  scratch directory without any ``__pycache__``, and with ``compiled=True`` runs ``compileall`` on
  the copy. A process started with ``PYTHONPATH=<copy>`` imports the copy before the installed
  (editable) one, so the same interpreter and dependencies run the code with or without .pyc.
* :data:`PROBE_SOURCE` is a ``sitecustomize`` module put on the children's ``PYTHONPATH`` (it is
  inherited by the vehicle, shim and GCS that ``daa-sil run`` starts). With ``DAA_SIL_PROBE_DIR``
  set it records, per process: its start (kernel start time), when it printed its ready line
  (``READY ...`` or the shim's ``... vehicle side ...``) and each vehicle progress line (``t= ...``,
  every 10 steps), each with the process's CPU time (user + system) at that moment, and its exit
  (at ``atexit``, or just before an ``os._exit``, which skips ``atexit``).
  Nothing here writes .pyc files but ``compileall`` on a copy; the runs only read them.

All times are ``CLOCK_BOOTTIME`` seconds, the clock of ``/proc/<pid>/stat``'s start time.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

PACKAGES = ("daa_sil", "vehicle", "gcs")

PROBE_SOURCE = r'''
import atexit, json, os, sys, time

_DIR = os.environ.get("DAA_SIL_PROBE_DIR")


def _now():
    t = os.times()
    return [time.clock_gettime(time.CLOCK_BOOTTIME), t.user + t.system]


if _DIR:
    with open("/proc/self/stat") as _f:
        _start = int(_f.read().rsplit(")", 1)[1].split()[19]) / os.sysconf("SC_CLK_TCK")
    _rec = {"pid": os.getpid(), "start": _start, "hook": _now(), "marks": []}

    class _Tap:
        def __init__(self, stream):
            self._s = stream

        def write(self, text):
            for line in str(text).splitlines():
                if line.startswith("READY") or " vehicle side udp:" in line:
                    _rec["marks"].append(["ready", None] + _now())
                elif line.startswith("t=") and line[2:].split("s", 1)[0].strip().replace(".", "", 1).isdigit():
                    _rec["marks"].append(["t", float(line[2:].split("s", 1)[0])] + _now())
            return self._s.write(text)

        def __getattr__(self, name):
            return getattr(self._s, name)

    sys.stdout, sys.stderr = _Tap(sys.stdout), _Tap(sys.stderr)

    @atexit.register
    def _write():
        _rec["exit"] = _now()
        _rec["argv"] = list(sys.argv)
        mod = sys.modules.get("daa_sil")
        _rec["daa_sil"] = getattr(mod, "__file__", None)
        with open(os.path.join(_DIR, f"{os.getpid()}.json"), "w") as f:
            json.dump(_rec, f)

    _os_exit = os._exit

    def _exit_recorded(code):  # a process that ends without the interpreter's teardown skips atexit
        if "exit" not in _rec:
            _write()
        _os_exit(code)

    os._exit = _exit_recorded
'''


def prepare_tree(checkout: Path, dest: Path, python: str, compiled: bool) -> Path:
    """Copy ``checkout``'s packages into ``dest`` (no ``__pycache__``); compile them if ``compiled``."""
    dest.mkdir(parents=True, exist_ok=True)
    for pkg in PACKAGES:
        shutil.copytree(checkout / pkg, dest / pkg, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    if compiled:
        subprocess.run([python, "-m", "compileall", "-q", *[str(dest / p) for p in PACKAGES]], check=True,
                       stdout=subprocess.DEVNULL)
    return dest


def write_probe(directory: Path) -> Path:
    """The ``sitecustomize`` probe in ``directory`` (put it on ``PYTHONPATH``)."""
    directory.mkdir(parents=True, exist_ok=True)
    (directory / "sitecustomize.py").write_text(PROBE_SOURCE)
    return directory


def run_probed(python: str, tree: Path, probe: Path, scenario: Path, out: Path, cache: "str | None") -> dict:
    """``python -m daa_sil.cli run scenario --out out --json`` with the tree and the probe on the path.

    Returns ``{"wall": s, "rc": int, "procs": {role: record}}`` (see :func:`roles`)."""
    pdir = out.parent / f"{out.name}.probe"
    pdir.mkdir(parents=True, exist_ok=True)
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "DAA_SIL_PROBE_DIR")}
    env.update(PYTHONPATH=f"{tree}{os.pathsep}{probe}", DAA_SIL_PROBE_DIR=str(pdir))
    if cache:
        env["DAA_SIL_CACHE"] = cache
    t0 = time.clock_gettime(time.CLOCK_BOOTTIME)
    # cwd: not a checkout (``-m`` puts the working directory first on sys.path)
    p = subprocess.run([python, "-m", "daa_sil.cli", "run", str(scenario), "--out", str(out), "--json"], env=env,
                       stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, cwd=probe)
    wall = time.clock_gettime(time.CLOCK_BOOTTIME) - t0
    recs = [json.loads(f.read_text()) for f in pdir.glob("*.json")]
    return {"wall": wall, "rc": p.returncode, "stderr": p.stderr[-400:], "procs": roles(recs), "t0": t0}


def roles(recs: list) -> dict:
    """Name each process record: driver, vehicle, gcs, shim."""
    out = {}
    for r in recs:
        argv = r.get("argv") or []
        head = argv[0] if argv else ""
        if head.endswith(os.path.join("vehicle", "__main__.py")):
            out["vehicle"] = r
        elif head.endswith(os.path.join("gcs", "__main__.py")):
            out["gcs"] = r
        elif "shim" in head or (len(argv) > 1 and argv[1] == "shim"):
            out["shim"] = r
        elif len(argv) > 1 and argv[1] == "run":
            out["driver"] = r
    return out


def figures(run: dict, n_steps: int) -> dict:
    """Start-up and per-step figures of one probed run (s and ms; None where a mark is missing).

    * ``ready_<p>``: wall s from the driver's start to process ``p``'s ready line; ``ready_cpu_<p>``:
      its CPU s by then.
    * ``step_ms_vehicle``: CPU ms per step between its progress lines at t = 0 and the last one
      (the steps themselves, without start-up and the step log written at the end);
      ``step_ms_gcs`` / ``step_ms_shim``: CPU ms per step from ready to exit (their shut-down is
      small: a JSONL log, a stats JSON), over the ``n_steps`` of the scenario.
    * ``play_wall``: wall s from the vehicle's t = 0 line to its last progress line, per step (ms).
    """
    P = run["procs"]
    drv = P.get("driver")
    t0 = drv["start"] if drv else run["t0"]
    f = {"wall": run["wall"], "driver_cpu": drv["exit"][1] if drv and "exit" in drv else None}
    v = P.get("vehicle") or {}
    tm = [m for m in v.get("marks", []) if m[0] == "t"]
    steps = int(round(tm[-1][1] - tm[0][1])) if len(tm) >= 2 else None
    for name in ("vehicle", "gcs", "shim"):
        r = P.get(name)
        ready = next((m for m in (r or {}).get("marks", []) if m[0] == "ready"), None)
        f[f"ready_{name}"] = ready[2] - t0 if ready else None
        f[f"ready_cpu_{name}"] = ready[3] if ready else None
        f[f"start_{name}"] = r["start"] - t0 if r else None
        if name == "vehicle":
            f["step_ms_vehicle"] = 1e3 * (tm[-1][3] - tm[0][3]) / steps if steps else None
            f["play_ms_per_step"] = 1e3 * (tm[-1][2] - tm[0][2]) / steps if steps else None
        elif r and ready and "exit" in r and n_steps:
            f[f"step_ms_{name}"] = 1e3 * (r["exit"][1] - ready[3]) / n_steps
        else:
            f[f"step_ms_{name}"] = None
    f["modules"] = {k: r.get("daa_sil") for k, r in P.items()}
    return f


def median(xs: list) -> "float | None":
    xs = sorted(x for x in xs if x is not None)
    if not xs:
        return None
    m = len(xs) // 2
    return xs[m] if len(xs) % 2 else 0.5 * (xs[m - 1] + xs[m])


def in_process(python: str, tree: Path, probe: Path, scenario: Path, cache: "str | None") -> dict:
    """The vehicle's core alone in one process: build ``VehicleCore`` (loading the DAA kernels and running the
    garbage collector as ``python -m vehicle`` does) and fly every step (no link), then the same steps again with each step's telemetry built and encoded (as the old bench did)."""
    code = r'''
import json, sys, time
try:  # the garbage collector as python -m vehicle runs it (relaxed until READY), in a checkout that has that
    from daa_sil.runtime.process_gc import freeze_after_startup, relax_for_startup
except ImportError:
    freeze_after_startup = relax_for_startup = lambda: None
relax_for_startup()
from pathlib import Path
from daa_sil.sil.scenario import load_scenario
from vehicle.core import VehicleCore
from vehicle import telemetry as T
from daa_sil.link.codec import MavCodec
path = Path(sys.argv[1])
t0 = time.perf_counter(); c0 = time.process_time()
try:  # load the kernels as the vehicle process (python -m vehicle) does, in a checkout that has that
    from daa_sil.daa.kernels import skip_blas_probe
    skip_blas_probe()
except ImportError:
    pass
vc = VehicleCore(load_scenario(path))
freeze_after_startup()  # where the vehicle prints READY
t1 = time.perf_counter(); c1 = time.process_time()
for k in range(vc.n_steps):
    vc.step(float(k))
t2 = time.perf_counter(); c2 = time.process_time()
codec = MavCodec(1, 1)
vc = VehicleCore(load_scenario(path))
tel = 0.0; home = None
for k in range(vc.n_steps):
    out = vc.step(float(k))
    a = time.process_time()
    home = home or T.kin_of(out.own, 0)
    codec.encode_many([m for ms in T.step_messages(vc, float(k), out, home).values() for m in ms])
    tel += time.process_time() - a
print(json.dumps({"wall": t2 - t0, "build_wall": t1 - t0, "build_cpu": c1 - c0, "steps": vc.n_steps,
                  "step_ms": 1e3 * (c2 - c1) / vc.n_steps, "telemetry_ms": 1e3 * tel / vc.n_steps}))
'''
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "DAA_SIL_PROBE_DIR")}
    env["PYTHONPATH"] = str(tree)
    if cache:
        env["DAA_SIL_CACHE"] = cache
    p = subprocess.run([python, "-c", code, str(scenario)], env=env, capture_output=True, text=True, cwd=probe)
    if p.returncode:
        raise RuntimeError(f"in-process run failed: {p.stderr[-400:]}")
    return json.loads(p.stdout.strip().splitlines()[-1])


def load() -> float:
    return os.getloadavg()[0]


__all__ = ["PACKAGES", "PROBE_SOURCE", "figures", "in_process", "load", "median", "prepare_tree", "run_probed",
           "write_probe"]

if __name__ == "__main__":  # pragma: no cover
    sys.exit("sil_probe is a helper of bench_sil.py")
