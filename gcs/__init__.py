"""The SIL ground-control-station process (``daa-gcs``): delayed telemetry in, remote-pilot commands out.

* :mod:`gcs.node`    -- the asyncio node (pilot model or scripted pilot; realtime and lockstep)
* :mod:`gcs.display` -- the one-line-per-second console display
* :mod:`gcs.cli`     -- ``daa-gcs`` command line
"""
