"""The software-in-the-loop I/O shell: UDP endpoint, delay shim, clocks, lockstep handshake, live feed, process supervision, scenario files."""
