"""numba's cache of the kernels lives in a directory of the kernel sources' state
(``tofpose.kernels.kernel_cache_dir``): an edit of any kernel file is another directory,
so a caller's cached kernel can never run with another file's old code inlined."""

from __future__ import annotations

import subprocess
import sys

import numba

from tofpose import kernels


def test_numba_caches_in_the_directory_of_the_sources_state():
    path = kernels.kernel_cache_dir()
    assert str(path) == numba.config.CACHE_DIR
    assert path.name == f"tofpose-kernels-{kernels.kernel_sources_digest()}"
    assert any(p.name == "mixed_pixels.py" for p in kernels.KERNEL_SOURCES)
    assert any(p.name == "raycast.py" for p in kernels.KERNEL_SOURCES)


def test_an_edit_of_any_kernel_source_is_another_cache(tmp_path, monkeypatch):
    copies = []
    for p in kernels.KERNEL_SOURCES:
        q = tmp_path / p.name
        q.write_bytes(p.read_bytes())
        copies.append(q)
    monkeypatch.setattr(kernels, "KERNEL_SOURCES", tuple(copies))
    before = kernels.kernel_sources_digest()
    callee = next(q for q in copies if q.name == "mixed_pixels.py")
    callee.write_bytes(callee.read_bytes() + b"\n# an edit\n")
    after = kernels.kernel_sources_digest()
    assert after != before
    callee.write_bytes(callee.read_bytes()[: -len(b"\n# an edit\n")])
    assert kernels.kernel_sources_digest() == before  # the state, not the file's time


def test_a_user_cache_base_is_kept_and_stale_states_beside_it_removed(tmp_path):
    """In a fresh process with ``NUMBA_CACHE_DIR`` set: the kernels' directory is inside
    it, a compiled kernel's cache files land there, and a directory of another state of
    the sources is removed."""
    stale = tmp_path / "tofpose-kernels-0123456789abcdef"
    stale.mkdir()
    (stale / "old.nbi").write_bytes(b"x")
    other = tmp_path / "someone-else"
    other.mkdir()
    code = (
        "import numpy as np\n"
        "from tofpose import kernels\n"
        "from tofpose.kernels.stats import median_inplace\n"
        "median_inplace(np.arange(5.0))\n"
        "print(kernels.kernel_cache_dir())\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env={"NUMBA_CACHE_DIR": str(tmp_path), "PATH": "/usr/bin:/bin"},
                         check=True, timeout=600).stdout.strip().splitlines()[-1]  # fmt: skip
    assert out.startswith(str(tmp_path / "tofpose-kernels-"))
    assert not stale.exists() and other.exists()
    assert any(p.suffix == ".nbi" for p in (tmp_path / out.split("/")[-1]).rglob("*"))
