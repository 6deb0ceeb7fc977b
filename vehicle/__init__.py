"""The SIL vehicle process (``daa-vehicle``): ownship + intruder simulation, onboard DAA, wait map
and allocation agent (via :class:`daa_sil.onboard.OnboardCore` with N = 1), over MAVLink/UDP.

* :mod:`vehicle.telemetry` -- pure encoding of one step's state into MAVLink messages
* :mod:`vehicle.commands`  -- pilot command gate (at most once, never older after newer)
* :mod:`vehicle.node`      -- the asyncio node (realtime and lockstep clocks)
* :mod:`vehicle.cli`       -- ``daa-vehicle`` command line
"""
