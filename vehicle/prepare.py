"""Preparing the vehicle's simulation beside its link: the DAA kernels, the wait maps, the onboard core.

A cold first start compiles the DAA kernels (17-40 s on two cores) and builds the wait maps (about a
minute of CPU for the default maps). The vehicle answers its ground stations meanwhile
(:mod:`vehicle.boot`), so the work runs beside its loop:

* what is cold runs in a **worker process**, ``python -m vehicle.prepare`` (started with
  :func:`daa_sil.sil.children.spawn`: it dies with the vehicle): it compiles the kernels into their cache
  and builds the maps into theirs, one progress line per stage on stdout, which the vehicle sends on
  as STATUSTEXT. A process, not a thread: compiling holds the interpreter lock for long stretches,
  which would stall the vehicle's heartbeat;
* the simulation is then **loaded** from those caches (:class:`vehicle.core.VehicleCore`, about a second)
  in a daemon thread, so the link is still served.

A warm start skips the worker. If the worker fails, the load in the thread does the work itself and
raises what went wrong (a bad ``--waitmap`` says so in one line).
"""

from __future__ import annotations

import argparse
import asyncio
import subprocess
import sys
import threading
import time
from typing import Callable

#: the map building's progress is reported at most this often (fraction of the work)
MAP_PROGRESS_STEP = 0.1


def waitmap_source(opts) -> "tuple[str, float | None]":
    """The wait maps the vehicle will fly, as :func:`vehicle.core.build_onboard` reads them: ``(source,
    horizon)`` -- ``--waitmap``, else the configuration's (the default reading's without one)."""
    from .core import run_config  # lazy: start-up time

    config = run_config(opts.config)
    source = opts.waitmap if opts.waitmap is not None else config.map_source
    return source, config.map_horizon(source)


def cold_parts(sc, opts, policy) -> "list[str]":
    """What a start would build rather than load: ``"kernels"``, ``"maps"`` (only if the policy reads a map)."""
    from daa_sil.runtime.jit_cache import is_warm  # lazy: start-up time

    cold = [] if is_warm() else ["kernels"]
    if policy.wait_mode == "map":
        from daa_sil.waitmap.source import is_cached  # lazy: start-up time

        source, horizon = waitmap_source(opts)
        if not is_cached(source, preset="paper", horizon=horizon):
            cold.append("maps")
    return cold


def _daemon(fn: Callable, loop: asyncio.AbstractEventLoop) -> "asyncio.Future":
    """``fn()`` in a daemon thread (a Ctrl-C never waits for it); its result or exception in a future."""
    fut = loop.create_future()

    def settle(ok: bool, value) -> None:
        if not fut.done():
            (fut.set_result if ok else fut.set_exception)(value)

    def work() -> None:
        try:
            value, ok = fn(), True
        except BaseException as exc:  # noqa: BLE001 -- handed to the loop, which raises it there
            value, ok = exc, False
        try:
            loop.call_soon_threadsafe(settle, ok, value)
        except RuntimeError:  # the loop is closed: the vehicle has stopped
            pass

    threading.Thread(target=work, name="daa-vehicle prepare", daemon=True).start()
    return fut


class Preparation:
    """The vehicle's preparation (see the module docstring). ``on_line(text)`` gets each progress line in
    the loop's thread."""

    def __init__(self, sc, opts, policy, on_line: Callable[[str], None]):
        self.sc, self.opts, self.policy, self.on_line = sc, opts, policy, on_line
        self.proc: "subprocess.Popen | None" = None

    async def run(self):
        """Prepare; returns the :class:`vehicle.core.VehicleCore` (raises what its construction raised)."""
        loop = asyncio.get_running_loop()
        cold = cold_parts(self.sc, self.opts, self.policy)
        if cold:
            rc = await self._worker(loop, cold)
            if rc != 0:
                self.on_line(f"worker failed (exit {rc}); preparing here")
        self.on_line("loading the simulation")
        t0 = time.monotonic()
        from .core import VehicleCore  # lazy: start-up time

        sc, opts = self.sc, self.opts
        core = await _daemon(lambda: VehicleCore(sc, waitmap=opts.waitmap, config=opts.config,
                                                         flags=opts.settings), loop)
        self.on_line(f"simulation loaded ({time.monotonic() - t0:.1f} s)")
        return core

    async def _worker(self, loop, cold: "list[str]") -> int:
        from daa_sil.sil.children import spawn  # lazy: start-up time

        argv = [sys.executable, "-m", "vehicle.prepare"]
        if "kernels" not in cold:
            argv.append("--no-kernels")
        if "maps" in cold:
            src, horizon = waitmap_source(self.opts)
            argv += ["--maps", str(src)] + (["--horizon", repr(float(horizon))] if horizon is not None else [])
        self.proc = spawn(argv, "daa-prepare", stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                          stdin=subprocess.DEVNULL)
        proc = self.proc

        def read() -> int:
            for line in proc.stdout:
                if line.strip():
                    loop.call_soon_threadsafe(self.on_line, line.strip()[:200])
            return proc.wait()

        return await _daemon(read, loop)

    def cancel(self) -> None:
        """Stop the worker, if it runs."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()


def main(argv: "list[str] | None" = None) -> int:
    """The worker process: compile the kernels and build the maps into their caches, saying each stage."""
    from daa_sil.sil.children import adopt  # lazy: start-up time

    adopt("daa-prepare")
    p = argparse.ArgumentParser(prog="python -m vehicle.prepare", description=main.__doc__)
    p.add_argument("--no-kernels", action="store_true", help="the kernels are cached already")
    p.add_argument("--maps", default=None, metavar="SOURCE", help="build the wait maps of SOURCE (a --waitmap value)")
    p.add_argument("--horizon", type=float, default=None, metavar="S", help="their wait-time horizon H (s)")
    args = p.parse_args(argv)

    def say(text: str) -> None:
        print(text, flush=True)

    if not args.no_kernels:
        from daa_sil.runtime.jit_cache import COLD_COMPILE_TIME  # lazy: start-up time

        say(f"compiling the DAA kernels ({COLD_COMPILE_TIME})")
        t0 = time.monotonic()
        from daa_sil.daa import kernels  # lazy: start-up time

        kernels.get().search_into.compile()
        say(f"DAA kernels ready ({time.monotonic() - t0:.0f} s)")
    if args.maps is not None:
        from daa_sil import waitmap  # lazy: start-up time

        say("building the wait maps")
        t0 = time.monotonic()
        shown = [0.0]

        def progress(frac: float) -> None:
            if frac >= shown[0] + MAP_PROGRESS_STEP and frac < 1.0:
                shown[0] = frac
                say(f"wait maps {100 * frac:.0f} %")

        waitmap.family_for(args.maps, preset="paper", progress=progress, horizon=args.horizon)
        say(f"wait maps ready ({time.monotonic() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
