"""The tracking stage's constants, shared by its kernels, its reference statement and its
orchestration (defined once: numba freezes a module global into the compiled code as it
reads here)."""

from __future__ import annotations

#: outcome codes of ``search_windows``
FOUND, NOT_FOUND, NO_SIZE, AT_EDGE = 0, 1, 2, 3
#: outcome codes of ``track_frame`` (anything but TRACKED: fall back to acquisition)
TRACKED, LOST, SHARED, NOT_PERSISTENT, NO_RANGE, OUTLIER = 0, 1, 2, 3, 4, 5
