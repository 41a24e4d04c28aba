"""numba's cache of the kernels lives in a directory of the kernel sources' state
(``tofpose.core.compiled.kernel_cache_dir``): an edit of any kernel file is another directory,
so a caller's cached kernel can never run with another file's old code inlined."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import numba

from tofpose.core import compiled


def test_numba_caches_in_the_directory_of_the_sources_state():
    path = compiled.kernel_cache_dir()
    assert str(path) == numba.config.CACHE_DIR
    assert path.name == f"tofpose-kernels-{compiled.kernel_sources_digest()}"
    assert any(p.name == "mixed_pixels.py" for p in compiled.KERNEL_SOURCES)
    assert any(p.name == "raycast.py" for p in compiled.KERNEL_SOURCES)


def test_an_edit_of_any_kernel_source_is_another_cache(tmp_path, monkeypatch):
    copies = []
    for p in compiled.KERNEL_SOURCES:
        q = tmp_path / p.name
        q.write_bytes(p.read_bytes())
        copies.append(q)
    monkeypatch.setattr(compiled, "KERNEL_SOURCES", tuple(copies))
    before = compiled.kernel_sources_digest()
    callee = next(q for q in copies if q.name == "mixed_pixels.py")
    callee.write_bytes(callee.read_bytes() + b"\n# an edit\n")
    after = compiled.kernel_sources_digest()
    assert after != before
    callee.write_bytes(callee.read_bytes()[: -len(b"\n# an edit\n")])
    assert compiled.kernel_sources_digest() == before  # the state, not the file's time


def _fresh_process(code: str, cache_base: Path) -> str:
    """stdout of ``code`` run by a fresh interpreter whose ``NUMBA_CACHE_DIR`` is
    ``cache_base`` (nothing else of this process's environment but a PATH)."""
    return subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        env={"NUMBA_CACHE_DIR": str(cache_base), "PATH": "/usr/bin:/bin"},
        check=True,
        timeout=600,
    ).stdout


def test_a_user_cache_base_is_kept_and_a_compiled_kernel_lands_there(tmp_path):
    """In a fresh process with ``NUMBA_CACHE_DIR`` set, the kernels' directory is inside
    it and a compiled kernel's cache files land there."""
    code = (
        "import numpy as np\n"
        "from tofpose.core import compiled\n"
        "from tofpose.core.kernels.stats import median_inplace\n"
        "median_inplace(np.arange(5.0))\n"
        "print(compiled.kernel_cache_dir())\n"
    )
    out = _fresh_process(code, tmp_path).strip().splitlines()[-1]
    assert out == str(tmp_path / f"tofpose-kernels-{compiled.kernel_sources_digest()}")
    assert any(p.suffix == ".nbi" for p in Path(out).rglob("*"))


def test_a_numba_variable_set_later_keeps_the_kernels_cache(tmp_path):
    """A Dask nanny sets ``NUMBA_NUM_THREADS`` in the process that starts its workers;
    numba then re-reads its configuration at the next compile, and its ``CACHE_DIR``
    fell back to '' (kernels cached beside their sources). In a fresh process: the
    variable set after import, a kernel compiled, the cache is still the sources'
    state's and the kernel's cache files land there."""
    code = (
        "import os\n"
        "import numba, numpy as np\n"
        "from tofpose.core import compiled\n"
        "os.environ['NUMBA_NUM_THREADS'] = '1'\n"
        "from tofpose.core.kernels.stats import median_inplace\n"
        "median_inplace(np.arange(5.0))\n"
        "print(numba.config.NUMBA_NUM_THREADS, numba.config.CACHE_DIR)\n"
    )
    out = _fresh_process(code, tmp_path).split()
    expected = tmp_path / f"tofpose-kernels-{compiled.kernel_sources_digest()}"
    assert out[-2:] == ["1", str(expected)]  # the variable took effect, the cache stayed
    assert any(p.suffix == ".nbi" for p in expected.rglob("*"))


def test_only_old_caches_of_other_states_are_pruned(tmp_path, monkeypatch):
    """``prune_stale_kernel_caches`` (run by ``tofpose warm-up``) removes the directories
    of other source states idle for a day; a recent one (another checkout running now),
    the current one and anything not a kernel cache stay."""
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    current = compiled.kernel_cache_dir()
    current.mkdir()
    old = tmp_path / "tofpose-kernels-0123456789abcdef"
    recent = tmp_path / "tofpose-kernels-fedcba9876543210"
    other = tmp_path / "someone-else"
    for d in (old, recent, other):
        d.mkdir()
    two_days_ago = time.time() - 2 * 86400
    os.utime(old, (two_days_ago, two_days_ago))
    os.utime(other, (two_days_ago, two_days_ago))
    assert compiled.prune_stale_kernel_caches() == [old]
    assert not old.exists() and recent.exists() and current.exists() and other.exists()


def test_an_unwritable_package_directory_falls_back_to_the_users_cache(tmp_path, monkeypatch):
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    real = compiled._writable
    monkeypatch.setattr(
        compiled, "_writable", lambda p: False if compiled._HERE in p.parents else real(p)
    )
    path = compiled.kernel_cache_dir()
    assert path == tmp_path / "tofpose" / f"tofpose-kernels-{compiled.kernel_sources_digest()}"


def test_importing_the_library_writes_nothing(tmp_path):
    """``import tofpose`` and the command line's parser in a fresh process create no
    file or directory in a new cache base (the kernels are imported, and numba makes
    its cache directories, only when a name of the pipeline is first used)."""
    base = tmp_path / "cache"
    code = (
        "import tofpose, sys\nfrom tofpose.cli import build_parser\nbuild_parser()\n"
        "assert 'numba' not in sys.modules and 'cv2' not in sys.modules\nprint('ok')\n"
    )
    assert _fresh_process(code, base).strip() == "ok"
    assert not base.exists()


def test_writability_is_read_from_the_nearest_existing_ancestor(tmp_path):
    """A cache path under a new directory of a writable one is writable; one under a
    regular file cannot be made; neither check creates anything."""
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    assert compiled._writable(tmp_path / "new" / "tofpose-kernels-x")
    assert not compiled._writable(blocker / "tofpose-kernels-x")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a-file"]
