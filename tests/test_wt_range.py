"""W_T has one range everywhere (issue 20 item 8): [0, 120] s, ``daa_sil.config.settings.WAIT_THRESHOLD``.

On bba2fd8 the campaign side (``campaign run --wt``, groups, run configurations) accepted up to
600 s while the SIL (scenarios, the vehicle's DAA_WT) accepted up to 120 s. A W_T of 200 s is now
refused with one line and exit 2 by every input, through the installed console scripts, and
120 s is accepted by every input.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
LIMIT_S = 300.0


def _console(name: str) -> str:
    path = Path(sys.executable).parent / name
    assert path.is_file(), f"{path} is not installed (pip install -e .)"
    return str(path)


def _scenario(tmp_path: Path, wt: float) -> Path:
    d = yaml.safe_load((ROOT / "scenarios" / "head_on.yaml").read_text())
    d["allocation"]["wait_threshold_s"] = wt
    f = tmp_path / f"wt{wt:g}.yaml"
    f.write_text(yaml.safe_dump(d))
    return f


def test_wt_200_is_refused_by_every_input(tmp_path):
    daa_sil = _console("daa-sil")
    groups = tmp_path / "groups.yaml"
    groups.write_text("IC-9: {base: IC-1, wait_threshold_s: 200}\n")
    config = tmp_path / "config.yaml"
    config.write_text("base: paper\nallocation: {wt: 200}\n")
    small = ["--encounters", "2", "--duration", "30"]  # IC-1 needs no wait map: a mistaken run stays short
    cases = {
        "campaign run --wt 200": ([daa_sil, "campaign", "run", "--groups", "IC-1", "--wt", "200", *small], "--wt"),
        "campaign run --groups FILE": ([daa_sil, "campaign", "run", "--groups", str(groups), *small],
                                       "wait_threshold_s"),
        "campaign run --config FILE": ([daa_sil, "campaign", "run", "--groups", "IC-1", "--config", str(config),
                                        *small], "allocation.wt"),
        "run SCENARIO": ([daa_sil, "run", str(_scenario(tmp_path, 200))], "wait_threshold_s"),
    }
    env = dict(os.environ, PYTHONDONTWRITEBYTECODE="1", DAA_SIL_CACHE=str(tmp_path / "cache"))
    procs = {}
    try:
        for i, (what, (argv, needle)) in enumerate(cases.items()):
            out = tmp_path / f"out{i}"
            procs[what] = (out, needle, subprocess.Popen(argv + ["--out", str(out)], stdout=subprocess.PIPE,
                                                         stderr=subprocess.PIPE, text=True, env=env))
        for what, (out, needle, proc) in procs.items():
            _, err = proc.communicate(timeout=LIMIT_S)
            lines = err.strip().splitlines()
            assert proc.returncode == 2, (what, err)
            assert len(lines) == 1 and lines[0].startswith("daa-sil: error: "), (what, err)
            assert needle in lines[0] and "120" in lines[0] and "200" in lines[0], (what, lines[0])
            assert not out.exists(), what
    finally:
        for _, _, proc in procs.values():
            if proc.poll() is None:
                proc.kill()
                proc.wait()


def test_wt_120_is_accepted_by_every_input(tmp_path):
    from daa_sil.config.groups import load_group_file
    from daa_sil.config.overrides import Overrides
    from daa_sil.config.settings import WAIT_THRESHOLD
    from daa_sil.config.run_config import config_from_dict
    from daa_sil.sil.scenario import load_scenario
    from daa_sil.study.campaign.config import CampaignConfig

    assert WAIT_THRESHOLD.range == (0.0, 120.0)
    CampaignConfig(settings=Overrides.of_values({WAIT_THRESHOLD: 120.0})).validate()
    groups = tmp_path / "g.yaml"
    groups.write_text("IC-9: {base: IC-1, wait_threshold_s: 120}\n")
    assert load_group_file(groups)[0].allocation.wait_threshold_s == 120.0
    assert config_from_dict({"allocation": {"wt": 120}}, "c.yaml").allocation["wt"] == 120
    assert load_scenario(_scenario(tmp_path, 120)).allocation.settings.of(WAIT_THRESHOLD) == 120.0


def test_the_vehicle_parameter_has_the_same_range():
    from vehicle.params import ParamTable

    wt = next(s for s in ParamTable("paper").specs if s.name == "DAA_WT")
    assert (wt.lo, wt.hi) == (0.0, 120.0)
