"""``python -m daa_sil.daa.kernels``: compile the DAA kernels into their cache (or load them) and say
where it is and how long it took (CI runs it after installing, so tests and SIL processes start warm)."""

from daa_sil.daa import kernels

kernels.get()
print(f"DAA kernels ready: {kernels.LOAD_S:.1f} s compiling or loading, {kernels.LOCK_WAIT_S:.1f} s waiting for "
      f"another process's compilation; cache {kernels.CACHE_DIR}")
