"""Where a recording goes (:class:`SinkOptions`): ``.rrd`` file, native viewer, gRPC viewer, web viewer;
:class:`Recording` attaches a ``RecordingStream`` to them. Ports are TCP ports, timeouts s."""

from __future__ import annotations

import atexit
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.parse
from dataclasses import dataclass
from pathlib import Path

from ..errors import OutputError, UsageError
from ..sil.children import spawn
from ..sil.web_ports import SPAWN_PORT, WEB_GRPC_PORT, WEB_HTTP_PORT, check_web_ports  # noqa: F401 (re-exported)
from .warning import warn_viz

APP_ID = "daa_sil"
#: default ports: spawned native viewer (Rerun's default), web viewer's gRPC proxy, web viewer HTTP


@dataclass
class SinkOptions:
    """Where a recording goes. All off = visualisation disabled (Rerun is not touched)."""

    rrd: "str | os.PathLike | None" = None  #: write an .rrd file (atomically, on close)
    spawn: bool = False  #: start the native viewer (needs a display)
    connect: "str | None" = None  #: gRPC URL of a running viewer, e.g. rerun+http://127.0.0.1:9876/proxy
    serve_web: bool = False  #: start the web viewer (the rerun binary) on ``bind``
    bind: str = "127.0.0.1"
    web_port: int = WEB_HTTP_PORT
    grpc_port: int = WEB_GRPC_PORT
    spawn_port: int = SPAWN_PORT
    overwrite: bool = False  #: replace an existing .rrd
    deterministic: bool = False  #: ChunkBatcherConfig.NEVER (identical files run to run)
    app_id: str = APP_ID
    #: where the .rrd is written before the atomic rename (default: a fresh name next to ``rrd``); a
    #: :class:`BackgroundRecorder` picks it so that its owner can remove it if the helper is killed
    rrd_tmp: "str | os.PathLike | None" = None

    @property
    def enabled(self) -> bool:
        return bool(self.rrd or self.spawn or self.connect or self.serve_web)


def has_display() -> bool:
    """True if a native window can be opened (always on macOS/Windows; DISPLAY/WAYLAND elsewhere)."""
    if sys.platform == "darwin" or os.name == "nt":
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY") or os.environ.get("WAYLAND_SOCKET"))


def url_host_port(url: str) -> tuple[str, int]:
    """Host and port of a Rerun gRPC URL (the spawn port if it has none); :class:`UsageError` if it is not one."""
    u = urllib.parse.urlparse(url)
    if not u.scheme.startswith("rerun") or not u.hostname:
        raise UsageError(f"--connect URL {url!r} is not a Rerun gRPC URL like rerun+http://127.0.0.1:9876/proxy")
    return u.hostname, u.port or SPAWN_PORT


def port_open(host: str, port: int, timeout: float = 0.5) -> bool:
    """True if a TCP connection to ``host:port`` succeeds within ``timeout`` s."""
    try:
        with socket.create_connection((host, port), timeout=timeout):
            return True
    except OSError:
        return False


def rerun_binary() -> str:
    """Path of the real rerun viewer binary (not the Python wrapper script)."""
    import rerun_cli  # lazy: start-up time

    exe = "rerun.exe" if os.name == "nt" else "rerun"
    return str(Path(rerun_cli.__file__).parent / exe)


class WebServer:
    """The rerun binary serving the web viewer and a gRPC proxy on ``bind`` (own process group; it
    dies with this process, also on SIGKILL: :func:`daa_sil.sil.children.spawn`)."""

    def __init__(self, bind: str = "127.0.0.1", grpc_port: int = WEB_GRPC_PORT, web_port: int = WEB_HTTP_PORT,
                 rrd: "str | None" = None, startup_s: float = 20.0):
        self.bind, self.grpc_port, self.web_port = bind, grpc_port, web_port
        host = "127.0.0.1" if bind in ("0.0.0.0", "::") else bind
        self.grpc_url = f"rerun+http://{host}:{grpc_port}/proxy"
        self.url = f"http://{host}:{web_port}/?url={urllib.parse.quote(self.grpc_url, safe='')}"
        for port in (grpc_port, web_port):
            if port_open(host, port, 0.2):
                raise OSError(f"port {port} on {host} is already in use")
        cmd = [rerun_binary(), "--serve-web", "--bind", bind, "--port", str(grpc_port),
               "--web-viewer-port", str(web_port)] + ([str(rrd)] if rrd else [])
        # dies with us, also on SIGKILL (daa_sil.sil.children); own group, stopped by stop()
        self.proc = spawn(cmd, "rerun", python=False, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                          stderr=subprocess.DEVNULL, start_new_session=True)
        atexit.register(self.stop)
        deadline = time.monotonic() + startup_s
        while not (port_open(host, grpc_port) and port_open(host, web_port)):
            if self.proc.poll() is not None or time.monotonic() > deadline:
                self.stop()
                raise OSError(f"the rerun web viewer did not start on {host}:{grpc_port}/{web_port}")
            time.sleep(0.1)

    def alive(self) -> bool:
        return self.proc.poll() is None

    def stop(self) -> None:
        """Terminate the server's process group (SIGTERM, then SIGKILL after 5 s)."""
        if self.proc.poll() is not None:
            return
        try:
            os.killpg(self.proc.pid, signal.SIGTERM)
            self.proc.wait(timeout=5.0)
        except subprocess.TimeoutExpired:
            os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait()
        except ProcessLookupError:
            pass


def check_rrd_path(path: "str | os.PathLike", overwrite: bool = False) -> Path:
    """``path`` as a Path if an .rrd can be written there; OutputError naming the problem otherwise."""
    rrd = Path(path)
    if rrd.is_dir():
        raise OutputError(f"{rrd} is a directory, not an .rrd file path")
    if rrd.exists() and not overwrite:
        raise OutputError(f"{rrd} exists; refusing to overwrite (use --force or another path)")
    parent = rrd.parent
    if not parent.is_dir() or not os.access(parent, os.W_OK):
        raise OutputError(f"cannot write {rrd}: directory {parent} is missing or not writable")
    return rrd


class Recording:
    """A ``RecordingStream`` attached to the sinks of :class:`SinkOptions` (file, viewer, web).

    Raises only for a bad explicit request (an .rrd that exists without ``overwrite``, an unwritable
    directory, a malformed ``connect`` URL); everything else that goes wrong is a :class:`VizWarning`
    and leaves ``rec`` None (disabled).
    """

    def __init__(self, sinks: "SinkOptions | None" = None, recording_id: "str | None" = None, blueprint_=None):
        self.sinks = sinks or SinkOptions()
        self.rec = None
        self.web: "WebServer | None" = None
        self.rrd_path: "Path | None" = None
        self._tmp: "Path | None" = None
        self._closed = False
        if self.sinks.rrd:
            self.rrd_path = check_rrd_path(self.sinks.rrd, self.sinks.overwrite)
        if self.sinks.connect:
            url_host_port(self.sinks.connect)  # a malformed URL is a usage error, not a missing viewer
        if not self.sinks.enabled:
            return
        try:
            self._open(recording_id, blueprint_)
        except Exception as exc:  # visualisation must never stop the caller
            warn_viz(f"Rerun logging disabled: {type(exc).__name__}: {exc}")
            self._discard()

    def _open(self, recording_id, blueprint_) -> None:
        import rerun as rr  # lazy: start-up time

        o = self.sinks
        batcher = rr.ChunkBatcherConfig.NEVER() if o.deterministic else None
        rec = rr.RecordingStream(o.app_id, recording_id=recording_id, batcher_config=batcher)
        if not rec.is_enabled():
            warn_viz("Rerun is disabled in the environment (RERUN=off); no visualisation is written")
            return
        rec.set_log_time_enabled(False)
        sinks: list = []
        if self.rrd_path is not None:
            if o.rrd_tmp is not None:
                self._tmp = Path(o.rrd_tmp)
            else:
                fd, tmp = tempfile.mkstemp(prefix=f".{self.rrd_path.name}.", suffix=".tmp", dir=self.rrd_path.parent)
                os.close(fd)
                self._tmp = Path(tmp)
            sinks.append(rr.FileSink(str(self._tmp)))
        if o.connect:
            host, port = url_host_port(o.connect)
            if port_open(host, port):
                sinks.append(rr.GrpcSink(o.connect))
            else:
                warn_viz(f"no Rerun viewer at {o.connect}; live view disabled")
        if o.spawn:
            if not has_display():
                warn_viz("--spawn-viewer needs a display (DISPLAY/WAYLAND_DISPLAY unset); live view skipped "
                      "(use --serve-web or --rrd instead)")
            else:
                try:
                    rec.spawn(port=o.spawn_port, connect=False)
                    sinks.append(rr.GrpcSink(f"rerun+http://127.0.0.1:{o.spawn_port}/proxy"))
                except Exception as exc:
                    warn_viz(f"could not spawn the Rerun viewer: {exc}")
        if o.serve_web:
            try:
                self.web = WebServer(o.bind, o.grpc_port, o.web_port)
                sinks.append(rr.GrpcSink(self.web.grpc_url))
            except Exception as exc:
                warn_viz(f"could not start the Rerun web viewer: {exc}")
        if not sinks:
            return
        rec.set_sinks(*sinks, default_blueprint=blueprint_)
        self.rec = rec

    def _discard(self) -> None:
        self.rec = None
        if self._tmp is not None:
            self._tmp.unlink(missing_ok=True)
        if self.web is not None:
            self.web.stop()

    def close(self, keep_serving: bool = False, commit: bool = True) -> "Path | None":
        """Flush, disconnect, move the .rrd into place (unless ``commit`` is False); return its path."""
        if self._closed:
            return self.rrd_path if self.rrd_path is not None and self.rrd_path.exists() and commit else None
        self._closed = True
        written = None
        if self.rec is not None:
            try:
                self.rec.flush()
                self.rec.disconnect()
            except Exception as exc:
                warn_viz(f"Rerun flush failed: {exc}")
                commit = False
            if commit and self._tmp is not None and self._tmp.exists() and self._tmp.stat().st_size > 0:
                try:
                    with open(self._tmp, "rb+") as fh:
                        os.fsync(fh.fileno())
                    umask = os.umask(0)
                    os.umask(umask)
                    os.chmod(self._tmp, 0o666 & ~umask)  # mkstemp makes 0600; a normal output file
                    os.replace(self._tmp, self.rrd_path)
                    written = self.rrd_path
                except OSError as exc:
                    warn_viz(f"cannot write {self.rrd_path}: {exc.strerror or exc}")
        if self._tmp is not None:
            self._tmp.unlink(missing_ok=True)
        if not keep_serving and self.web is not None:
            self.web.stop()
        return written
