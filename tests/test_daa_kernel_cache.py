"""The compiled-kernel cache (daa_sil.daa.kernels.jit): processes starting together on a cold cache
all start, one compiles while the others wait for it and load its result, and a damaged cache is
reported in one line, dropped and rebuilt, with the same numbers."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

#: prints the lock wait and a few band numbers of a fixed encounter
PROBE = """
import numpy as np
from daa_sil.daa import DaaConfig, compute_bands, kernels
from daa_sil.geometry.kinematics import AircraftState
own = AircraftState(*(np.array([v]) for v in (0.0, 0.0, 1000.0, 55.0, 0.0, 0.0)))
intr = AircraftState(*(np.array([[v]]) for v in (300.0, 6000.0, 1010.0, 60.0, np.pi, 0.0)))
b = compute_bands(own, intr, DaaConfig.for_preset("do365"))
print(kernels.LOCK_WAIT_S, kernels.CACHE_DIR, repr(b.trk.t_in[0].tolist()))
"""


def _start(cache, n=1):
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    return [subprocess.Popen([sys.executable, "-c", PROBE], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                             text=True) for _ in range(n)]


def _finish(procs, timeout=600):
    out = []
    for p in procs:
        stdout, stderr = p.communicate(timeout=timeout)
        assert p.returncode == 0, stderr[-2000:]
        wait, cache_dir, t_in = stdout.split(" ", 2)
        out.append((float(wait), cache_dir, t_in.strip(), stderr))
    return out


@pytest.mark.slow  # two cold compilations (about 10 s each on a quiet machine, a minute under load)
def test_cold_start_together_then_damaged_cache(tmp_path):
    cache = tmp_path / "numba"
    runs = _finish(_start(cache, 3))
    assert len({r[2] for r in runs}) == 1  # the same bands in each
    waited = sorted(r[0] for r in runs)
    assert waited[-1] > 0.5  # someone waited for the one that compiled (compiling takes seconds)
    entries = list(cache.rglob("*.nbc"))
    assert entries and all(r[1].startswith(str(cache)) for r in runs)
    for f in entries:  # truncate every compiled entry
        f.write_bytes(f.read_bytes()[:64])
    (again,) = _finish(_start(cache))
    assert again[2] == runs[0][2]
    lines = [ln for ln in again[3].splitlines() if "compiled-kernel cache" in ln]
    assert len(lines) == 1 and "recompiling" in lines[0]
    (warm,) = _finish(_start(cache))  # rebuilt: nothing to report any more
    assert warm[2] == runs[0][2] and "compiled-kernel cache" not in warm[3]
    # the cold start compiled the lazy kernels too (the "ready" file says every kernel is cached)
    index = " ".join(f.name for f in cache.rglob("*.nbi"))
    for name in LAZY:
        assert f".{name}-" in index, name


#: the kernels only some configurations call, loaded at their first call
LAZY = ("wcv_soa_into", "classify_into", "clear2_into", "candidates_into", "segment_into", "axis_relative_knots_into",
        "axis_knots_into", "search_into")

#: with a warm cache: how many lazy kernels get() left unloaded, then one called
LAZY_PROBE = """
import numpy as np
from daa_sil.daa import kernels
ns = kernels.get()
lazy = {k.__name__: k for k in kernels.lazy_kernels()}
before = sorted(n for n, k in lazy.items() if k.dispatcher is None)
out = np.zeros(2, bool)
z = np.zeros(2)
ns.wcv_soa_into(z + 100.0, z, z, z - 50.0, z, z, 1.0e6, 35.0, 140.0, 0.0, out)
print(" ".join(before), "|", lazy["wcv_soa_into"].dispatcher is not None, out.tolist())
"""


def test_lazy_kernels_are_loaded_at_their_first_call():
    """A process on a warm cache loads every kernel but the lazy ones (eight a SIL process never calls with
    the default configuration); the first call loads one and computes with it."""
    for _ in range(2):  # (the first run warms the cache if this machine's is cold)
        p = subprocess.run([sys.executable, "-c", LAZY_PROBE], capture_output=True, text=True, timeout=900)
        assert p.returncode == 0, p.stderr[-2000:]
    names, after = p.stdout.split("|")
    assert sorted(names.split()) == sorted(LAZY)
    assert after.strip().split(None, 1) == ["True", "[True, True]"]


def test_the_numba_free_locator_agrees_with_the_kernels():
    """daa_sil.jit_cache (which the SIL driver asks without importing numba) names the directory the kernels
    use, and says it is warm once they are loaded."""
    from daa_sil import jit_cache
    from daa_sil.daa import kernels

    kernels.get()
    assert jit_cache.cache_dir() == kernels.CACHE_DIR
    assert jit_cache.is_warm()


def test_a_complete_cache_loads_without_the_compile_lock():
    """Loading only reads: with the cache complete, a process loads while another holds the compile lock
    (the SIL's vehicle and GCS start together; they used to load one after the other)."""
    import fcntl

    from daa_sil.daa import kernels

    kernels.get()  # the cache is complete now (its ready file)
    with open(kernels.CACHE_DIR / ".compile.lock", "a+b") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
            res = subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True, text=True, timeout=120)
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)
    assert res.returncode == 0, res.stderr[-2000:]
    assert res.stdout.split(" ", 2)[1] == str(kernels.CACHE_DIR)


FIRST_CALL = r"""
import sys
from daa_sil.daa import kernels
kernels.skip_blas_probe()
kernels.get()
import numpy as np
from daa_sil.daa import DaaConfig, compute_bands
from daa_sil.geometry.kinematics import AircraftState
own = AircraftState(*(np.array([v]) for v in (0.0, 0.0, 1000.0, 50.0, 0.0, 0.0)))
intr = AircraftState(*(np.array([[v]]) for v in (0.0, 6000.0, 1000.0, 50.0, 3.14159, 0.0)))
before = set(sys.modules)
b = compute_bands(own, intr, DaaConfig())
assert b.trk.region.shape[0] == 1
print(" ".join(sorted(set(sys.modules) - before)))
"""


def test_the_first_daa_step_imports_nothing():
    """After :func:`kernels.get` (the SIL nodes call it before READY), the first bands of a conflict import no
    module: numba's first typing of an array imported numpy.ma there (20-35 ms in the first DAA step of the
    vehicle and the GCS, a realtime deadline)."""
    res = subprocess.run([sys.executable, "-c", FIRST_CALL], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr[-2000:]
    assert res.stdout.strip() == "", f"imported during the first bands: {res.stdout.strip()}"


VEHICLE_START = """
from pathlib import Path
from daa_sil.daa import kernels
from daa_sil.sil.scenario import load_scenario
from vehicle.core import VehicleCore
kernels.skip_blas_probe()
VehicleCore(load_scenario(Path("scenarios/head_on.yaml")))
print(" ".join(sorted(k.__name__ for k in kernels.lazy_kernels() if k.dispatcher is not None)))
"""


def test_the_vehicle_loads_the_blending_search_before_its_first_step():
    """Algorithm 2's search (a lazy kernel) is loaded when the vehicle's core is built, not at the first blend:
    in the SIL head-on the vehicle blends 13 of 240 steps, and loading it there (7-30 ms) fell inside a realtime
    step. The other lazy kernels stay unloaded (the start-up they save)."""
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    res = subprocess.run([sys.executable, "-c", VEHICLE_START], capture_output=True, text=True, timeout=300, cwd=root)
    assert res.returncode == 0, res.stderr[-2000:]
    assert res.stdout.split() == ["search_into"]


def test_ready_means_complete_for_these_sources_where_they_are(tmp_path, monkeypatch):
    """The ``ready`` file holds for one checkout's sources as they are: a copy elsewhere gets its own cache
    directory (numba files entries under each source's directory, so the copy has none of them), and a
    source touched without a change (numba then recompiles it) is not warm until marked again. Either
    used to read as warm: the vehicle and the GCS then compiled side by side at start-up, and a lazy
    kernel in the middle of a run."""
    import shutil

    from daa_sil import jit_cache

    copies = []
    for name in ("a", "b"):
        d = tmp_path / name / "kernels"
        shutil.copytree(jit_cache.KERNEL_DIR, d, ignore=shutil.ignore_patterns("__pycache__"),
                        copy_function=shutil.copy2)
        copies.append(d)
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "cache"))

    def at(d):
        monkeypatch.setattr(jit_cache, "KERNEL_DIR", d)
        jit_cache.source_hash.cache_clear()

    try:
        at(copies[0])
        first = jit_cache.cache_dir()
        first.mkdir(parents=True)
        assert not jit_cache.is_warm()
        (first / jit_cache.READY_MARKER).touch()  # an empty marker (as older code wrote it) says nothing
        assert not jit_cache.is_warm()
        jit_cache.mark_ready()
        assert jit_cache.is_warm()
        at(copies[1])  # the same sources, copied with their time stamps, elsewhere
        assert jit_cache.cache_dir() != first and not jit_cache.is_warm()
        at(copies[0])
        assert jit_cache.is_warm()
        f = sorted(copies[0].glob("*.py"))[0]
        st = f.stat()
        os.utime(f, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000_000))
        assert jit_cache.cache_dir() == first and not jit_cache.is_warm()
        jit_cache.mark_ready()
        assert jit_cache.is_warm() and not list(first.glob(".ready.*"))
    finally:
        jit_cache.source_hash.cache_clear()


#: on PYTHONPATH: the compile helper (and only it) fails at once
FAILING_HELPER = """
import os, sys
if os.environ.get("DAA_SIL_PROCESS_NAME") == "daa-kernels":
    sys.stderr.write("helper broken on purpose\\n")
    os._exit(3)
"""


@pytest.mark.slow  # two cold compilations (about 35 and 55 s on the 2-vCPU benchmark VM)
def test_a_cold_cache_is_compiled_with_a_helper_process_and_without_one_if_it_fails(tmp_path):
    """On two cores a cold cache is compiled by this process and a helper (kernels.HELPER_MODULES), and gives
    the bands a warm cache gives; a helper that fails is reported in one line and its part compiled here."""
    from daa_sil.daa import kernels

    kernels.get()
    (warm,) = _finish(_start(kernels.CACHE_DIR.parent))  # this machine's cache: the bands to get
    runs = {}
    for case in ("helper", "failing"):
        env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / case))
        if case == "failing":
            (tmp_path / "site").mkdir()
            (tmp_path / "site" / "sitecustomize.py").write_text(FAILING_HELPER)
            env["PYTHONPATH"] = os.pathsep.join([str(tmp_path / "site")] + [p for p in [env.get("PYTHONPATH")] if p])
        p = subprocess.run([sys.executable, "-m", "daa_sil.daa.kernels"], env=env, capture_output=True, text=True,
                           timeout=900)
        assert p.returncode == 0, p.stderr[-2000:]
        runs[case] = p
        (again,) = _finish(_start(tmp_path / case))
        assert again[2] == warm[2], case
        index = " ".join(f.name for f in (tmp_path / case).rglob("*.nbi"))
        for name in LAZY:
            assert f".{name}-" in index, (case, name)
    assert "with a helper process compiling resolve" in runs["helper"].stdout, runs["helper"].stdout
    assert "helper" not in runs["helper"].stderr
    assert "its helper process failed: exit 3" in runs["failing"].stdout
    lines = [ln for ln in runs["failing"].stderr.splitlines() if "helper" in ln]
    assert lines == ["daa-sil: the kernel compilation helper failed (exit 3: helper broken on purpose); "
                     "compiling its part here"], runs["failing"].stderr
