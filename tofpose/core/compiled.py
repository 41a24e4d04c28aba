"""The compiler of the pipeline's inner loops (numba): the decorator every kernel uses and
the cache it compiles into. The kernels themselves live with their stage
(``tofpose/stages/<stage>/kernels/``) and in ``tofpose/core/kernels/``.

The pipeline's per-frame work is many small array operations over a few blobs of a few
to a few hundred pixels: in NumPy each costs microseconds of call overhead, and a frame
made thousands of them. The loops here do the same arithmetic as the NumPy code they
replaced (the A/B harness ``bench/ab.py`` checks the poses are unchanged) in one compiled
call per stage.

Every kernel is compiled on first use and cached on disk (``cache=True``); ``warm_up()``
compiles them all on a tiny synthetic frame, so that a server or a long CLI run pays the
compile time once at start and never on a live frame (``tofpose warm-up`` does it after a
fresh install).

The cache lives in a directory named after a digest of every kernel source
(``kernel_cache_dir``): numba keys a cached kernel on its own file only, so after an
edit the kernels of other files that call the edited one would otherwise keep their old
compiled code. With the digest in the path, an edit of any kernel file is a new, empty
cache, and a kernel can never run against another state of the sources. Old states'
directories are removed by ``tofpose warm-up`` (``prune_stale_kernel_caches``), not at
import: another checkout or version may be running from the same base.
"""

from __future__ import annotations

import hashlib
import os
import shutil
from pathlib import Path

import numba

_HERE = Path(__file__).resolve().parent
_PACKAGE = _HERE.parent
#: every file with compiled code: the stages' and the core's kernels and the simulator's
#: ray caster
KERNEL_SOURCES = (
    *sorted(_HERE.glob("kernels/*.py")),
    *sorted(_PACKAGE.glob("stages/*/kernels/*.py")),
    # what the kernels freeze at compile time or build their records from
    _HERE / "records.py",
    *sorted(_PACKAGE.glob("stages/*/constants.py")),
    *sorted(_PACKAGE.glob("stages/*/records.py")),
    _PACKAGE / "sim" / "raycast.py",
)
_PREFIX = "tofpose-kernels-"


def kernel_sources_digest() -> str:
    """16 hex digits of SHA-256 over the kernel sources' names and bytes and numba's
    version."""
    h = hashlib.sha256(numba.__version__.encode())
    for path in KERNEL_SOURCES:
        h.update("/".join(path.parts[-4:]).encode())  # e.g. stages/pose/kernels/pose.py
        h.update(path.read_bytes())
    return h.hexdigest()[:16]


def kernel_cache_dir() -> Path:
    """The numba cache directory of this state of the kernel sources:
    ``<base>/tofpose-kernels-<digest>``, base ``NUMBA_CACHE_DIR`` when set, else this
    package's ``__pycache__`` (where numba would put it), else, when that cannot be
    written (a read-only install, a container run as another user), the user's cache
    (``$XDG_CACHE_HOME`` or ``~/.cache``, ``/tofpose``)."""
    name = f"{_PREFIX}{kernel_sources_digest()}"
    if os.environ.get("NUMBA_CACHE_DIR"):
        return Path(os.environ["NUMBA_CACHE_DIR"]) / name
    for base in (
        _HERE / "__pycache__",
        Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "tofpose",
    ):
        if _writable(base / name):
            return base / name
    return _HERE / "__pycache__" / name  # numba then compiles in memory, each process


def _writable(path: Path) -> bool:
    """Whether ``path`` could be created and written by this process: its nearest
    existing ancestor is a writable directory (checked with ``os.access``; nothing is
    written, so importing the library leaves the file system as it was)."""
    for candidate in (path, *path.parents):
        if candidate.exists():
            return candidate.is_dir() and os.access(candidate, os.W_OK | os.X_OK)
    return False


def prune_stale_kernel_caches(min_age_s: float = 86400.0) -> list[Path]:
    """Remove the cache directories of other states of the kernel sources beside this
    one that nothing wrote to for ``min_age_s`` (another checkout or version still
    running keeps its own); returns what was removed. ``tofpose warm-up`` calls it."""
    import time

    current = kernel_cache_dir()
    removed = []
    for old in current.parent.glob(f"{_PREFIX}*"):
        try:
            if old != current and old.is_dir() and time.time() - old.stat().st_mtime > min_age_s:
                shutil.rmtree(old, ignore_errors=True)
                removed.append(old)
        except OSError:
            continue
    return removed


# numba.config sets its settings at import, from the environment: no stub declares them
_CACHE_DIR = str(kernel_cache_dir())
numba.config.CACHE_DIR = _CACHE_DIR  # type: ignore[attr-defined]


def _keep_cache_dir_across_reloads() -> None:
    """numba re-reads its whole configuration from the environment whenever a ``NUMBA_*``
    variable of this process changed since the last compile (``numba.core.config``'s
    ``_EnvReloader``), and ``CACHE_DIR`` then falls back to ``NUMBA_CACHE_DIR`` or ''. A
    Dask nanny sets ``NUMBA_NUM_THREADS`` in the process that starts its workers (the
    server, a study): every kernel first compiled after that would be cached beside its
    source, where a caller's cached code outlives an edit of a kernel it inlines. So the
    reload is wrapped to set this state's directory again."""
    reloader = getattr(numba.core.config, "_env_reloader", None)
    process = getattr(reloader, "process_environ", None)
    if reloader is None or process is None or getattr(process, "_tofpose_keeps", False):
        return

    def process_keeping_cache_dir(environ):
        process(environ)
        numba.config.CACHE_DIR = _CACHE_DIR

    process_keeping_cache_dir._tofpose_keeps = True  # type: ignore[attr-defined]
    reloader.process_environ = process_keeping_cache_dir


_keep_cache_dir_across_reloads()

#: the decorator of every kernel: compiled once, cached on disk, releases the GIL (the
#: server's acquisition thread and its HTTP threads then do not wait on each other)
jit = numba.njit(cache=True, nogil=True)
