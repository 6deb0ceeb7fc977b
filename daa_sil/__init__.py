"""daa-sil: a MAVLink software-in-the-loop bridge for UAS detect-and-avoid with a delayed remote pilot.

Implements Tabassum & Bai, *Dynamic Control Allocation between Onboard and Delayed Remote Control
for UAS Detect-and-Avoid*: an MDP wait map, the allocation agent (Eq. 10-11, Algorithm 1) and
pilot/DAA command blending (Algorithm 2), exercised both in a batched fast-time Monte Carlo study
and through real MAVLink 2 over UDP with a delay shim.

The sans-IO core (SI units, world frame ENU, no sockets, no wall clock) is every package but
``daa_sil.sil``, ``daa_sil.viz`` and ``daa_sil.commands``, the I/O side; docs/architecture.md shows
the layout and tests/test_import_rules.py enforces it.
"""

__version__ = "0.1.0"
