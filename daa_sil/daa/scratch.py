"""Working arrays the DAA's compiled passes reuse from one call to the next, one set per thread.

A large array allocated afresh is page-faulted in on every call (about 4 us per 4 KiB page on the
benchmark machine; a call at N = 10,000 would fault in tens of MB). What :class:`Scratch` hands out is
only ever read and written inside the call that took it, and never returned to a caller."""

from __future__ import annotations

import threading

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


_THREAD = threading.local()


def scratch() -> Scratch:
    """This thread's :class:`Scratch`."""
    s = getattr(_THREAD, "scratch", None)
    if s is None:
        s = _THREAD.scratch = Scratch()
    return s
