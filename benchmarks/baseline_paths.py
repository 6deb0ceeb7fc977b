"""Where the benchmarks look for the baseline commit installed apart (bba2fd8, CONTRIBUTING.md): its
checkout with its own ``.venv``, and its own ``DAA_SIL_CACHE`` (wait maps), one definition for every
script that compares with it."""

from pathlib import Path

#: the baseline's checkout (``git worktree add /work/baseline bba2fd8``), with ``.venv`` inside
BASELINE_DIR = Path("/work/baseline")
#: its interpreter
BASELINE_PYTHON = BASELINE_DIR / ".venv" / "bin" / "python"
#: its ``DAA_SIL_CACHE`` (kept apart from this checkout's: the maps' formats may differ)
BASELINE_CACHE = Path("/work/cache-baseline")
