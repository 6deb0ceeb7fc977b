"""Import a module in a daemon thread, so that a process pays for it while it would otherwise wait.

Used where a process is known to sit idle for a while before it needs a heavy module: the
``daa-sil run`` driver while the vehicle starts, the lockstep vehicle (pyarrow, for the step log it
writes at the end) while it waits for each tick's answer. The import holds the interpreter lock
only while it runs Python code; whoever then imports the module normally gets the loaded one (or
waits for the import in progress, under the import system's per-module lock).
"""

from __future__ import annotations

import importlib
import threading


def import_in_background(module: str) -> threading.Thread:
    """Start importing ``module`` (a dotted name) in a daemon thread; returns the thread."""
    thread = threading.Thread(target=importlib.import_module, args=(module,), daemon=True,
                              name=f"preload {module}")
    thread.start()
    return thread
