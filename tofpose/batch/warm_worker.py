"""Imported by a LocalCluster's forkserver before it forks a worker
(``tofpose.batch.cluster.PRELOAD``): loads the pipeline's kernels from numba's on-disk
cache (``tofpose.warmup.warm_up``; on a fresh install it compiles them, once), so that
every worker forked from it starts with them loaded instead of loading them at its first
frame, each on its own. ``SECONDS``: what it took here; None when it failed (the workers
then load the kernels themselves, as without it)."""

from __future__ import annotations

SECONDS: float | None
try:
    from tofpose.warmup import warm_up

    SECONDS = warm_up()
except Exception:  # noqa: BLE001 (a worker without preloaded kernels still works)
    SECONDS = None
