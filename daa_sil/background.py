"""One function call on a daemon thread while the caller does something else (e.g. the vehicle reads
its wait maps while numba loads the DAA kernels: the reads, CRCs and numpy copies release the GIL)."""

from __future__ import annotations

import threading
from typing import Any, Callable


class BackgroundCall:
    """``fn(*args, **kwargs)`` started now on a daemon thread; :meth:`result` waits for it and returns
    its value, or raises the exception it raised (with its traceback), in the caller's thread."""

    def __init__(self, fn: Callable[..., Any], *args, **kwargs):
        self._value: Any = None
        self._error: "BaseException | None" = None
        self._thread = threading.Thread(target=self._run, args=(fn, args, kwargs), daemon=True,
                                        name=f"background {getattr(fn, '__name__', 'call')}")
        self._thread.start()

    def _run(self, fn: Callable[..., Any], args: tuple, kwargs: dict) -> None:
        try:
            self._value = fn(*args, **kwargs)
        except BaseException as exc:  # noqa: BLE001  (handed to the caller by result())
            self._error = exc

    def result(self) -> Any:
        """The call's return value once it finished; its exception re-raised here if it raised one."""
        self._thread.join()
        if self._error is not None:
            raise self._error
        return self._value


__all__ = ["BackgroundCall"]
