"""Test-session set-up shared by every test module."""

from __future__ import annotations

import subprocess
import sys

import pytest

from daa_sil.jit_cache import cache_dir, is_warm


@pytest.fixture(scope="session", autouse=True)
def warm_kernel_cache() -> None:
    """The DAA kernels compiled into their cache before the first test, as ``python -m daa_sil.daa.kernels``
    does (once per machine and source version; a no-op when the cache is complete). Without it, on a
    fresh machine the first tests that start SIL processes would have them compile the kernels
    (20-60 s on two cores) against their READY timeouts."""
    if is_warm():
        return
    print(f"\ncompiling the DAA kernels into {cache_dir()} (first run only)", file=sys.__stderr__, flush=True)
    subprocess.run([sys.executable, "-m", "daa_sil.daa.kernels"], check=True, timeout=900)
