"""Whether this process runs the compiled kernels in code that never starts numba itself.

Truth motion (:mod:`daa_sil.geometry.kinematics`) and the step's NMAC test
(:mod:`daa_sil.geometry.wellclear`) are also called by processes that need no DAA (reading a scenario,
sampling encounters on the driver, ``daa-sil geometry``): importing numba and loading the kernels would
cost them about 0.6 s. They run compiled where the process has loaded the kernels anyway
(:func:`daa_sil.daa.kernels.get`: the SIL's vehicle and GCS, every campaign worker) and as their numpy
references elsewhere; both give the same numbers (``docs/daa.md``, "Compiled kernels").
"""

from __future__ import annotations

import sys

#: False: always the numpy references (profiling them; tests force a path by replacing a function instead)
ENABLED = True


def loaded_kernels():
    """The DAA's compiled kernels (a ``SimpleNamespace``) if this process has loaded them, else None. Never
    imports numba, nor :mod:`daa_sil.daa` (whose modules import the geometry that asks)."""
    mod = sys.modules.get("daa_sil.daa.kernels")
    return mod.loaded() if ENABLED and mod is not None else None


__all__ = ["ENABLED", "loaded_kernels"]
