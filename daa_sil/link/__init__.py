"""The MAVLink link, sans-IO: dialect, codec with signing, messages, delay line.

* :mod:`daa_sil.link.delayline` -- the delay line (the FIFO rule fast-time uses vectorised)
* :mod:`daa_sil.link.codec`     -- datagram <-> messages, signing, key files
* :mod:`daa_sil.link.messages`  -- builders/readers for ticks, pilot commands, bands, decisions
* :mod:`daa_sil.link.fuzz`      -- hostile datagrams for the fuzz tests
* :mod:`daa_sil.link.dialect`   -- ``daa_sil.xml`` and the generated ``daa_sil`` module

The UDP endpoint, the delay shim, the clocks and the lockstep handshake are I/O: :mod:`daa_sil.sil`.
Import submodules directly; this package imports nothing heavy on its own.
"""
