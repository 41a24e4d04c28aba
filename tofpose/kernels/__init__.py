"""Compiled inner loops of the pipeline (numba), one module per paper stage.

The pipeline's per-frame work is many small array operations over a few blobs of a few
to a few hundred pixels: in NumPy each costs microseconds of call overhead, and a frame
made thousands of them. The loops here do the same arithmetic as the NumPy code they
replaced (the A/B harness ``bench/ab.py`` checks the poses are unchanged) in one compiled
call per stage.

Every kernel is compiled on first use and cached on disk (``cache=True``); ``warm_up()``
compiles them all on a tiny synthetic frame, so that a server or a long CLI run pays the
compile time once at start and never on a live frame (``tofpose warm-up`` does it after a
fresh install).
"""

from __future__ import annotations

import numba

#: the decorator of every kernel: compiled once, cached on disk, releases the GIL (the
#: server's acquisition thread and its HTTP threads then do not wait on each other)
jit = numba.njit(cache=True, nogil=True)
