"""The ``--config PRESET|FILE`` option of every command that takes a run configuration.

Kept apart from :mod:`daa_sil.config.run_config` (which imports the configuration sections, the
readings and, through them, numpy) so that building a command's parser costs nothing: ``daa-sil
run`` starts its three processes sooner, and ``daa-vehicle`` / ``daa-gcs`` import the configuration
only when ``--config`` is given.
"""

from __future__ import annotations

import argparse

from daa_sil.config.choices import PRESET_NAMES
from daa_sil.config.settings import PRESET


def add_config_argument(p: argparse.ArgumentParser, default_help: str = PRESET.default) -> None:
    """The ``--config PRESET|FILE`` option of a command."""
    p.add_argument("--config", default=None, metavar="PRESET|FILE",
                   help=f"run configuration: a preset ({', '.join(PRESET_NAMES)}) or a YAML file "
                        f"('daa-sil config show {default_help}' prints one to start from); explicit flags override it")


def config_of(spec: "str | None"):
    """The :class:`~daa_sil.config.run_config.RunConfig` of a ``--config`` value (one-line
    :class:`~daa_sil.errors.UsageError` if bad), or None without one; the configuration modules are
    imported only then."""
    if not spec:
        return None
    from daa_sil.config.run_config import load_config  # lazy: start-up time

    return load_config(spec)
