"""``daa-sil`` command-line entry point: ``daa-sil <noun> [<verb>] ...``.

Errors are for people: a :class:`daa_sil.errors.DaaSilError` prints one line
(``daa-sil: error: ...``) and exits with its code (2 for usage errors); argparse errors exit 2;
Ctrl-C exits 130. No tracebacks unless ``DAA_SIL_DEBUG=1``.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys

from . import __version__
from .commands._args import OneLineParser as _Parser
from .errors import DaaSilError

#: modules providing ``register(subparsers)``; order = order in ``--help``
COMMAND_MODULES = [
    "daa_sil.commands.config",
    "daa_sil.commands.geometry",
    "daa_sil.commands.daa",
    "daa_sil.commands.conformance",
    "daa_sil.commands.waitmap",
    "daa_sil.commands.shim",
    "daa_sil.commands.run",
    "daa_sil.commands.campaign",
    "daa_sil.commands.viz",
]
#: the commands each module registers (``daa-sil COMMAND ...`` imports only that module)
COMMANDS = {"config": "daa_sil.commands.config", "geometry": "daa_sil.commands.geometry",
            "daa": "daa_sil.commands.daa", "conformance": "daa_sil.commands.conformance",
            "waitmap": "daa_sil.commands.waitmap", "shim": "daa_sil.commands.shim", "run": "daa_sil.commands.run",
            "demo": "daa_sil.commands.run", "campaign": "daa_sil.commands.campaign", "viz": "daa_sil.commands.viz"}

EPILOG = """examples:
  daa-sil geometry --own 0,0,1000,0,55,0 --intruder 0,6000,1000,0,-100,0
  daa-sil geometry --own 0,0,1000,0,55,0 --intruder 0,6000,1000,0,-100,0 --preset paper --json

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


def main(argv: "list[str] | None" = None) -> int:
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
    except KeyboardInterrupt:
        print("daa-sil: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        return 0
    return int(rc or 0)


def run_guarded(prog: str, fn) -> int:
    """Run ``fn()`` for a console script named ``prog``: a DaaSilError becomes one line on stderr and
    its exit code, Ctrl-C exits 130 (tracebacks only with ``DAA_SIL_DEBUG=1``)."""
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
