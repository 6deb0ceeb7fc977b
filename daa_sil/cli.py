"""``daa-sil`` command-line entry point: ``daa-sil <noun> [<verb>] ...``.

Errors are for people: a :class:`daa_sil.errors.DaaSilError` prints one line
(``daa-sil: error: ...``) and exits with its code (2 for usage errors); argparse errors exit 2;
Ctrl-C exits 130. No tracebacks unless ``DAA_SIL_DEBUG=1``.
"""

from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys
import threading

from . import __version__
from .commands.common_args import OneLineParser as _Parser
from .errors import DaaSilError
from daa_sil.runtime.process_gc import freeze_at_exit

#: modules providing ``register(subparsers)``; order = order in ``--help``
COMMAND_MODULES = [
    "daa_sil.commands.config",
    "daa_sil.commands.geometry",
    "daa_sil.commands.daa",
    "daa_sil.commands.conformance",
    "daa_sil.commands.waitmap",
    "daa_sil.commands.shim",
    "daa_sil.commands.run",
    "daa_sil.commands.inject",
    "daa_sil.commands.campaign",
    "daa_sil.commands.viz",
]
#: the commands each module registers (``daa-sil COMMAND ...`` imports only that module)
COMMANDS = {"config": "daa_sil.commands.config", "geometry": "daa_sil.commands.geometry",
            "daa": "daa_sil.commands.daa", "conformance": "daa_sil.commands.conformance",
            "waitmap": "daa_sil.commands.waitmap", "shim": "daa_sil.commands.shim", "run": "daa_sil.commands.run",
            "demo": "daa_sil.commands.run", "inject": "daa_sil.commands.inject", "campaign": "daa_sil.commands.campaign",
            "viz": "daa_sil.commands.viz"}

EPILOG = """examples:
  # the demo: a head-on encounter, 4 s link delay, vehicle / delay shim / GCS over MAVLink
  daa-sil demo --out demo-out

  # any scenario through the three processes (lockstep), or in real time at 10x
  daa-sil run scenarios/head_on.yaml --out runs/head_on
  daa-sil run scenarios/crossing_left.yaml --clock realtime --speed 10 --out runs/crossing

  # the fast-time study: a quick campaign of two groups, then its report
  daa-sil campaign run --groups B-2,ID-2 --encounters 200 --seed 7 --out runs/quick
  daa-sil campaign report runs/quick --out runs/quick/report

  # one geometry at a glance
  daa-sil geometry --own 0,0,1000,0,55,0 --intruder 0,6000,1000,0,-100,0

Every command has --help with examples. Units are SI (m, s, m/s) in the ENU frame unless a flag says otherwise.
"""


def build_parser(command: "str | None" = None) -> argparse.ArgumentParser:
    """The ``daa-sil`` parser with every command, or with ``command``'s module only (its commands:
    ``daa-sil run ...`` then imports neither the campaign nor the viewer modules)."""
    parser = _Parser(prog="daa-sil", description=__doc__.splitlines()[0] + "\n\n"
                     "MAVLink SIL bridge and fast-time study for UAS detect-and-avoid with a delayed remote pilot.",
                     epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action="version", version=f"daa-sil {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    for name in ([COMMANDS[command]] if command in COMMANDS else COMMAND_MODULES):
        importlib.import_module(name).register(sub)
    return parser


def _adopt(prog: "str | None") -> None:
    """Take the process name and parent watch of a child started by ``daa-sil run`` (or name a
    console script ``prog``): :func:`daa_sil.sil.children.adopt`."""
    from daa_sil.sil.children import NAME_ENV, PARENT_ENV, adopt  # lazy: start-up time

    if prog or NAME_ENV in os.environ or PARENT_ENV in os.environ:
        adopt(prog)


def _interrupted(prog: str, exc: KeyboardInterrupt, whole_process: bool = False) -> int:
    """One line for Ctrl-C / SIGTERM / SIGHUP (what was cut short, if the command said); exit 128 + signal.
    ``whole_process``: this is the process's own command (not a call from Python), so a further signal
    while the interpreter shuts down ends it at once (:func:`_end_on_further_signals`)."""
    from daa_sil.sil.children import interrupt_signum  # lazy: start-up time

    detail = str(exc) if str(exc).startswith("interrupted") else "interrupted"
    try:
        print(f"{prog}: {detail}", file=sys.stderr, flush=True)
    except OSError:  # a closed terminal (SIGHUP)
        pass
    code = 128 + interrupt_signum(exc)
    if whole_process:
        _end_on_further_signals(code)
    return code


def _end_on_further_signals(code: int) -> None:
    """After the interrupt's line the command has stopped its workers and children and the interpreter
    is shutting down: another Ctrl-C (a user pressing it twice) is ignored, instead of a traceback from
    the exit handler it would interrupt; SIGTERM or SIGHUP end the process at once with ``code``."""
    def end_now(signum, frame):
        os._exit(code)

    for name, handler in (("SIGINT", signal.SIG_IGN), ("SIGTERM", end_now), ("SIGHUP", end_now)):
        try:
            signal.signal(getattr(signal, name), handler)
        except (AttributeError, ValueError):  # no such signal here, or not the main thread
            pass


def _restore_ctrl_c() -> None:
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.default_int_handler)


def main(argv: "list[str] | None" = None) -> int:
    _adopt(None)
    freeze_at_exit()  # the interpreter's shutdown skips traversing numba's objects (daa_sil.runtime.process_gc)
    whole = argv is None  # the console script (not a call from Python, e.g. a test)
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(argv[0] if argv else None)
    try:
        args = parser.parse_args(argv)
        rc = args.func(args)
    except DaaSilError as exc:
        if os.environ.get("DAA_SIL_DEBUG"):
            raise
        print(f"daa-sil: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt as exc:
        code = _interrupted("daa-sil", exc, whole_process=whole)
        if not whole:  # a caller from Python gets its Ctrl-C back (signals_interrupt left it ignored)
            _restore_ctrl_c()
        return code
    except BrokenPipeError:
        return 0
    return int(rc or 0)


def run_guarded(prog: str, fn) -> int:
    """Run ``fn()`` for a console script named ``prog``: a DaaSilError becomes one line on stderr and
    its exit code, Ctrl-C exits 130 (tracebacks only with ``DAA_SIL_DEBUG=1``). The process is named
    ``prog`` (ps/pgrep) and, when ``daa-sil run`` started it, dies with its parent. Its exit is made cheap
    as :func:`main`'s (:func:`daa_sil.runtime.process_gc.freeze_at_exit`)."""
    _adopt(prog)
    freeze_at_exit()
    try:
        return int(fn() or 0)
    except DaaSilError as exc:
        if os.environ.get("DAA_SIL_DEBUG"):
            raise
        print(f"{prog}: error: {exc}", file=sys.stderr, flush=True)
        return exc.exit_code
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
