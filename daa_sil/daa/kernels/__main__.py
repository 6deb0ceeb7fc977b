"""``python -m daa_sil.daa.kernels``: compile the DAA kernels into their cache (or load them) and say
where it is and how long it took (the test suite runs it before its first test, so its SIL processes start warm)."""

from daa_sil.daa import kernels

kernels.get()
helper = "" if kernels.HELPER_RC is None else (
    f" (with a helper process compiling {', '.join(kernels.HELPER_MODULES)})" if kernels.HELPER_RC == 0
    else f" (its helper process failed: exit {kernels.HELPER_RC})")
print(f"DAA kernels ready: {kernels.LOAD_S:.1f} s compiling or loading{helper}, {kernels.LOCK_WAIT_S:.1f} s waiting "
      f"for another process's compilation; cache {kernels.CACHE_DIR}")
