"""``daa_sil.background.BackgroundCall``: the value, or the exception, of a call made on another thread."""

from __future__ import annotations

import threading

import pytest

from daa_sil.background import BackgroundCall


def test_result_is_the_calls_value_computed_on_another_thread():
    where = []

    def work(a, b=0):
        where.append(threading.current_thread() is threading.main_thread())
        return a + b

    assert BackgroundCall(work, 2, b=3).result() == 5
    assert where == [False]


def test_result_raises_the_calls_own_exception():
    err = ValueError("bad map")

    def fail():
        raise err

    call = BackgroundCall(fail)
    with pytest.raises(ValueError) as caught:
        call.result()
    assert caught.value is err
    with pytest.raises(ValueError):  # and again: the outcome is kept
        call.result()


def test_result_waits_for_the_call():
    go = threading.Event()
    call = BackgroundCall(lambda: go.wait(10.0) and "done")
    threading.Timer(0.05, go.set).start()
    assert call.result() == "done"
