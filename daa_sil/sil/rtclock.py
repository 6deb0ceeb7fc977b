"""Precise real-time helpers for the delay shim: kernel receive timestamps and a timerfd wake-up.

Where the error of a real-time delay line comes from (measured by ``benchmarks/bench_link.py``):

1. **Input stamping.** A datagram stamped when the event loop gets round to reading it is stamped
   late whenever the process was busy or not on a CPU. :func:`enable_rx_timestamps` asks the
   kernel to stamp each datagram on arrival (``SO_TIMESTAMPNS``); :func:`rx_time` converts that
   stamp to the loop's clock (``time.monotonic``). The release time is then computed from the
   arrival instant, whatever the read latency was.
2. **Wake-up.** ``loop.call_at`` hands the selector a timeout in whole milliseconds (rounded up),
   so a release is up to ~1 ms late even on an idle machine; polling the loop to the instant
   burns CPU, which on a shared machine makes the scheduler treat the process as CPU-bound and
   wake it *later*. :class:`PreciseTimer` arms a Linux ``timerfd`` (absolute
   ``CLOCK_MONOTONIC``, nanoseconds) registered with the loop as a reader: the process sleeps in
   ``epoll`` until the kernel's high-resolution timer fires, with no polling. The timer slack of
   the process is set to 1 us (``PR_SET_TIMERSLACK``; the default 50 us) -- both are per-process
   and harmless.
3. **Scheduling latency** once woken: on a busy machine another process holds the CPU when the
   timer fires. Linux >= 6.12 (EEVDF scheduler) lets an ordinary ``SCHED_OTHER`` process ask for a
   short time slice (``sched_setattr`` with ``sched_runtime``, no privilege needed, priority and
   CPU share unchanged); a task with a shorter slice gets an earlier virtual deadline and may
   preempt the running task when it wakes. :func:`request_short_slice` asks for 0.1 ms. Beyond
   that only real-time priority helps (``daa-sil shim --rt-priority``).

Everything degrades gracefully: without ``timerfd`` (non-Linux, or ctypes unavailable) the timer
falls back to ``call_at`` a little early plus polling the loop to the instant; without kernel
stamps :func:`rx_time` returns None and the caller stamps on read.
"""

from __future__ import annotations

import asyncio
import ctypes
import ctypes.util
import os
import socket
import struct
import sys
import time
from typing import Callable
import platform

#: ``SO_TIMESTAMPNS`` / ``SCM_TIMESTAMPNS`` (asm-generic Linux value; Python 3.11 lacks the constant)
SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35)
_TS = struct.Struct("qq")  # struct timespec (64-bit)
_CMSG_SPACE = socket.CMSG_SPACE(_TS.size) if hasattr(socket, "CMSG_SPACE") else 0
_CLOCK_MONOTONIC, _TFD_NONBLOCK, _TFD_CLOEXEC, _TFD_TIMER_ABSTIME = 1, 0o4000, 0o2000000, 1
_PR_SET_TIMERSLACK = 29


class _Timespec(ctypes.Structure):
    _fields_ = [("tv_sec", ctypes.c_long), ("tv_nsec", ctypes.c_long)]


class _Itimerspec(ctypes.Structure):
    _fields_ = [("it_interval", _Timespec), ("it_value", _Timespec)]


def _libc():
    if not sys.platform.startswith("linux"):
        return None
    try:
        lib = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        lib.timerfd_create  # noqa: B018 (probe)
        lib.timerfd_settime  # noqa: B018
        return lib
    except (OSError, AttributeError):
        return None


_LIBC = _libc()


def set_timer_slack(ns: int = 1000) -> bool:
    """Set this process's timer slack (ns) so timed wake-ups are not coalesced late; False if unsupported."""
    if _LIBC is None:
        return False
    try:
        return _LIBC.prctl(_PR_SET_TIMERSLACK, ctypes.c_ulong(int(ns)), 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


class _SchedAttr(ctypes.Structure):
    _fields_ = [("size", ctypes.c_uint32), ("sched_policy", ctypes.c_uint32), ("sched_flags", ctypes.c_uint64),
                ("sched_nice", ctypes.c_int32), ("sched_priority", ctypes.c_uint32), ("sched_runtime", ctypes.c_uint64),
                ("sched_deadline", ctypes.c_uint64), ("sched_period", ctypes.c_uint64)]


#: sched_setattr / sched_getattr syscall numbers per machine
_SYS_SCHED_ATTR = {"x86_64": (314, 315), "aarch64": (274, 275), "riscv64": (274, 275)}


def request_short_slice(slice_s: float = 0.0001) -> bool:
    """Ask the scheduler for a ``slice_s`` time slice (EEVDF custom slice, Linux >= 6.12); False if refused.

    Keeps the policy (must be ``SCHED_OTHER``) and the nice value; only the slice changes. On older
    kernels the call succeeds but the value is ignored.
    """

    nums = _SYS_SCHED_ATTR.get(platform.machine())
    if _LIBC is None or nums is None:
        return False
    try:
        if os.sched_getscheduler(0) != os.SCHED_OTHER:
            return False
        attr = _SchedAttr(48, os.SCHED_OTHER, 0, os.getpriority(os.PRIO_PROCESS, 0), 0, int(slice_s * 1e9), 0, 0)
        return _LIBC.syscall(nums[0], 0, ctypes.byref(attr), 0) == 0
    except (OSError, AttributeError):
        return False


def enable_rx_timestamps(sock: socket.socket) -> bool:
    """Ask the kernel to stamp every datagram received on ``sock``; False if not supported."""
    if not sys.platform.startswith("linux") or not _CMSG_SPACE:
        return False
    try:
        sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
    except OSError:
        return False
    return True


def rx_buffer_size() -> int:
    """Ancillary-data buffer size to pass to ``sock.recvmsg`` for one kernel timestamp."""
    return _CMSG_SPACE


def rx_time(ancdata) -> "float | None":
    """The kernel arrival stamp in ``recvmsg`` ancillary data as ``time.monotonic()`` seconds, or None.

    The stamp is CLOCK_REALTIME; it is moved onto the monotonic clock with the current offset
    between the two clocks (read twice around ``time.time()`` to bound the error to ~1 us).
    """
    for level, kind, data in ancdata:
        if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS and len(data) >= _TS.size:
            sec, nsec = _TS.unpack_from(data)
            m0 = time.monotonic()
            real = time.time()
            m1 = time.monotonic()
            return sec + nsec * 1e-9 - real + 0.5 * (m0 + m1)
    return None


class PreciseTimer:
    """A re-armable one-shot timer on an asyncio loop that fires at a ``time.monotonic()`` instant.

    ``arm(when)`` (re)schedules ``callback()`` for ``when``; ``cancel()``; ``close()``. With a
    timerfd the callback runs when the kernel timer expires (no polling); otherwise ``call_at``
    fires ``spin_s`` early and the loop is polled (``call_soon``, I/O still served) until ``when``.
    ``kind`` is ``"timerfd"`` or ``"poll"``.
    """

    def __init__(self, loop: asyncio.AbstractEventLoop, callback: Callable[[], None], spin_s: float = 0.002,
                 use_timerfd: bool = True):
        self.loop, self.callback, self.spin_s = loop, callback, float(spin_s)
        self.when: "float | None" = None
        self._handle: "asyncio.Handle | None" = None
        self._fd = -1
        if use_timerfd and _LIBC is not None and isinstance(loop.time(), float) and self._loop_is_monotonic():
            fd = _LIBC.timerfd_create(_CLOCK_MONOTONIC, _TFD_NONBLOCK | _TFD_CLOEXEC)
            if fd >= 0:
                self._fd = fd
                self._spec = _Itimerspec()
                loop.add_reader(fd, self._expired)
        self.kind = "timerfd" if self._fd >= 0 else "poll"

    def _loop_is_monotonic(self) -> bool:
        return abs(self.loop.time() - time.monotonic()) < 0.01

    def arm(self, when: float) -> None:
        """Fire at monotonic time ``when`` (s), replacing any pending expiry."""
        self.when = when
        if self._fd >= 0:
            sec = int(when)
            ns = int(round((when - sec) * 1e9))
            if ns >= 1_000_000_000:
                sec, ns = sec + 1, ns - 1_000_000_000
            self._spec.it_value.tv_sec, self._spec.it_value.tv_nsec = max(sec, 0), max(ns, 0)
            if sec <= 0 and ns <= 0:  # 0 would disarm: fire as soon as possible instead
                self._spec.it_value.tv_nsec = 1
            if _LIBC.timerfd_settime(self._fd, _TFD_TIMER_ABSTIME, ctypes.byref(self._spec), None) != 0:
                self._fallback_arm(when)
            return
        self._fallback_arm(when)

    def _fallback_arm(self, when: float) -> None:
        if self._handle is not None:
            self._handle.cancel()
        self._handle = self.loop.call_at(when - self.spin_s, self._poll)

    def _poll(self) -> None:
        if self.when is None:
            self._handle = None
            return
        if self.loop.time() < self.when:  # early by design: poll again after one loop iteration
            self._handle = self.loop.call_soon(self._poll)
            return
        self._handle = None
        self._fire()

    def _expired(self) -> None:
        try:
            os.read(self._fd, 8)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            return
        self._fire()

    def _fire(self) -> None:
        if self.when is None:
            return
        self.when = None
        self.callback()

    def cancel(self) -> None:
        """Drop the pending expiry (if any)."""
        self.when = None
        if self._handle is not None:
            self._handle.cancel()
            self._handle = None
        if self._fd >= 0:
            self._spec.it_value.tv_sec = self._spec.it_value.tv_nsec = 0
            _LIBC.timerfd_settime(self._fd, 0, ctypes.byref(self._spec), None)

    def close(self) -> None:
        """Cancel and release the timerfd (idempotent)."""
        self.cancel()
        if self._fd >= 0:
            try:
                self.loop.remove_reader(self._fd)
            except (RuntimeError, ValueError):
                pass
            os.close(self._fd)
            self._fd = -1
