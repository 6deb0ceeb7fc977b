"""The software-in-the-loop I/O shell around the sans-IO core.

* :mod:`daa_sil.sil.endpoint` -- asyncio UDP endpoint around the codec, address parsing
* :mod:`daa_sil.sil.connstr`  -- ``udp:``/``udpin:``/``udpout:`` connection strings
* :mod:`daa_sil.sil.shim`     -- the delay shim (its sans-IO ``shim_core``, with ``shim_config``, ``shim_socket``)
* :mod:`daa_sil.sil.rtclock`  -- realtime clocks: kernel receive stamps, precise timers
* :mod:`daa_sil.sil.lockstep` -- the tick protocol, sans-IO (:class:`TickPeer`), for vehicle and GCS
* :mod:`daa_sil.sil.silence`  -- one silence watch (and its threshold per role) for shim, vehicle, GCS
* :mod:`daa_sil.sil.live`     -- the live step feed (UDP, fire-and-forget) to the Rerun recorder
* :mod:`daa_sil.sil.supervise`, :mod:`daa_sil.sil.play`, :mod:`daa_sil.sil.summary` -- the
  three-process run of ``daa-sil run``: supervision, orchestration, result
* :mod:`daa_sil.sil.web_ports` -- the Rerun web viewer's ports and their ``--serve-web`` options
* :mod:`daa_sil.sil.children` -- how every child process is started (dies with its parent, even on
  SIGKILL; named for ps/pgrep) and SIGTERM/SIGHUP taken as Ctrl-C
* :mod:`daa_sil.sil.scenario` -- scenario files: schema, loader/validator, conversion, expectations
"""
