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
        "axis_knots_into", "search_into", "pivot_search_into", "cylinder_prepare_into", "cylinder_step_into",
        "cylinder_finish_into")

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
    """A process on a warm cache loads every kernel but the lazy ones (twelve a SIL process never calls with
    the default configuration); the first call loads one and computes with it."""
    for _ in range(2):  # (the first run warms the cache if this machine's is cold)
        p = subprocess.run([sys.executable, "-c", LAZY_PROBE], capture_output=True, text=True, timeout=900)
        assert p.returncode == 0, p.stderr[-2000:]
    names, after = p.stdout.split("|")
    assert sorted(names.split()) == sorted(LAZY)
    assert after.strip().split(None, 1) == ["True", "[True, True]"]


def test_the_numba_free_locator_agrees_with_the_kernels():
    """daa_sil.runtime.jit_cache (which the SIL driver asks without importing numba) names the directory the kernels
    use, and says it is warm once they are loaded."""
    from daa_sil.runtime import jit_cache
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
            res = subprocess.run([sys.executable, "-c", PROBE], env=dict(os.environ), capture_output=True, text=True,
                                 timeout=120)  # (the same cache directory: a NUMBA_CACHE_DIR the run was given too)
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
    from daa_sil.daa import kernels

    kernels.get()  # a warm cache (a cold one compiles, so loads, every lazy kernel)
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    res = subprocess.run([sys.executable, "-c", VEHICLE_START], capture_output=True, text=True, timeout=300, cwd=root)
    assert res.returncode == 0, res.stderr[-2000:]
    assert res.stdout.split() == ["search_into"]


def test_a_copy_of_the_sources_elsewhere_has_its_own_cache_directory(tmp_path, monkeypatch):
    """numba files its entries under each source file's directory, so the same sources elsewhere (a second
    checkout, a benchmark's copy) have none of them: they get their own cache directory and ``ready`` file.
    A shared one read as warm there, and the SIL's vehicle and GCS then compiled side by side at start-up,
    and the lazy kernels in the middle of a run."""
    import shutil

    from daa_sil.runtime import jit_cache

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
        return jit_cache.cache_dir()

    try:
        first = at(copies[0])
        first.mkdir(parents=True)
        assert not jit_cache.is_warm()
        jit_cache.mark_ready()
        assert jit_cache.is_warm() and jit_cache.is_warm(first)
        second = at(copies[1])  # the same sources (copied with their metadata), elsewhere
        assert second != first and second.parent == first.parent
        assert not jit_cache.is_warm() and jit_cache.is_warm(first)
    finally:
        jit_cache.source_hash.cache_clear()


#: on PYTHONPATH: in the compile helper (a spawned process) the resolution's kernel module cannot be imported
FAILING_HELPER = """
import sys
if "--multiprocessing-fork" in sys.argv:
    sys.modules["daa_sil.daa.kernels.resolve"] = None
"""

#: compiles or loads the kernels; prints the helper's exit status and resolve_into's cache hits and misses here
HELPER_PROBE = """
from daa_sil.daa import kernels
kernels.get()
from daa_sil.daa.kernels import resolve
st = resolve.resolve_into.stats
print(kernels.HELPER_RC, sum(st.cache_hits.values()), sum(st.cache_misses.values()))
"""


@pytest.mark.slow  # two cold compilations (about 40 and 55 s on the 2-vCPU benchmark VM)
@pytest.mark.skipif((os.cpu_count() or 1) < 2, reason="the helper runs on two cores or more")
def test_a_cold_cache_is_compiled_with_a_helper_process_and_without_one_if_it_fails(tmp_path):
    """On two cores a cold cache is compiled by this process and a helper (kernels.HELPER_MODULES): the
    resolution's kernel is then loaded here, not compiled, and the bands are those of a warm cache. A
    helper that fails is reported in one line, and its part compiled here."""
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
        p = subprocess.run([sys.executable, "-c", HELPER_PROBE], env=env, capture_output=True, text=True,
                           timeout=900)
        assert p.returncode == 0, p.stderr[-2000:]
        runs[case] = (p.stdout.split(), p.stderr)
        (again,) = _finish(_start(tmp_path / case))
        assert again[2] == warm[2], case
        index = " ".join(f.name for f in (tmp_path / case).rglob("*.nbi"))
        for name in LAZY:
            assert f".{name}-" in index, (case, name)
    assert runs["helper"][0] == ["0", "1", "0"], runs["helper"]  # loaded from the helper's entry
    assert "helper" not in runs["helper"][1]
    assert runs["failing"][0] == ["1", "0", "1"], runs["failing"]  # compiled here
    lines = [ln for ln in runs["failing"][1].splitlines() if "helper" in ln]
    assert lines == ["daa-sil: the kernel compilation helper failed (exit 1: ModuleNotFoundError: import of "
                     "daa_sil.daa.kernels.resolve halted; None in sys.modules); compiling its part here"], lines


DAEMON_PROBE = """
import multiprocessing as mp


def work(q):
    from daa_sil.daa import kernels
    kernels.get()
    q.put(kernels.HELPER_RC)


if __name__ == "__main__":
    ctx = mp.get_context("spawn")
    q = ctx.Queue()
    p = ctx.Process(target=work, args=(q,), daemon=True)
    p.start()
    rc = q.get(timeout=900)
    p.join(60)
    print(rc, p.exitcode)
"""


@pytest.mark.slow  # a cold compilation in one process (about a minute on the 2-vCPU benchmark VM)
def test_a_daemonic_process_compiles_a_cold_cache_alone(tmp_path):
    """A daemonic process (a Dask worker) may not start children: on a cold cache it compiles every kernel
    itself instead of failing."""
    script = tmp_path / "daemon_probe.py"
    script.write_text(DAEMON_PROBE)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba"))
    p = subprocess.run([sys.executable, str(script)], env=env, capture_output=True, text=True, timeout=1200)
    assert p.returncode == 0, p.stderr[-2000:]
    assert p.stdout.split() == ["None", "0"], (p.stdout, p.stderr[-2000:])
    assert "helper" not in p.stderr and "could not be read" not in p.stderr, p.stderr[-2000:]
