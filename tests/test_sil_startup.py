"""SIL start-up does only what a run needs (issue 21, item 5).

* The shim starts through its own entry point (``python -m daa_sil.commands.shim``), which takes
  the arguments of ``daa-sil shim`` and imports none of the wait-map, DAA, configuration (but the shared-defaults table config.settings) or
  fast-time modules; the GCS imports no fast-time / Parquet code; nothing in the vehicle's start-up
  (including loading the wait maps) imports scipy, which only building a map needs, beyond what
  numba (the compiled DAA, loaded before READY) imports by itself.
* The vehicle places a scenario's ``cpa`` intruders without integrating their realised CPA (never
  read in the SIL); the states are the same as with it.
* ``daa-sil run`` does not load a cached wait-map family: the vehicle loads it once and writes its
  description (content hashes included) into the step log, which ``result.json`` records.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


def _modules_after(code: str) -> set:
    """Module names loaded by a fresh interpreter after running ``code`` (run from the repository)."""
    probe = code + "\nimport sys, json\nprint(json.dumps(sorted(sys.modules)))\n"
    res = subprocess.run([sys.executable, "-c", probe], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr[-2000:]
    return set(json.loads(res.stdout.strip().splitlines()[-1]))


def _numba_modules() -> set:
    """What loading the compiled DAA kernels loads by itself: numba imports part of scipy (to type
    the numpy functions it compiles), but not ``scipy.sparse``, which only building a map needs."""
    return _modules_after("from daa_sil.daa import kernels\nkernels.get()")


def _under(mods: set, *prefixes: str) -> list:
    return sorted(m for m in mods if any(m == p or m.startswith(p + ".") for p in prefixes))


def test_shim_entry_point_imports_only_the_link_side():
    mods = _modules_after("from daa_sil.commands import shim\nshim.build_parser().parse_args(['--delay', 'const:4'])")
    heavy = _under(mods, "scipy", "pyarrow", "daa_sil.waitmap", "daa_sil.daa", "daa_sil.config", "daa_sil.study",
                   "daa_sil.agent.step", "daa_sil.onboard", "daa_sil.commands.waitmap", "daa_sil.commands.run")
    # the one table of shared defaults (the delay epoch) imports nothing of ours but errors: any layer may read it
    allowed = ["daa_sil.config", "daa_sil.config.settings"]
    assert [m for m in heavy if m not in allowed] == [], heavy


def test_shim_entry_point_has_the_arguments_of_daa_sil_shim():
    from daa_sil.cli import build_parser
    from daa_sil.commands import shim

    sub = next(a for a in build_parser()._actions if a.dest == "command").choices["shim"]
    own = shim.build_parser()
    assert sorted(a.dest for a in own._actions) == sorted(a.dest for a in sub._actions)
    assert own.prog == "daa-sil shim"


def test_shim_entry_point_errors_are_one_line_exit_2(tmp_path):
    for args, text in ((["--delay", "bogus:1"], "daa-sil: error: bad delay spec"),
                       (["--delay", "const:4", "--bogus"], "daa-sil shim: error: unrecognized arguments: --bogus")):
        res = subprocess.run([sys.executable, "-m", "daa_sil.commands.shim", *args], cwd=tmp_path,
                             capture_output=True, text=True, timeout=60)
        assert res.returncode == 2, res.stderr
        assert res.stderr.strip().splitlines() == [res.stderr.strip()] and text in res.stderr, res.stderr


def test_vehicle_start_up_with_its_wait_maps_imports_no_scipy():
    code = ("from daa_sil.sil.scenario import load_scenario\nfrom vehicle.core import VehicleCore\n"
            "import vehicle.node, vehicle.cli\n"
            "vc = VehicleCore(load_scenario('scenarios/head_on.yaml'))\nassert vc.waitmap_record is not None")
    mods = _modules_after(code)
    assert _under(mods, "scipy.sparse") == []
    assert _under(mods - _numba_modules(), "scipy") == []
    assert "daa_sil.waitmap.lookup" in mods  # the maps were loaded


def test_gcs_start_up_imports_no_fast_time_or_parquet_code():
    code = ("import gcs.cli\nfrom daa_sil.sil.scenario import load_scenario\nfrom gcs.node import GcsNode, GcsOptions\n"
            "GcsNode(load_scenario('scenarios/head_on.yaml'), GcsOptions(clock='lockstep'))")
    mods = _modules_after(code)
    assert _under(mods - _numba_modules(), "scipy", "pyarrow", "daa_sil.study", "daa_sil.waitmap") == []
    assert "daa_sil.models.pilot" in mods  # the pilot model was built


def test_streams_are_the_fast_time_ones():
    from daa_sil.models import streams
    from daa_sil.study.simulation import fasttime

    assert fasttime.encounter_streams is streams.encounter_streams
    assert (fasttime.STREAM_PILOT, fasttime.STREAM_UP, fasttime.STREAM_DOWN) == (0, 1, 2)


@pytest.mark.parametrize("name", ["head_on.yaml", "crossing_left.yaml", "two_intruders.yaml", "climbing.yaml",
                                  "overtaking.yaml"])
def test_scenario_placement_without_the_realised_cpa_is_the_same(name):
    from daa_sil.models.encounter_geometry import IntruderGeometry, encounter_from_geometry
    from daa_sil.sil.scenario import encounter_set, load_scenario, ownship_state

    sc = load_scenario(ROOT / "scenarios" / name)
    es = encounter_set(sc)
    own = ownship_state(sc)
    for j, spec in enumerate(sc.intruders):
        if spec.cpa is None:
            continue
        c = spec.cpa
        mv = [(x.start_s, x.end_s, x.turn_rate_dps, x.accel_mps2, x.vertical_accel_mps2) for x in spec.maneuvers]
        full = encounter_from_geometry([IntruderGeometry(c.angle_deg, c.hmd_m, c.t_cpa_s, c.gs_mps, c.vmd_m, c.vs_mps,
                                                         mv)], own=own, duration_s=sc.duration_s, seed=sc.seed)
        assert np.isfinite(full.params["hmd_real_m"]).all()  # the full placement did integrate it
        np.testing.assert_array_equal(es.intr.as_array()[:, j], full.intr.as_array()[:, 0])


def test_placement_without_the_realised_cpa_leaves_it_nan():
    from daa_sil.models.encounter_geometry import IntruderGeometry, encounter_from_geometry

    g = IntruderGeometry(angle_deg=90, hmd_m=300, t_cpa_s=60, gs_mps=80, maneuvers=[(10, 40, 2.0, 0.0, 0.0)])
    lean = encounter_from_geometry(g, duration_s=120, realised=False)
    full = encounter_from_geometry(g, duration_s=120)
    np.testing.assert_array_equal(lean.intr.as_array(), full.intr.as_array())
    for k in ("hmd_real_m", "vmd_real_m", "t_cpa_real_s"):
        assert np.isnan(lean.params[k]).all() and np.isfinite(full.params[k]).all()


def test_run_does_not_load_a_cached_family_and_records_the_vehicles(tmp_path, monkeypatch):
    """The driver neither loads the maps before the run nor to describe them after: the record comes
    from the vehicle's step log (the family it loaded, hashes verified)."""
    from daa_sil import waitmap
    from daa_sil.sil import play
    from daa_sil.sil.scenario import load_scenario
    from daa_sil.steplog import steplog_metadata

    sc = load_scenario(ROOT / "scenarios" / "head_on.yaml")
    assert sc.allocation.wait == "map"
    from daa_sil.config.run_config import default_wait_maps

    source, horizon = default_wait_maps()  # the vehicle flies the study's default reading's maps
    fam = waitmap.family_for(source, preset="paper", horizon=horizon)  # cached now (built on first use)
    expected = {"source": source, **json.loads(json.dumps(waitmap.describe(fam)))}

    def refuse(*a, **k):
        raise AssertionError("the driver loaded the wait-map family")

    monkeypatch.setattr(waitmap, "family_for", refuse)
    play.prepare_waitmap(sc, None, None)  # cached: nothing loaded
    res = play.run_sil(play.RunOptions(ROOT / "scenarios" / "head_on.yaml", tmp_path / "run"))
    assert res["waitmap"] == expected
    described = json.loads(steplog_metadata(tmp_path / "run" / "steplog.parquet")["waitmap"])
    assert {"source": source, **described} == expected


def test_waitmap_record_falls_back_to_loading_without_the_step_log_entry(tmp_path):
    """A step log without the vehicle's description (written by another tool) is still recorded right."""
    import pyarrow as pa

    from daa_sil import waitmap
    from daa_sil.sil import play
    from daa_sil.sil.scenario import load_scenario
    from daa_sil.steplog import STEP_SCHEMA, write_steplog

    sc = load_scenario(ROOT / "scenarios" / "head_on.yaml")
    path = write_steplog(pa.Table.from_pylist([], schema=STEP_SCHEMA), tmp_path / "s.parquet")
    rec = play._waitmap_record(sc, None, path)
    from daa_sil.config.run_config import default_wait_maps

    source, horizon = default_wait_maps()
    fam = waitmap.family_for(source, preset="paper", horizon=horizon)
    assert rec["content_hashes"] == [m.content_hash for m in fam.maps] and rec["source"] == source


def _commands(parser) -> set:
    return set(next(a for a in parser._actions if a.dest == "command").choices)


def test_cli_imports_only_the_module_of_the_command_given():
    """``daa-sil run ...`` builds the parser of the run module only; the map covers every command."""
    from daa_sil.cli import COMMANDS, build_parser

    assert _commands(build_parser()) == set(COMMANDS)
    for name in COMMANDS:
        assert name in _commands(build_parser(name))
    mods = _modules_after("from daa_sil.cli import build_parser\nbuild_parser('run').parse_args(['run', 'x.yaml'])")
    assert _under(mods, "daa_sil.commands.campaign", "daa_sil.commands.viz", "daa_sil.viz", "daa_sil.study",
                  "pyarrow") == []


def test_cli_unknown_command_is_the_usual_one_line_error():
    res = subprocess.run([sys.executable, "-m", "daa_sil.cli", "bogus"], cwd=ROOT, capture_output=True, text=True,
                         timeout=60)
    assert res.returncode == 2 and "invalid choice: 'bogus'" in res.stderr and "'campaign'" in res.stderr


def test_kernels_load_without_the_blas_probe_and_compute_the_same_bands():
    """``kernels.skip_blas_probe`` (what ``python -m vehicle`` and ``python -m gcs`` call first): loading
    the kernels then imports no ``scipy.linalg``, scipy still imports afterwards, and the bands are
    bit-identical to a process that loaded them with numba's probe."""
    code = """
import json, sys
import numpy as np
from daa_sil.daa import kernels
if SKIP:
    kernels.skip_blas_probe()
kernels.get()
loaded = sorted(m for m in sys.modules if m == "scipy.linalg" or m.startswith("scipy.linalg."))
import scipy.linalg
from daa_sil.daa import DaaConfig, compute_bands
from daa_sil.geometry.kinematics import AircraftState
own = AircraftState(*(np.array([v]) for v in (0.0, 0.0, 1000.0, 55.0, 0.1, 0.0)))
intr = AircraftState(*(np.array([[v]]) for v in (300.0, 6000.0, 1030.0, 60.0, 3.0, -1.0)))
b = compute_bands(own, intr, DaaConfig.for_preset("do365"))
print(json.dumps({"loaded": loaded, "linalg": scipy.linalg.__name__,
                  "bands": [[a.values.tolist(), a.region.tolist()] for a in b.axes()]}))
"""
    out = {}
    for skip in (True, False):
        res = subprocess.run([sys.executable, "-c", code.replace("SKIP", str(skip))], cwd=ROOT, capture_output=True,
                             text=True, timeout=300)
        assert res.returncode == 0, res.stderr[-2000:]
        out[skip] = json.loads(res.stdout.strip().splitlines()[-1])
    assert out[True]["loaded"] == [] and out[False]["loaded"] != []
    assert out[True]["linalg"] == "scipy.linalg"
    assert out[True]["bands"] == out[False]["bands"]
    assert any(r != 0 for axis in out[True]["bands"] for r in axis[1][0])  # the encounter has bands to compare


def test_the_kernels_every_process_loads_leave_out_the_unfused_ones():
    """The unfused resolution's kernels (only the tests take that path) are loaded on first use, not by
    ``kernels.get()``, which every SIL node and campaign worker calls."""
    mods = _modules_after("from daa_sil.daa import kernels\nkernels.get()")
    assert "daa_sil.daa.kernels.resolve" in mods
    assert "daa_sil.daa.kernels.unfused" not in mods


def test_run_and_the_gcs_import_the_run_configuration_only_for_config(tmp_path):
    """``daa-sil run``'s parser and the GCS's start-up import the run configuration (its sections and
    readings) only when ``--config`` is given; with it, a bad value is still the one-line error before
    any process starts, and a preset is read."""
    gcs_start = ("import gcs.cli\nfrom daa_sil.sil.scenario import load_scenario\nfrom gcs.node import GcsNode, GcsOptions\n"
                 "from daa_sil.config.config_option import config_of\n"
                 "a = gcs.cli.build_parser().parse_args(['--scenario', 'scenarios/head_on.yaml'{extra}])\n"
                 "GcsNode(load_scenario(a.scenario), GcsOptions(clock='lockstep', config=config_of(a.config)))")
    assert "daa_sil.config.run_config" not in _modules_after(gcs_start.format(extra=""))
    assert "daa_sil.config.run_config" in _modules_after(gcs_start.format(extra=", '--config', 'do365'"))
    run_parser = ("from daa_sil.cli import build_parser\n"
                  "build_parser('run').parse_args(['run', 'scenarios/head_on.yaml', '--out', 'o', '--config', 'do365'])")
    assert "daa_sil.config.run_config" not in _modules_after(run_parser)
    bad = subprocess.run([sys.executable, "-m", "daa_sil.cli", "run", "scenarios/head_on.yaml", "--out",
                          str(tmp_path / "o"), "--config", str(tmp_path / "missing.yaml")], cwd=ROOT,
                         capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1 and "neither a preset" in bad.stderr, bad.stderr
    assert not (tmp_path / "o").exists()  # nothing started, nothing written

    from daa_sil.config.config_option import config_of
    from daa_sil.errors import UsageError

    assert config_of(None) is None and config_of("") is None
    assert config_of("do365").thresholds == "do365"
    with pytest.raises(UsageError, match="neither a preset"):
        config_of(str(tmp_path / "missing.yaml"))
