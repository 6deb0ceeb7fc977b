"""The MAVLink link: dialect, sans-IO codec with signing, delay line, UDP endpoint and delay shim.

* :mod:`daa_sil.link.delayline` -- sans-IO delay line (shared with fast-time)
* :mod:`daa_sil.link.codec`     -- datagram <-> messages, signing, key files
* :mod:`daa_sil.link.messages`  -- builders/readers for ticks, pilot commands, bands, decisions
* :mod:`daa_sil.sil.endpoint`  -- asyncio UDP endpoint around the codec, address parsing
* :mod:`daa_sil.sil.shim`      -- the delay shim (realtime and lockstep clocks)
* :mod:`daa_sil.sil.lockstep`  -- SIM_TICK / SIM_TICK_ACK handshake helpers for vehicle and GCS
* :mod:`daa_sil.link.dialect`   -- ``daa_sil.xml`` and the generated ``daa_sil`` module

Import submodules directly; this package imports nothing heavy on its own.
"""
