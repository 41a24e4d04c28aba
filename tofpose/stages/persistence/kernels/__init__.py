"""Compiled kernels of the persistence stage (numba, ``tofpose.core.compiled.jit``)."""
