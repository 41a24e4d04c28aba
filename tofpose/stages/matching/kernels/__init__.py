"""Compiled kernels of the matching stage (numba, ``tofpose.core.compiled.jit``)."""
