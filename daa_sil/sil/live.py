"""The live step feed: one step-log row per UDP datagram on loopback, vehicle -> Rerun recorder.

``daa-vehicle --live udp:127.0.0.1:PORT`` publishes each step's step-log row (the row the step log
gets, ``docs/architecture.md`` "Step log schema") the moment the step is done, fire-and-forget;
the :class:`~daa_sil.viz.recorder.BackgroundRecorder` of ``daa-sil run`` reads them and logs each
row with :meth:`daa_sil.viz.EncounterLogger.log_step`, so a person watching sees the encounter as
it plays. Nothing here can block or stop the vehicle: sending is non-blocking, every failure is
counted and ignored, and a lost datagram is backfilled from the step log at the end.

* :func:`encode_row` / :func:`decode_row` -- the wire format (no I/O): ``MAGIC`` followed by the
  row as compact JSON with sorted keys (floats round-trip exactly; NaN is the JSON extension
  ``NaN``). ``decode_row`` checks the shape and raises :class:`LiveRecordError` for anything else.
* :class:`LiveFeed` -- the receiver's state (no I/O): ``feed(datagram)`` returns the row to log or
  None, counting bad and out-of-order datagrams; :meth:`LiveFeed.missing` lists the step-log rows
  that never arrived or arrived different (the recorder backfills those).
* :class:`LiveSender` -- the vehicle's non-blocking sender (binds 127.0.0.1 only).
* :func:`parse_live_address` -- ``udp:127.0.0.1:PORT`` (loopback only, else UsageError).
"""

from __future__ import annotations

import json
import math
import socket
from dataclasses import dataclass, field
from typing import Any, Mapping

from daa_sil.errors import UsageError
from daa_sil.steplog import BAND_COLUMNS, INTRUDER_COLUMNS, STEP_COLUMNS, VOCAB

#: first bytes of every datagram (format version 1)
MAGIC = b"DAASIL-STEP1 "
#: larger rows are not sent (counted as ``too_big``; the step log backfills them)
MAX_DATAGRAM = 60_000
LIVE_HOST = "127.0.0.1"

_LISTS = frozenset(INTRUDER_COLUMNS) | frozenset(BAND_COLUMNS)
_STRINGS = frozenset(k for k in VOCAB if k not in _LISTS)
_KNOWN = frozenset(STEP_COLUMNS)


class LiveRecordError(ValueError):
    """A datagram that is not a step record of this format."""


def _plain(v: Any) -> Any:
    """numpy scalars/arrays -> Python values (the vehicle's rows are plain already)."""
    if hasattr(v, "tolist"):
        return v.tolist()
    raise TypeError(f"not JSON serialisable: {type(v).__name__}")


def encode_row(row: Mapping[str, Any]) -> bytes:
    """One step-log row (column name -> value) as a datagram."""
    return MAGIC + json.dumps(row, separators=(",", ":"), sort_keys=True, default=_plain).encode()


def _number(v: Any) -> bool:
    """A numeric cell: number, bool or null (missing)."""
    return v is None or isinstance(v, (int, float))


def decode_row(data: bytes) -> dict[str, Any]:
    """The row of a datagram made by :func:`encode_row`; LiveRecordError for anything else.

    Checked: the magic, a JSON object, an integer ``step`` >= 0, a finite number ``t``, every other
    known column of the right kind (number/bool/null, string, or list of those); unknown keys are
    dropped (a newer vehicle may send more columns).
    """
    if not isinstance(data, (bytes, bytearray, memoryview)) or not bytes(data[:len(MAGIC)]) == MAGIC:
        raise LiveRecordError("not a daa-sil step record (bad magic)")
    try:
        row = json.loads(bytes(data[len(MAGIC):]))
    except (ValueError, UnicodeDecodeError, RecursionError) as exc:
        raise LiveRecordError(f"not JSON: {exc}") from None
    if not isinstance(row, dict):
        raise LiveRecordError("not a JSON object")
    step, t = row.get("step"), row.get("t")
    if not isinstance(step, int) or isinstance(step, bool) or step < 0:
        raise LiveRecordError("no integer step >= 0")
    if not isinstance(t, (int, float)) or isinstance(t, bool) or not math.isfinite(t):
        raise LiveRecordError("no finite time t")
    out: dict[str, Any] = {}
    for k, v in row.items():
        if k not in _KNOWN:
            continue
        if k in _LISTS:
            kind = str if k == "bands_trk_region" else None
            if not isinstance(v, list) or not all(isinstance(x, str) if kind else _number(x) for x in v):
                raise LiveRecordError(f"column {k!r} is not a list of the right kind")
        elif k in _STRINGS:
            if not isinstance(v, str):
                raise LiveRecordError(f"column {k!r} is not a string")
        elif not _number(v):
            raise LiveRecordError(f"column {k!r} is not a number")
        out[k] = v
    return out


def parse_live_address(spec: str, option: str = "--live") -> tuple[str, int]:
    """``udp:127.0.0.1:PORT`` -> ``("127.0.0.1", PORT)``; the feed never leaves the machine."""
    parts = str(spec).split(":")
    if len(parts) != 3 or parts[0] != "udp" or not parts[2].isdigit():
        raise UsageError(f"{option} {spec!r} should look like udp:127.0.0.1:PORT")
    host, port = parts[1], int(parts[2])
    if host not in (LIVE_HOST, "localhost"):
        raise UsageError(f"{option} {spec!r}: the live feed is loopback only (udp:127.0.0.1:PORT)")
    if not 1 <= port <= 65535:
        raise UsageError(f"{option} {spec!r}: port must be within 1..65535")
    return LIVE_HOST, port


@dataclass
class SenderStats:
    sent: int = 0
    errors: int = 0  #: encoding or socket errors (buffer full, nobody listening, ...)
    too_big: int = 0


class LiveSender:
    """Fire-and-forget sender of step rows to ``udp:127.0.0.1:PORT`` (never blocks, never raises
    after construction)."""

    def __init__(self, address: str):
        self.address = parse_live_address(address)
        self.stats = SenderStats()
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setblocking(False)
        self.sock.bind((LIVE_HOST, 0))

    def send(self, row: Mapping[str, Any]) -> bool:
        """Send one row; True if the datagram left (not that anybody got it)."""
        try:
            data = encode_row(row)
        except (TypeError, ValueError):
            self.stats.errors += 1
            return False
        if len(data) > MAX_DATAGRAM:
            self.stats.too_big += 1
            return False
        try:
            self.sock.sendto(data, self.address)
        except OSError:  # buffer full (non-blocking), ECONNREFUSED from an earlier ICMP, ...
            self.stats.errors += 1
            return False
        self.stats.sent += 1
        return True

    def close(self) -> None:
        try:
            self.sock.close()
        except OSError:
            pass


@dataclass
class LiveFeed:
    """Receiver state: which rows to log, what was bad; :meth:`missing` for the backfill."""

    received: int = 0
    bad: int = 0  #: not a step record
    stale: int = 0  #: a step not after the last one logged (duplicate, reordered)
    last_step: int = -1
    rows: dict = field(default_factory=dict)  #: step -> the datagram's payload (for :meth:`missing`)

    @property
    def accepted(self) -> int:
        return len(self.rows)

    def feed(self, data: bytes) -> "dict[str, Any] | None":
        """The row to log now, or None (bad or out of order; counted)."""
        self.received += 1
        try:
            row = decode_row(data)
        except LiveRecordError:
            self.bad += 1
            return None
        if row["step"] <= self.last_step:
            self.stale += 1
            return None
        self.last_step = row["step"]
        self.rows[row["step"]] = encode_row(row)
        return row

    def missing(self, table) -> list[int]:
        """Row indices of the step log ``table`` (one encounter, step order) that were not logged
        live exactly as they are in the table (never arrived, or arrived different)."""
        cols = [c for c in table.column_names if c in _KNOWN]
        rows = table.select(cols).to_pylist()
        out = []
        for i, r in enumerate(rows):
            got = self.rows.get(r.get("step"))
            if got is None or got != encode_row(r):
                out.append(i)
        return out

    def counters(self) -> dict:
        return {"received": self.received, "logged": self.accepted, "bad": self.bad, "stale": self.stale}
