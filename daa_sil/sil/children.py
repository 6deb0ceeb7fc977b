"""Every process daa-sil starts dies with it, has a name a user can find, and SIGTERM/SIGHUP stop
a command the way Ctrl-C does.

* :func:`spawn` is the one way we start a child (the vehicle, shim and GCS of ``daa-sil run``,
  the Rerun web viewer, the recorder helper in exec mode). On Linux the child arms
  ``PR_SET_PDEATHSIG`` (SIGTERM) before ``exec``, so the kernel signals it when its parent dies --
  also on SIGKILL of the parent. The signal comes when the *thread* that forked exits, so
  :func:`spawn` refuses to run outside the main thread. Between ``fork`` and the ``prctl`` the
  parent may already have died: the child compares ``getppid()`` with the parent it was forked
  from and exits if they differ.
* Elsewhere (or with ``DAA_SIL_PARENT_WATCH=poll``, which the tests use to exercise it on Linux)
  a Python child polls ``getppid()`` every :data:`WATCH_POLL_S` in a daemon thread
  (:func:`adopt`) and sends itself SIGTERM (SIGKILL :data:`WATCH_KILL_S` later) when the parent
  is gone; a non-Python child is started under a small watchdog (``python -m
  daa_sil.sil.children watch PPID NAME -- ARGV``) that does the same for it.
* Names: a Python child calls :func:`adopt` first thing (``daa_sil.cli.main`` and
  :func:`daa_sil.cli.run_guarded` do); it takes the name :func:`spawn` put in its environment and
  sets it with ``prctl(PR_SET_NAME)`` (at most 15 bytes: ``daa-vehicle``, ``daa-gcs``,
  ``daa-shim``, ``daa-recorder``), so ``pgrep daa-gcs`` and ``ps -e`` find it. ``exec`` resets the
  name, which is why the child sets it itself. A binary we did not write keeps its own name
  (``rerun``).
* :func:`signals_interrupt`: inside it SIGTERM and SIGHUP raise :class:`Interrupted`, a
  ``KeyboardInterrupt``, so a ``timeout``, a CI cancel or a closed terminal stop the children and
  write the partial results exactly as Ctrl-C does; the command then exits 128 + the signal number.
"""

from __future__ import annotations

import ctypes
import functools
import os
import signal
import subprocess
import sys
import threading
import time
from contextlib import contextmanager
from typing import Callable, Iterator, Sequence


#: ``prctl`` options (linux/prctl.h)
PR_SET_PDEATHSIG = 1
PR_GET_PDEATHSIG = 2
PR_SET_NAME = 15
#: the kernel keeps at most 15 bytes of a process name (16 with the NUL)
NAME_MAX_BYTES = 15
#: the signal a child gets when its parent dies (our children flush their outputs on it)
DEATH_SIGNAL = signal.SIGTERM
#: environment handed from :func:`spawn` to :func:`adopt` (removed by the child, so it is not inherited)
PARENT_ENV = "DAA_SIL_PARENT_PID"
NAME_ENV = "DAA_SIL_PROCESS_NAME"
#: ``prctl`` (Linux default) or ``poll`` (the portable way; forced by setting it, e.g. in tests)
WATCH_ENV = "DAA_SIL_PARENT_WATCH"
#: how often a polling child looks at its parent, s; how long it allows itself to stop before SIGKILL, s
WATCH_POLL_S = 0.2
WATCH_KILL_S = 5.0
#: signals that stop a command as Ctrl-C does
INTERRUPT_SIGNALS = (signal.SIGTERM, signal.SIGHUP) if hasattr(signal, "SIGHUP") else (signal.SIGTERM,)


class Interrupted(KeyboardInterrupt):
    """Ctrl-C, SIGTERM or SIGHUP: ``signum`` (the exit status is ``128 + signum``) and ``detail``, what
    was cut short, read after "interrupted by SIGTERM" (e.g. "at t = 33 s of 180 s; ...")."""

    def __init__(self, signum: int = signal.SIGINT, detail: str = ""):
        self.signum = int(signum)
        self.detail = detail
        super().__init__(self.message())

    @property
    def signal_name(self) -> str:
        return signal_name(self.signum)

    def message(self) -> str:
        return f"interrupted by {self.signal_name}" + (f" {self.detail}" if self.detail else "")


def interrupt_signum(exc: BaseException) -> int:
    """The signal behind a KeyboardInterrupt (SIGINT for a plain Ctrl-C)."""
    return int(getattr(exc, "signum", signal.SIGINT))


def signal_name(signum: int) -> str:
    """``SIGTERM`` for 15 (``signal 99`` for an unknown number)."""
    try:
        return signal.Signals(signum).name
    except ValueError:
        return f"signal {signum}"


@contextmanager
def signals_interrupt(signals: Sequence[int] = INTERRUPT_SIGNALS) -> Iterator[None]:
    """Within the block SIGTERM/SIGHUP raise :class:`Interrupted` in the main thread and SIGINT raises
    KeyboardInterrupt; the previous handlers come back afterwards. After the first of them the command is
    stopping: a further Ctrl-C (a user pressing it twice) is ignored, also after the block, until the
    caller has reported it (:func:`daa_sil.cli.main` restores Ctrl-C for a caller from Python). A no-op
    outside the main thread."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    interrupted = []

    def stopping() -> None:  # the first interrupt: the command is stopping, a further Ctrl-C is ignored
        interrupted.append(True)
        signal.signal(signal.SIGINT, signal.SIG_IGN)

    def raise_interrupted(signum, frame):
        stopping()
        raise Interrupted(signum)

    def raise_keyboard(signum, frame):
        stopping()
        raise KeyboardInterrupt

    old = {s: signal.signal(s, raise_interrupted) for s in signals}
    old_int = signal.signal(signal.SIGINT, raise_keyboard)
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h)
        if not interrupted:  # interrupted: Ctrl-C stays ignored while the caller reports and exits
            signal.signal(signal.SIGINT, old_int)


def interruptible(command: Callable) -> Callable:
    """``command`` run under :func:`signals_interrupt` (SIGTERM and SIGHUP act as Ctrl-C)."""
    @functools.wraps(command)
    def run(*args, **kwargs):
        with signals_interrupt():
            return command(*args, **kwargs)

    return run


# --------------------------------------------------------------------------------------------
# prctl

_PRCTL = None


def _prctl_function():
    """libc's ``prctl`` (looked up once, in the parent: a child between fork and exec must not dlopen
    or dlsym); None where there is none."""
    global _PRCTL
    if _PRCTL is None and sys.platform.startswith("linux"):
        try:
            _PRCTL = ctypes.CDLL(None, use_errno=True).prctl  # the C library is in the global namespace
        except (OSError, AttributeError):
            _PRCTL = False
    return _PRCTL or None


def _prctl(option: int, arg) -> bool:
    """``prctl(option, arg, 0, 0, 0) == 0`` on Linux; False elsewhere or on failure."""
    fn = _prctl_function()
    return fn is not None and fn(option, arg, 0, 0, 0) == 0


def death_signal() -> int:
    """The signal this process gets when its parent dies (0 = none; Linux ``PR_GET_PDEATHSIG``)."""
    sig = ctypes.c_int(0)
    return int(sig.value) if _prctl(PR_GET_PDEATHSIG, ctypes.byref(sig)) else 0


def watch_mode() -> str:
    """``prctl`` where the kernel can signal a child on its parent's death, else ``poll``."""
    forced = os.environ.get(WATCH_ENV, "").strip().lower()
    if forced in ("poll", "prctl"):
        return "poll" if forced == "poll" or not sys.platform.startswith("linux") else "prctl"
    return "prctl" if sys.platform.startswith("linux") else "poll"


def set_process_name(name: str) -> bool:
    """Name this process ``name`` (cut to 15 bytes) for ps/pgrep/top; True if the kernel took it."""
    return _prctl(PR_SET_NAME, ctypes.c_char_p(name.encode("ascii", "replace")[:NAME_MAX_BYTES]))


def _arm_before_exec(parent_pid: int) -> None:
    """``preexec_fn`` of :func:`spawn` (between fork and exec: no allocation-heavy work, no threads)."""
    _prctl(PR_SET_PDEATHSIG, int(DEATH_SIGNAL))
    if os.getppid() != parent_pid:  # the parent died before the prctl took effect
        os._exit(128 + int(DEATH_SIGNAL))


def die_with_parent(parent_pid: int, mode: "str | None" = None) -> None:
    """In a running child (e.g. a forked one): get :data:`DEATH_SIGNAL` when ``parent_pid`` dies
    (``prctl``, else a polling thread). Exits at once if it is already gone."""
    mode = mode or watch_mode()
    if mode == "prctl" and not _prctl(PR_SET_PDEATHSIG, int(DEATH_SIGNAL)):
        mode = "poll"
    if os.getppid() != parent_pid:  # the parent died before the prctl took effect
        os._exit(128 + int(DEATH_SIGNAL))
    if mode == "poll":
        threading.Thread(target=_watch_parent, args=(parent_pid,), name="daa-sil-parent-watch", daemon=True).start()


def _watch_parent(parent_pid: int) -> None:
    while os.getppid() == parent_pid:
        time.sleep(WATCH_POLL_S)
    os.kill(os.getpid(), DEATH_SIGNAL)  # our handler flushes and exits
    time.sleep(WATCH_KILL_S)
    os.kill(os.getpid(), signal.SIGKILL)


def adopt(default_name: "str | None" = None) -> None:
    """First thing in a Python child: take the name and the parent watch :func:`spawn` handed over
    (a process not started by :func:`spawn` only gets ``default_name``, if given)."""
    name = os.environ.pop(NAME_ENV, None) or default_name
    if name:
        set_process_name(name)
    parent = os.environ.pop(PARENT_ENV, None)
    if parent is None or not parent.isdigit():
        return
    mode = watch_mode()
    if mode == "prctl" and death_signal() == int(DEATH_SIGNAL):  # armed before exec by spawn()
        if os.getppid() != int(parent):
            os._exit(128 + int(DEATH_SIGNAL))
        return
    die_with_parent(int(parent), mode)


def exit_without_teardown(code: int) -> None:
    """End this process with status ``code`` now: flush stdout and stderr, then ``os._exit``.

    For the ``__main__`` of a SIL child (vehicle, GCS, shim) once its command returned, i.e. after it
    wrote and closed its files. It skips the interpreter's teardown, which is not free once numba
    has loaded the DAA kernels: about 0.1 s for numba alone and 0.25 s with the kernels, on the 2-core
    machine the benchmarks ran on. A lockstep run waits for that twice at its end: for the vehicle to
    exit and, after it, for the GCS the driver then stops (docs/sil.md, "Start-up and shutdown").
    Not for code that leaves buffered files or pending atexit work behind, nor for a function a test
    calls in-process: the command functions themselves return normally.
    """
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError, AttributeError):  # closed or replaced: nothing left to lose
            pass
    os._exit(code)


# --------------------------------------------------------------------------------------------
# starting a child

def spawn(argv: Sequence[str], name: str, *, python: "bool | None" = None, env: "dict | None" = None,
          **popen_kwargs) -> subprocess.Popen:
    """``subprocess.Popen(argv, **popen_kwargs)`` for a child that dies with this process and is
    called ``name`` (module docstring). ``python``: the child runs our Python code and calls
    :func:`adopt` (default: ``argv[0]`` is this interpreter). Must be called from the main thread."""
    if threading.current_thread() is not threading.main_thread():
        raise RuntimeError("daa-sil starts its children from the main thread only (PR_SET_PDEATHSIG fires "
                           "when the thread that forked exits)")
    argv = [str(a) for a in argv]
    if python is None:
        python = argv[0] == sys.executable
    full_env = dict(os.environ if env is None else env)
    parent = os.getpid()
    mode = watch_mode()
    if python:
        full_env[NAME_ENV] = name
        full_env[PARENT_ENV] = str(parent)
    elif mode == "poll":  # a binary cannot watch us itself: a watchdog does it for it
        argv = [sys.executable, "-m", "daa_sil.sil.children", "watch", str(parent), name, "--"] + argv
        full_env[NAME_ENV] = f"{name}-watch"[:NAME_MAX_BYTES]
        full_env[PARENT_ENV] = str(parent)
    if mode == "prctl" and _prctl_function() is not None:
        popen_kwargs["preexec_fn"] = lambda: _arm_before_exec(parent)
    return subprocess.Popen(argv, env=full_env, **popen_kwargs)


def _watchdog(argv: Sequence[str]) -> int:
    """``watch PPID NAME -- ARGV``: run ARGV until it exits or PPID dies (then stop it: SIGTERM, SIGKILL)."""
    parent, _name, sep, *cmd = argv
    if sep != "--" or not cmd:
        print("usage: python -m daa_sil.sil.children watch PPID NAME -- ARGV...", file=sys.stderr)
        return 2
    adopt()
    parent_pid = int(parent)
    child = subprocess.Popen(cmd)

    def forward(signum, frame):
        if child.poll() is None:
            child.send_signal(signum)

    for s in (signal.SIGINT,) + INTERRUPT_SIGNALS:
        signal.signal(s, forward)
    while child.poll() is None:
        if os.getppid() != parent_pid:
            child.send_signal(DEATH_SIGNAL)
            try:
                child.wait(timeout=WATCH_KILL_S)
            except subprocess.TimeoutExpired:
                child.kill()
            break
        time.sleep(WATCH_POLL_S)
    rc = child.wait()
    return 128 - rc if rc < 0 else rc


if __name__ == "__main__":  # pragma: no cover (run as the watchdog of a non-Python child)
    if sys.argv[1:2] != ["watch"]:
        print("usage: python -m daa_sil.sil.children watch PPID NAME -- ARGV...", file=sys.stderr)
        sys.exit(2)
    sys.exit(_watchdog(sys.argv[2:]))
