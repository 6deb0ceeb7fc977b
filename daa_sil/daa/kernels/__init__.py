"""Compiled (numba) kernels of the DAA's hot loops; the rules are in :mod:`daa_sil.daa.kernels.jit`.

The numpy functions they replace stay as ``*_reference`` in their modules and are the test oracles
(``tests/test_daa_kernels.py``: identical results on random and adversarial inputs).
"""
