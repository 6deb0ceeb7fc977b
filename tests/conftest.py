"""Test-session set-up shared by every test module."""

from __future__ import annotations

import subprocess
import sys

import pytest

from daa_sil.runtime.jit_cache import COLD_COMPILE_TIME, cache_dir, is_warm


@pytest.fixture(scope="session", autouse=True)
def warm_kernel_cache(request) -> None:
    """The DAA kernels compiled into their cache before the first test, as ``python -m daa_sil.daa.kernels``
    does (once per machine and source version; a no-op when the cache is complete). Without it, on a
    fresh machine the first tests that start SIL processes would have them compile the kernels
    (:data:`~daa_sil.runtime.jit_cache.COLD_COMPILE_TIME`) against their READY timeouts. Its lines are shown
    whatever pytest captures; a failed compilation stops the session with one line."""
    if is_warm():
        return
    capture = request.config.pluginmanager.getplugin("capturemanager")
    with capture.global_and_fixture_disabled():
        print(f"\ncompiling the DAA kernels into {cache_dir()} (first run only; {COLD_COMPILE_TIME})", flush=True)
        try:
            subprocess.run([sys.executable, "-m", "daa_sil.daa.kernels"], check=True, timeout=900)
        except (subprocess.CalledProcessError, subprocess.TimeoutExpired) as exc:
            pytest.exit(f"compiling the DAA kernels failed ({exc}); run 'python -m daa_sil.daa.kernels' to see why",
                        returncode=3)
