"""Connection strings as MAVProxy / mavutil users write them: ``udpin:``, ``udpout:``, ``udp:``.

* ``udpin:HOST:PORT`` -- **listen** on HOST:PORT (and answer whoever sends to us);
* ``udpout:HOST:PORT`` -- **send** to HOST:PORT (from an OS-chosen local port unless told otherwise);
* ``udp:HOST:PORT`` (or bare ``HOST:PORT``) -- the option's own role: a local-socket option
  (``--listen``) listens, a destination option (``--out``, ``--vehicle``, ``--tap``) sends. This is
  how MAVProxy reads ``--master`` (listens) and ``--out`` (sends).

Anything else (``tcp:``, ``serial:``, a missing port, ...) is a one-line :class:`UsageError` naming
the option, the text and what is allowed. :func:`parse_connection` returns a :class:`Connection`;
the address parsing itself is :func:`daa_sil.sil.endpoint.parse_udp_address`.
"""

from __future__ import annotations

from typing import NamedTuple

from daa_sil.errors import UsageError
from .endpoint import Address, parse_udp_address

LISTEN, SEND = "listen", "send"
_SCHEME_ROLE = {"udpin": LISTEN, "udpout": SEND}


class Connection(NamedTuple):
    """A parsed connection string: ``role`` is ``"listen"`` or ``"send"``; ``addr`` ``(host, port)``."""

    role: str
    addr: Address
    text: str

    @property
    def listens(self) -> bool:
        return self.role == LISTEN


def parse_connection(text: str, option: str, default_role: str, *, allow: "tuple[str, ...]" = (LISTEN, SEND)
                     ) -> Connection:
    """Parse ``text`` given to ``option`` whose bare ``udp:`` role is ``default_role``.

    ``allow`` lists the roles the option accepts (e.g. ``--listen`` only ``listen``): a string whose
    scheme asks for another role is a one-line error saying which schemes fit. A listening address
    may use port 0 (OS-chosen); a destination may not.
    """
    if default_role not in (LISTEN, SEND):
        raise ValueError(f"default_role must be {LISTEN!r} or {SEND!r}")
    s = str(text).strip()
    scheme, sep, _ = s.partition(":")
    role = _SCHEME_ROLE.get(scheme.lower(), default_role) if sep else default_role
    if role not in allow:
        fits = ", ".join(f"{k}:" for k, v in (("udp", default_role), *_SCHEME_ROLE.items()) if v in allow)
        what = "listens" if role == LISTEN else "sends"
        raise UsageError(f"{option}: {text!r} {what}, but {option} must "
                         f"{'listen' if LISTEN in allow else 'send'}; use {fits}HOST:PORT")
    addr = parse_udp_address(s, option, allow_port_zero=(role == LISTEN))
    return Connection(role, addr, s)


def describe(conn: Connection) -> str:
    """``udpin:127.0.0.1:14550`` / ``udpout:127.0.0.1:14550`` (what the string does, unambiguously)."""
    host, port = conn.addr
    h = f"[{host}]" if ":" in host else host
    return f"{'udpin' if conn.listens else 'udpout'}:{h}:{port}"
