"""The matching stage's constants, shared by its kernels and its reference statement
(defined once: numba freezes a module global into the compiled code as it reads here)."""

from __future__ import annotations

#: the cost of a forbidden cell of the one-to-one step (another blob's null label)
FORBIDDEN = 1e6
