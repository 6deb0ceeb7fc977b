"""Real-time helpers of the shim: kernel arrival stamps and the timerfd timer (never early, re-armable)."""

from __future__ import annotations

import asyncio
import socket
import sys
import time

import pytest

from daa_sil.sil import rtclock

LINUX = sys.platform.startswith("linux")


def test_kernel_arrival_stamp_lies_between_send_and_read():
    a = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    b = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        a.bind(("127.0.0.1", 0))
        b.bind(("127.0.0.1", 0))
        assert rtclock.enable_rx_timestamps(a) == LINUX
        # Linux turns arrival stamping on lazily (a deferred static key) when the first socket in the
        # system asks for it; until then skbs carry no stamp and recvmsg stamps them at read. Let one
        # warm-up datagram through and give the kernel a moment before the timed one.
        b.sendto(b"w", a.getsockname())
        a.settimeout(5)
        a.recvmsg(2048, rtclock.rx_buffer_size())
        time.sleep(0.05)
        t_send = time.monotonic()
        b.sendto(b"x", a.getsockname())  # loopback: the kernel stamps it inside this call
        t_sent = time.monotonic()
        a.settimeout(5)
        time.sleep(0.05)  # the datagram waits in the socket: a read-time stamp would be >= 50 ms late
        for _ in range(100):  # skip strays (an OS-chosen port may still get another test's traffic)
            data, anc, _, src = a.recvmsg(2048, rtclock.rx_buffer_size())
            if src == b.getsockname():
                break
        t_read = time.monotonic()
        t_rx = rtclock.rx_time(anc)
    finally:
        a.close()
        b.close()
    assert data == b"x"
    if LINUX:
        # stamped on arrival (during sendto; 1 ms covers the clock conversion), not on read >= 50 ms later
        assert t_send - 1e-3 <= t_rx <= t_sent + 1e-3 and t_read >= t_sent + 0.05, (t_send, t_rx, t_sent, t_read)
    assert rtclock.rx_time([]) is None


@pytest.mark.asyncio
@pytest.mark.parametrize("use_timerfd", [True, False])
async def test_precise_timer_never_fires_early_and_rearms(use_timerfd):
    loop = asyncio.get_running_loop()
    fired: list[float] = []
    done = asyncio.Event()

    def cb():
        fired.append(time.monotonic())
        if len(fired) == 2:
            done.set()

    timer = rtclock.PreciseTimer(loop, cb, use_timerfd=use_timerfd)
    try:
        assert timer.kind == ("timerfd" if (use_timerfd and LINUX) else "poll")
        t0 = time.monotonic()
        timer.arm(t0 + 0.2)
        timer.arm(t0 + 0.02)  # re-arming replaces the pending expiry
        await asyncio.sleep(0.01)
        timer.cancel()  # ... and cancel drops it
        timer.arm(t0 + 0.03)
        await asyncio.wait_for(asyncio.shield(_until(lambda: len(fired) == 1)), 10)
        timer.arm(time.monotonic() - 1.0)  # a past instant fires at once
        await asyncio.wait_for(done.wait(), 10)
        await asyncio.sleep(0.25)  # the replaced 0.2 s expiry must not fire any more
    finally:
        timer.close()
    assert len(fired) == 2 and fired[0] >= t0 + 0.03


async def _until(cond) -> None:
    while not cond():
        await asyncio.sleep(0.001)
