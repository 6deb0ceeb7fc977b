"""Shared helpers for tests that drive a real ``daa-sil run`` (processes on loopback)."""

from __future__ import annotations

import re
import time
from pathlib import Path

import pytest


def wait_for_vehicle_time(out: Path, t_s: int, proc=None, timeout: float = 60.0) -> None:
    """Block until ``OUT/logs/vehicle.log`` reports sim time ``t_s`` (the vehicle prints ``t=  NNs``
    every 10 s); fail the test if it does not within ``timeout`` s of wall time or ``proc`` exits."""
    log = Path(out) / "logs" / "vehicle.log"
    pattern = re.compile(rf"^t=\s*{int(t_s)}s\b", re.M)
    end = time.monotonic() + timeout
    while time.monotonic() < end and (proc is None or proc.poll() is None):
        if log.exists() and pattern.search(log.read_text()):
            return
        time.sleep(0.05)
    pytest.fail(f"the vehicle never reached t = {t_s} s")


def child_pid(out: Path, name: str) -> int:
    """PID of the ``daa-sil run`` child ``name`` (``vehicle``, ``shim`` or ``gcs``) writing into ``out``.

    Found by its command line: the module it runs and the output file only that child is given."""
    import os

    marker = {"vehicle": ("-m vehicle", f"{out}/steplog.parquet"), "shim": ("-m daa_sil.commands.shim", f"{out}/shim_stats.json"),
              "gcs": ("-m gcs", f"{out}/gcs_commands.jsonl")}[name]
    found = []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit() or int(d.name) == os.getpid():
            continue
        try:
            cmd = (d / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        if all(m in cmd for m in marker):
            found.append(int(d.name))
    assert len(found) == 1, f"expected one {name} process for {out}, found {found}"
    return found[0]


def sil_fast_time(sc):
    """What the SIL flies for scenario ``sc`` under the default configuration (the study's default
    reading: its policy rules, wait maps and pilot), as fast-time arguments: ``(policy, wait_lookup
    or None, pilot config, DAA config)``."""
    from daa_sil import waitmap
    from daa_sil.config.run_config import load_config
    from daa_sil.agent.wait_function import make_wait_lookup
    from vehicle.core import build_policy

    cfg = load_config(None)
    pol = cfg.onboard_policy(build_policy(sc))
    daa = cfg.daa_config(sc.thresholds)
    lookup = None
    if pol.wait_mode == "map":
        fam = waitmap.family_for(cfg.map_source, preset="paper", horizon=cfg.map_horizon())
        lookup = make_wait_lookup(fam, daa, outside=cfg.effective_reading.outside)
    return pol, lookup, cfg.pilot_config(mode=sc.pilot.response), daa
