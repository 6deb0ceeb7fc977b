"""The Rerun viewer's default ports and the check that they are free (light: no Rerun, no Parquet).

The commands that can serve a recording (``viz steplog|replay``, ``run``, ``demo``) register their
``--serve-web`` options from here, so ``daa-sil run`` does not import the viewer code to build its
parser."""

from __future__ import annotations

import socket

from daa_sil.errors import UsageError

#: the Rerun viewer a run spawns (gRPC), the web viewer's gRPC proxy and its HTTP page
SPAWN_PORT, WEB_GRPC_PORT, WEB_HTTP_PORT = 9876, 9877, 9090


def check_web_ports(bind: str, ports: "dict[str, int]") -> None:
    """UsageError (one line, naming the flag) if one of ``ports`` (flag -> TCP port) cannot be bound on
    ``bind`` now, as the web viewer will (SO_REUSEADDR, like its server)."""
    family = socket.AF_INET6 if ":" in bind else socket.AF_INET
    for flag, port in ports.items():
        with socket.socket(family, socket.SOCK_STREAM) as sk:
            sk.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            try:
                sk.bind((bind, int(port)))
            except OSError as exc:
                raise UsageError(f"{flag} {port}: cannot serve the web viewer on {bind}:{port} "
                                 f"({exc.strerror or exc}); choose a free port with {flag}") from None


def add_web_viewer_arguments(g, serve_help: str) -> None:
    """``--serve-web``, ``--bind``, ``--web-port``, ``--grpc-port`` (``viz steplog|replay``, ``run``, ``demo``)."""
    g.add_argument("--serve-web", action="store_true", help=serve_help)
    g.add_argument("--bind", default="127.0.0.1", help="address of the web viewer (default 127.0.0.1)")
    g.add_argument("--web-port", type=int, default=WEB_HTTP_PORT,
                   help=f"web viewer HTTP port (default {WEB_HTTP_PORT})")
    g.add_argument("--grpc-port", type=int, default=WEB_GRPC_PORT,
                   help=f"web viewer gRPC port (default {WEB_GRPC_PORT})")


def check_web_viewer_arguments(args) -> None:
    """The ports are TCP ports and, with ``--serve-web``, free on ``--bind`` (UsageError, one line)."""
    for name in ("web_port", "grpc_port"):
        port = getattr(args, name)
        if not 1 <= port <= 65535:
            raise UsageError(f"--{name.replace('_', '-')} must be a TCP port 1..65535, got {port}")
    if args.serve_web:
        check_web_ports(args.bind, {"--grpc-port": args.grpc_port, "--web-port": args.web_port})


__all__ = ["SPAWN_PORT", "WEB_GRPC_PORT", "WEB_HTTP_PORT", "check_web_ports", "add_web_viewer_arguments",
           "check_web_viewer_arguments"]
