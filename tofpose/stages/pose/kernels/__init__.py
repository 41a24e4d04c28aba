"""Compiled kernels of the pose stage (numba, ``tofpose.core.compiled.jit``)."""
