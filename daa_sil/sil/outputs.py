"""The vehicle's outputs: where its telemetry goes and whose messages it takes (``--out``, ``--tap``).

``daa-vehicle --out CONN[,rw]`` is repeatable, as ``--out`` of ArduPilot SITL and MAVProxy:

* the **first** ``--out`` is the pilot's link (named ``gcs``): the GCS, or the delay shim in front
  of it. Pilot commands, parameter and mode writes and the lockstep ticks travel on it;
* every further ``--out`` (named ``out2``, ``out3``, ... in the order given) and ``--tap`` (named
  ``tap``) is an **observer**: it gets the telemetry undelayed, with its own stream rates (its
  SET_MESSAGE_INTERVAL / REQUEST_DATA_STREAM change only its own stream), may read parameters and
  ask for messages, and is **read-only** unless marked writable: ``,rw`` after the connection
  string (``--out udp:127.0.0.1:14560,rw``; ``--tap-writable`` for the tap), which lets it write
  parameters and modes (applied undelayed). Pilot commands are taken from the first ``--out`` only:
  a command must cross the delayed link (the point of the simulation).

CONN is a connection string (:mod:`daa_sil.sil.connstr`): ``udp:`` / ``udpout:`` sends to HOST:PORT
from the vehicle's main socket (and takes replies from exactly that address); ``udpin:`` listens on
HOST:PORT and answers every ground station heard there in the last few seconds (pymavlink's ``udpin``
rule); ``tcpin:`` serves TCP clients on HOST:PORT (as SITL's 5760), each with its own rates. Every
ground station of an output has the output's rights. ``,ro`` says read-only explicitly. The first
``--out`` may not be marked: it is the pilot's, always writable.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

from daa_sil.errors import UsageError
from .connstr import SEND, Connection, parse_connection
from .endpoint import norm_host
import socket

#: name of the first --out (the pilot's link) and of --tap
PILOT_LINK, TAP = "gcs", "tap"
_MARKS = {"rw": True, "ro": False}


@dataclass(frozen=True)
class OutputSpec:
    """One output: ``name`` (``gcs``, ``tap``, ``out2``, ...), its connection, and whether it may write."""

    name: str
    conn: Connection
    writable: bool

    @property
    def listens(self) -> bool:
        return self.conn.listens

    @property
    def tcp(self) -> bool:
        return self.conn.tcp

    @cached_property
    def addr(self) -> "tuple[str, int]":
        """``(numeric host, port)``: where it sends (udp/udpout) or listens (udpin); resolved once (the
        vehicle reads it for every datagram it sends or takes)."""
        return norm_host(self.conn.addr[0]), self.conn.addr[1]


def split_mark(text: str, option: str) -> "tuple[str, bool | None]":
    """``"udp:127.0.0.1:14560,rw"`` -> ``("udp:127.0.0.1:14560", True)``; no mark -> ``(text, None)``."""
    s = str(text).strip()
    head, sep, mark = s.rpartition(",")
    if not sep:
        return s, None
    if mark.strip().lower() not in _MARKS:
        raise UsageError(f"{option} {text!r}: after the connection string only ',rw' (writable) or ',ro' "
                         f"(read-only, the default) may follow")
    return head.strip(), _MARKS[mark.strip().lower()]


def output_specs(outs: "list[str] | tuple[str, ...]", tap: "str | None" = None,
                 tap_writable: bool = False, option_of_extra: str = "--out") -> "list[OutputSpec]":
    """The outputs of ``--out`` (first = the pilot's link) and ``--tap``; one-line UsageError if malformed
    (a mark on the first ``--out``, two outputs at the same address, ...). ``option_of_extra``: the
    option the further outputs were given with, for messages (``daa-sil run --vehicle-out``)."""
    if not outs:
        raise UsageError("--out: at least one output (the GCS or the delay shim) is needed")
    specs: list[OutputSpec] = []
    for i, text in enumerate(outs):
        option = "--out" if i == 0 else option_of_extra
        conn_text, mark = split_mark(text, option)
        if i == 0 and mark is not None:
            raise UsageError(f"--out {text!r}: the first --out is the pilot's link and always writable; "
                             f"mark only the further outputs")
        specs.append(OutputSpec(PILOT_LINK if i == 0 else f"out{i + 1}",
                                parse_connection(conn_text, option, SEND, allow_tcp=True), bool(mark)))
    if tap is not None:
        specs.append(OutputSpec(TAP, parse_connection(tap, "--tap", SEND, allow=(SEND,)), bool(tap_writable)))
    seen: dict = {}
    for s in specs:
        key = (s.listens, s.conn.transport, s.addr)
        if key in seen:
            raise UsageError(f"{s.name} ({s.conn.text}) and {seen[key]} are the same address; give each output its own")
        seen[key] = s.name
    return specs


def check_listening(specs: "list[OutputSpec]", option: str = "--out") -> None:
    """Bind (and close at once) the port of every listening output (``udpin:`` / ``tcpin:``): a taken one is a
    one-line UsageError now, before a run starts any process or any work."""

    for s in specs:
        if not s.listens or s.addr[1] == 0:
            continue
        family = socket.AF_INET6 if ":" in s.addr[0] else socket.AF_INET
        sock = socket.socket(family, socket.SOCK_STREAM if s.tcp else socket.SOCK_DGRAM)
        try:
            if s.tcp:
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as the vehicle's server binds
            sock.bind(s.addr)
        except OSError as exc:
            raise UsageError(f"{option} {s.conn.text}: cannot listen there ({exc.strerror or exc}); is another vehicle "
                             f"or ground station using that port?") from None
        finally:
            sock.close()
