"""The numba types the kernels' explicit signatures are written with, defined once.

``A``/``A2``/``A3``/``A4``: read-only float64 arrays of 1-4 dimensions, any layout (inputs); ``IA``,
``B2``: read-only int64 (1-d) and boolean (2-d) arrays; ``O``/``O2``/``O4``: writable float64 output
arrays (1-d any layout, 2-d and 4-d C-contiguous); ``I8``: a writable int8 C-contiguous 1-d array;
``F``/``I``/``B``: float64, int64 and boolean scalars.
"""

from __future__ import annotations

from numba import boolean, float64, int8, int64, types

A = types.Array(float64, 1, "A", readonly=True)
A2 = types.Array(float64, 2, "A", readonly=True)
A3 = types.Array(float64, 3, "A", readonly=True)
A4 = types.Array(float64, 4, "A", readonly=True)
IA = types.Array(int64, 1, "A", readonly=True)
B2 = types.Array(boolean, 2, "A", readonly=True)
O = float64[:]
O2 = types.Array(float64, 2, "C")
O4 = types.Array(float64, 4, "C")
I8 = types.Array(int8, 1, "C")
F = float64
I = int64
B = boolean
