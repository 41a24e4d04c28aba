"""Compiled kernels of the extraction stage (numba, ``tofpose.core.compiled.jit``)."""
