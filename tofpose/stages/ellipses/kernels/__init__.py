"""Compiled kernels of the ellipses stage (numba, ``tofpose.core.compiled.jit``)."""
