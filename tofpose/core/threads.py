"""One BLAS thread: the pipeline's matrices are 3x3 to 6x6, where threading only costs.

OpenBLAS (numpy's BLAS) keeps its worker threads spinning for a while after every call;
with a few small products per frame, the workers never get to sleep and burn a whole core
while doing nothing (measured: a server on the simulated camera at 10 Hz used 135 % of a
core with its BLAS threads, 35 % without). The CLI (``tofpose serve`` included) calls
``single_threaded_blas()`` first thing, on the main thread (from another thread, while
a limit is in force, OpenBLAS ignored the call here); a library user decides for their
own process.
"""

from __future__ import annotations


def single_threaded_blas() -> None:
    """Limit every loaded BLAS library to one thread for the rest of the process."""
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=1, user_api="blas")
