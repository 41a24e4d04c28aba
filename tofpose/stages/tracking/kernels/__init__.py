"""Compiled kernels of the tracking stage (numba, ``tofpose.core.compiled.jit``)."""
