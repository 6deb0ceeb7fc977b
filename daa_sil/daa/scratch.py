"""Working arrays the DAA's compiled passes reuse from one call to the next.

A large array allocated afresh is page-faulted in on every call (about 4 us per 4 KiB page on the
benchmark machine; a call at N = 10,000 would fault in tens of MB). What :class:`Scratch` hands out is
only ever read and written inside the call that took it, and never returned to a caller. A call holds
its :class:`Scratch` for its duration (:func:`scratch`), so a call nested in it, or one in another
thread, gets another one."""

from __future__ import annotations

import contextlib
from typing import Iterator

import numpy as np


class Scratch:
    """Buffers kept under names, grown when too small."""

    def __init__(self):
        self._bufs: dict[str, np.ndarray] = {}

    def buffer(self, name: str, dtype=np.float64) -> np.ndarray:
        """The whole buffer under ``name`` (uninitialised; empty until something was taken)."""
        buf = self._bufs.get(name)
        if buf is None or buf.dtype != dtype:
            buf = self._bufs[name] = np.empty(0, dtype)
        return buf

    def take(self, name: str, size: int, dtype=np.float64) -> np.ndarray:
        """A 1-d array of ``size`` elements of ``dtype`` (uninitialised) under ``name``, valid until the next
        :meth:`take` or :meth:`buffer` of that name."""
        buf = self.buffer(name, dtype)
        if buf.size < size:
            buf = self._bufs[name] = np.empty(int(size), dtype)
        return buf[:size]


#: the Scratch objects no call holds (taken and put back last in, first out: a call and the call nested in
#: it get the same two every time)
_FREE: "list[Scratch]" = []


@contextlib.contextmanager
def scratch() -> Iterator[Scratch]:
    """A :class:`Scratch` held for the duration of the ``with`` block (list ``pop`` / ``append`` are atomic:
    two threads never hold the same one)."""
    try:
        s = _FREE.pop()
    except IndexError:
        s = Scratch()
    try:
        yield s
    finally:
        _FREE.append(s)
