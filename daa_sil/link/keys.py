"""MAVLink 2 signing keys on disk: reading a key file and writing a new one.

A file of exactly 32 bytes is the raw key; anything else is a UTF-8 passphrase (surrounding
whitespace stripped, at least :data:`MIN_PASSPHRASE` characters) and the key is
``sha256(passphrase)``, the convention MAVProxy's ``signing setup`` uses. 32 bytes and a line break
(what ``echo`` or an editor leaves) is read by what the 32 bytes are: binary -> the raw key, the line
break ignored; printable text -> a passphrase; either way a warning says which. A key file readable by
group or others is read, with a warning. :func:`generate_key_file` writes 32 random bytes atomically
with mode 0600. The codec that signs with the key is :mod:`daa_sil.link.codec`.
"""

from __future__ import annotations

import hashlib
import os
import secrets
from pathlib import Path
from typing import Callable

from ..errors import FileFormatError, OutputError, UsageError
import tempfile

#: bytes in a MAVLink 2 signing key
KEY_LEN = 32
#: shortest passphrase a key file may hold (characters)
MIN_PASSPHRASE = 8


def key_from_passphrase(passphrase: str) -> bytes:
    """The 32-byte key ``sha256(passphrase)`` (MAVProxy's convention)."""
    if not passphrase:
        raise UsageError("signing passphrase must not be empty")
    return hashlib.sha256(passphrase.encode("utf-8")).digest()


def load_key(path: "str | os.PathLike", warn: "Callable[[str], None] | None" = None) -> bytes:
    """Read a key file (rules in the module docstring); ``warn`` gets one-line notes (default: none).

    Raises a one-line :class:`FileFormatError` for an unreadable, empty, non-UTF-8 file or a
    passphrase shorter than :data:`MIN_PASSPHRASE` characters.
    """
    p = Path(path)
    say = warn or (lambda _text: None)
    try:
        data = p.read_bytes()
        mode = p.stat().st_mode
    except OSError as exc:
        raise FileFormatError(f"cannot read signing key file {p}: {exc.strerror or exc}") from None
    if os.name == "posix" and mode & 0o044:
        say(f"signing key file {p} is readable by group or others (mode {mode & 0o777:04o}); "
            f"run: chmod 600 {p}")
    if len(data) == KEY_LEN:
        return data
    body = data[:-2] if data.endswith(b"\r\n") else data[:-1] if data.endswith(b"\n") else None
    if body is not None and len(body) == KEY_LEN:
        if not _printable(body):
            say(f"signing key file {p}: {KEY_LEN} raw bytes and a line break: the line break is ignored "
                f"(a raw key file is exactly {KEY_LEN} bytes)")
            return body
        say(f"signing key file {p}: {KEY_LEN} characters and a line break: read as a passphrase (key = "
            f"sha256 of the text); for a raw key write exactly {KEY_LEN} bytes")
    try:
        text = data.decode("utf-8").strip()
    except UnicodeDecodeError:
        raise FileFormatError(f"signing key file {p} is neither {KEY_LEN} raw bytes ({len(data)} bytes) "
                              "nor a UTF-8 passphrase") from None
    if not text:
        raise FileFormatError(f"signing key file {p} is empty")
    if len(text) < MIN_PASSPHRASE:
        raise FileFormatError(f"signing key file {p}: the passphrase has {len(text)} characters, at least "
                              f"{MIN_PASSPHRASE} are needed (or a raw key of exactly {KEY_LEN} bytes)")
    return key_from_passphrase(text)


def _printable(data: bytes) -> bool:
    """True if ``data`` is UTF-8 text of printable characters only (a typed passphrase, not random bytes)."""
    try:
        return data.decode("utf-8").isprintable()
    except UnicodeDecodeError:
        return False


def generate_key_file(path: "str | os.PathLike", overwrite: bool = False) -> bytes:
    """Write a new random 32-byte key to ``path`` atomically with mode 0600; returns the key.

    The key never exists on disk with wider permissions: it is written to a ``mkstemp`` file
    (created 0600) in the target directory, fsynced and renamed over ``path``.
    """

    target = Path(path)
    if not overwrite and target.exists():
        raise OutputError(f"{target} exists; refusing to overwrite (choose another path or remove it)")
    key = secrets.token_bytes(KEY_LEN)
    tmp = None
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent if str(target.parent) else ".")
        with os.fdopen(fd, "wb") as fh:
            os.fchmod(fh.fileno(), 0o600)
            fh.write(key)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, target)
        tmp = None
    except OSError as exc:
        raise OutputError(f"cannot write signing key file {target}: {exc.strerror or exc}") from None
    finally:
        if tmp is not None:
            try:
                os.unlink(tmp)
            except OSError:
                pass
    return key
