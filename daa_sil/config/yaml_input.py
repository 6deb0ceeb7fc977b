"""The one way daa-sil reads YAML: scenarios, ``--config`` and ``--groups`` files, grid files and the
package's own data files all go through :func:`read_yaml_text` and :func:`load_yaml` /
:func:`compose_yaml`.

YAML from a user is bounded before and while it is parsed, so that a hostile or mistaken file
costs a second at most and fails with one line (:class:`~daa_sil.errors.FileFormatError`, exit 2):

* :data:`MAX_BYTES` (64 KiB): the pure-Python parser reads 50-150 kB of YAML per second of CPU,
  so a 50 MB file parsed for minutes in gigabytes of memory; at 64 KiB the worst file we tried
  (65,536 bytes of nested flow lists) takes 1.3 s of CPU on a loaded machine; the largest YAML we
  ship is 10 kB (``daa_sil/data/paper_findings.yaml``), a scenario about 1 kB;
* :data:`MAX_DEPTH` (32 levels: a value counts one level below its container): PyYAML composes
  recursively, and a few hundred levels end in a RecursionError; a scenario nests 4 levels;
* :data:`MAX_NODES` (50,000 values, every alias counted as a copy of what it names): aliases let
  a file of 200 bytes describe a million values ("billion laughs");
* UTF-8 only; a NUL or other control character is named with its line, not reported as PyYAML's
  two-line "in <unicode string>, position N".

Only PyYAML's safe subset is constructed (no Python objects).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import yaml

from daa_sil.errors import FileFormatError

MAX_BYTES = 64 * 1024  #: largest YAML input, bytes
MAX_DEPTH = 32  #: deepest nesting of mappings and lists
MAX_NODES = 50_000  #: most values in one document, each alias counted as the values it names


class _Limit(Exception):
    """A bound of this module was exceeded at ``mark``."""

    def __init__(self, message: str, mark) -> None:
        super().__init__(message)
        self.mark = mark


class _BoundedLoader(yaml.SafeLoader):
    """SafeLoader that counts nesting depth and (alias-expanded) nodes as it composes."""

    def __init__(self, stream) -> None:
        super().__init__(stream)
        self._depth = 0
        self._nodes = 0
        self._sizes: dict[int, int] = {}

    def compose_node(self, parent, index):
        event = self.peek_event()
        if isinstance(event, yaml.AliasEvent):
            node = super().compose_node(parent, index)
            self._count(self._sizes.get(id(node), 1), event.start_mark)
            return node
        self._depth += 1
        if self._depth > MAX_DEPTH:
            raise _Limit(f"nested more than {MAX_DEPTH} levels deep", event.start_mark)
        start = self._nodes
        try:
            node = super().compose_node(parent, index)
        finally:
            self._depth -= 1
        self._count(1, event.start_mark)
        self._sizes[id(node)] = self._nodes - start
        return node

    def _count(self, n: int, mark) -> None:
        self._nodes += n
        if self._nodes > MAX_NODES:
            raise _Limit(f"more than {MAX_NODES:,} values (an alias counts as every value it names)", mark)


def read_yaml_text(path: "str | os.PathLike", what: str) -> str:
    """The text of a YAML file of kind ``what`` (e.g. ``"scenario"``), at most :data:`MAX_BYTES`,
    UTF-8. FileNotFoundError passes through (callers word it); every other problem is one-line
    FileFormatError."""
    p = Path(path)
    try:
        with open(p, "rb") as fh:
            data = fh.read(MAX_BYTES + 1)  # a FIFO or /dev/zero has no useful size: read at most this
            if len(data) > MAX_BYTES:
                try:
                    size = os.fstat(fh.fileno()).st_size
                except OSError:
                    size = 0
                size_text = f"{size:,} bytes" if size > MAX_BYTES else f"more than {MAX_BYTES:,} bytes"
                raise FileFormatError(f"{p}: {size_text}; a {what} file is at most {MAX_BYTES:,} bytes")
    except FileNotFoundError:
        raise
    except IsADirectoryError:
        raise FileFormatError(f"{p}: cannot read {what}: it is a directory") from None
    except OSError as exc:
        raise FileFormatError(f"{p}: cannot read {what}: {exc.strerror or exc}") from None
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise FileFormatError(f"{p}: cannot read {what}: not UTF-8 text (byte 0x{data[exc.start]:02x} at offset "
                              f"{exc.start})") from None


def _read_bounded(text: str, source: str, what: str, read: str):
    """``_BoundedLoader(text).<read>()`` (``get_single_node`` or ``get_single_data``) under the module's
    bounds; a YAML error or a bound reached becomes one FileFormatError line naming ``source``."""
    _check_size(text, source, what)
    loader = None
    try:
        loader = _BoundedLoader(text)  # checks for control characters already
        return getattr(loader, read)()
    except (yaml.YAMLError, _Limit, RecursionError) as exc:
        raise FileFormatError(_describe(exc, text, source, what)) from None
    finally:
        if loader is not None:
            loader.dispose()


def compose_yaml(text: str, source: str, what: str = "YAML document") -> "yaml.Node | None":
    """The node tree of one YAML document (with line marks), bounded as the module says; None for
    an empty document. One-line FileFormatError naming ``source`` and the line."""
    return _read_bounded(text, source, what, "get_single_node")


def load_yaml(text: str, source: str, what: str = "YAML document") -> Any:
    """The plain data (dicts, lists, str, int, float, bool, None, dates) of one YAML document,
    bounded as the module says. One-line FileFormatError naming ``source`` and the line."""
    return _read_bounded(text, source, what, "get_single_data")


def load_yaml_file(path: "str | os.PathLike", what: str) -> Any:
    """:func:`read_yaml_text` then :func:`load_yaml` (FileNotFoundError passes through)."""
    return load_yaml(read_yaml_text(path, what), str(path), what)


def _check_size(text: str, source: str, what: str) -> None:
    if len(text) > MAX_BYTES:  # characters >= bytes / 4; text given directly, not read from a file
        raise FileFormatError(f"{source}: {len(text):,} characters; a {what} file is at most {MAX_BYTES:,} bytes")


def _describe(exc: BaseException, text: str, source: str, what: str) -> str:
    """One line: ``source:line: problem``."""
    if isinstance(exc, _Limit):
        line = f":{exc.mark.line + 1}" if exc.mark is not None else ""
        return f"{source}{line}: {exc} (the limit for a {what} file)"
    if isinstance(exc, RecursionError):  # not expected below MAX_DEPTH; never a traceback
        return f"{source}: nested too deeply for a {what} file"
    if isinstance(exc, yaml.reader.ReaderError):
        line = text.count("\n", 0, exc.position) + 1 if isinstance(exc.position, int) else 0
        char = exc.character if isinstance(exc.character, int) else ord(str(exc.character)[:1] or "\0")
        return (f"{source}:{line}: not valid YAML: the control character U+{char:04X} is not allowed "
                f"(at character {exc.position})")
    mark = getattr(exc, "problem_mark", None)
    line = f":{mark.line + 1}" if mark is not None else ""
    problem = getattr(exc, "problem", None) or str(exc)
    return " ".join(f"{source}{line}: not valid YAML: {problem}".split())
