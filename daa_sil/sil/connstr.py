"""Connection strings as MAVProxy / mavutil users write them: ``udpin:``, ``udpout:``, ``udp:``, ``tcpin:``.

* ``udpin:HOST:PORT`` -- **listen** on HOST:PORT (and answer whoever sends to us);
* ``udpout:HOST:PORT`` -- **send** to HOST:PORT (from an OS-chosen local port unless told otherwise);
* ``udp:HOST:PORT`` (or bare ``HOST:PORT``) -- the option's own role: a local-socket option
  (``--listen``) listens, a destination option (``--out``, ``--vehicle``, ``--tap``) sends. This is
  how MAVProxy reads ``--master`` (listens) and ``--out`` (sends);
* ``tcpin:HOST:PORT`` -- a **TCP server** on HOST:PORT (as ArduPilot SITL's 5760), for the options
  that allow it (``allow_tcp``: the vehicle's ``--out``).

Anything else (``tcp:`` / ``tcpout:`` clients, ``serial:``, a missing port, ...) is a one-line
:class:`UsageError` naming the option, the text and what is allowed. :func:`parse_connection` returns a
:class:`Connection`; the address parsing itself is :func:`daa_sil.sil.endpoint.parse_udp_address`.
"""

from __future__ import annotations

from typing import NamedTuple

from daa_sil.errors import UsageError
from .endpoint import Address, parse_udp_address

LISTEN, SEND = "listen", "send"
UDP, TCP = "udp", "tcp"
_SCHEME_ROLE = {"udpin": LISTEN, "udpout": SEND}
#: TCP client schemes (MAVProxy's ``--master tcp:``): refused, with what to use instead
_TCP_CLIENT = ("tcp", "tcpout")


class Connection(NamedTuple):
    """A parsed connection string: ``role`` is ``"listen"`` or ``"send"``; ``addr`` ``(host, port)``;
    ``transport`` ``"udp"`` or ``"tcp"`` (a ``tcpin:`` server)."""

    role: str
    addr: Address
    text: str
    transport: str = UDP

    @property
    def listens(self) -> bool:
        return self.role == LISTEN

    @property
    def tcp(self) -> bool:
        return self.transport == TCP


def parse_connection(text: str, option: str, default_role: str, *, allow: "tuple[str, ...]" = (LISTEN, SEND),
                     allow_tcp: bool = False) -> Connection:
    """Parse ``text`` given to ``option`` whose bare ``udp:`` role is ``default_role``.

    ``allow`` lists the roles the option accepts (e.g. ``--listen`` only ``listen``): a string whose
    scheme asks for another role is a one-line error saying which schemes fit. A listening address
    may use port 0 (OS-chosen); a destination may not. ``allow_tcp``: ``tcpin:HOST:PORT`` (a TCP
    server) is accepted too.
    """
    if default_role not in (LISTEN, SEND):
        raise ValueError(f"default_role must be {LISTEN!r} or {SEND!r}")
    s = str(text).strip()
    scheme, sep, rest = s.partition(":")
    if sep and scheme.lower() == "tcpin":
        if not allow_tcp:
            raise UsageError(f"{option}: {text!r} is a TCP server; {option} takes UDP only (udp:HOST:PORT, "
                             f"udpin:HOST:PORT or udpout:HOST:PORT); tcpin: serves ground stations from "
                             f"daa-vehicle --out")
        return Connection(LISTEN, parse_udp_address(rest, option, allow_port_zero=True), s, TCP)
    if sep and scheme.lower() in _TCP_CLIENT and allow_tcp:
        raise UsageError(f"{option}: {text!r} would connect out as a TCP client; the vehicle serves TCP "
                         f"clients instead: tcpin:HOST:PORT (as SITL's 5760: mavproxy.py --master tcp:HOST:PORT)")
    role = _SCHEME_ROLE.get(scheme.lower(), default_role) if sep else default_role
    if role not in allow:
        fits = ", ".join(f"{k}:" for k, v in (("udp", default_role), *_SCHEME_ROLE.items()) if v in allow)
        what = "listens" if role == LISTEN else "sends"
        raise UsageError(f"{option}: {text!r} {what}, but {option} must "
                         f"{'listen' if LISTEN in allow else 'send'}; use {fits}HOST:PORT")
    addr = parse_udp_address(s, option, allow_port_zero=(role == LISTEN))
    return Connection(role, addr, s)


def describe(conn: Connection, port: "int | None" = None) -> str:
    """``udpin:127.0.0.1:14550`` / ``udpout:127.0.0.1:14550`` / ``tcpin:127.0.0.1:5760`` (what the string does,
    unambiguously); ``port``: the port actually bound, if the string asked for port 0."""
    host, p = conn.addr
    h = f"[{host}]" if ":" in host else host
    scheme = "tcpin" if conn.tcp else "udpin" if conn.listens else "udpout"
    return f"{scheme}:{h}:{p if not port else port}"
