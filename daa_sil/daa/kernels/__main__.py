"""``python -m daa_sil.daa.kernels``: compile the DAA kernels into their cache (or load them) and say
where it is and how long it took (CI runs it after installing, so tests and SIL processes start warm)."""

from daa_sil.daa.kernels import CACHE_DIR, LOAD_S, LOCK_WAIT_S  # (the import compiles)

print(f"DAA kernels ready: {LOAD_S:.1f} s compiling or loading, {LOCK_WAIT_S:.1f} s waiting for another "
      f"process's compilation; cache {CACHE_DIR}")
