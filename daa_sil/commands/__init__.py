"""CLI sub-commands. Each module defines ``register(subparsers)`` adding its parser(s); the
parser's ``func`` attribute receives the parsed ``argparse.Namespace`` and returns an exit code.

Add a new command module to ``daa_sil.cli.COMMAND_MODULES`` and its command names to ``daa_sil.cli.COMMANDS``.
``common_args`` is not a command: it holds the argument helpers the commands and the node scripts
(``daa-vehicle``, ``daa-gcs``) share.
"""
