"""The ellipse stage's constants, shared by its kernels and its reference statement
(defined once: numba freezes a module global into the compiled code as it reads here)."""

from __future__ import annotations

#: parameters of the merged pair's model: u1, v1, u2, v2 (px), a1, a2 (counts), r (px),
#: s (px), bg (counts)
N_PARAMS = 9
#: major over minor axis (standard deviations) of a pair of touching like discs, at least
MIN_ELONGATION = 1.5
