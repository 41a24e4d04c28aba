"""restrict_data_dir on a temporary tree: what was world-readable becomes owner-only,
links are neither changed nor followed, and what the server creates afterwards is born
owner-only."""

from __future__ import annotations

import logging
import os
import stat
from pathlib import Path

import pytest

from backend import file_modes
from backend.file_modes import restrict_data_dir


@pytest.fixture(autouse=True)
def restore_umask():
    """restrict_data_dir sets the process umask: give the test process its own back."""
    before = os.umask(0o022)
    yield
    os.umask(before)


def mode(path: Path) -> int:
    return stat.S_IMODE(os.lstat(path).st_mode)


def _tree(root: Path, files: dict[str, int], dirs: dict[str, int]) -> None:
    for rel in dirs:
        (root / rel).mkdir(parents=True, exist_ok=True)
    for rel, m in files.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_bytes(b"x")
        os.chmod(root / rel, m)
    for rel, m in sorted(dirs.items(), key=lambda kv: -kv[0].count("/")):
        os.chmod(root / rel, m)


def test_an_open_tree_becomes_owner_only(tmp_path):
    data = tmp_path / "data"
    files = {
        "tofpose.db": 0o644,
        "tofpose.db-journal": 0o664,
        "api_token": 0o600,
        "campaigns/3/raw.h5": 0o644,
        "campaigns/3/notes.txt": 0o755,
        "studies/7/study.json": 0o666,
        "studies/7/frames/f000.npz": 0o444,
    }
    dirs = {
        ".": 0o755,
        "campaigns": 0o755,
        "campaigns/3": 0o775,
        "studies": 0o777,
        "studies/7": 0o755,
        "studies/7/frames": 0o700,
    }
    _tree(data, files, dirs)

    restrict_data_dir(data)

    assert {rel: mode(data / rel) for rel in files} == dict.fromkeys(files, 0o600)
    assert {rel: mode(data / rel) for rel in dirs} == dict.fromkeys(dirs, 0o700)


def test_links_are_neither_changed_nor_followed_and_special_files_are_left(tmp_path):
    shared = tmp_path / "shared"
    _tree(shared, {"catalog.json": 0o644, "sub/readme": 0o644}, {".": 0o755, "sub": 0o755})
    data = tmp_path / "data"
    _tree(data, {"tofpose.db": 0o644}, {".": 0o755})
    (data / "catalog.json").symlink_to(shared / "catalog.json")
    (data / "shared").symlink_to(shared, target_is_directory=True)
    (data / "dangling").symlink_to(tmp_path / "nowhere")
    os.mkfifo(data / "pipe", 0o644)
    os.chmod(data / "pipe", 0o644)

    restrict_data_dir(data)

    assert mode(data / "tofpose.db") == 0o600 and mode(data) == 0o700
    # the links' targets outside the data directory keep their modes
    assert mode(shared) == mode(shared / "sub") == 0o755
    assert mode(shared / "catalog.json") == mode(shared / "sub" / "readme") == 0o644
    assert (data / "catalog.json").is_symlink() and (data / "shared").is_symlink()
    assert mode(data / "pipe") == 0o644  # not opened (that would block), not changed


def test_a_data_dir_that_is_a_link_has_its_target_tightened(tmp_path):
    real = tmp_path / "disk" / "tofpose-data"
    _tree(real, {"tofpose.db": 0o644}, {".": 0o755})
    link = tmp_path / "data"
    link.symlink_to(real, target_is_directory=True)

    restrict_data_dir(link)

    assert mode(real) == 0o700 and mode(real / "tofpose.db") == 0o600


def test_what_is_created_afterwards_is_owner_only(tmp_path):
    data = tmp_path / "data"
    restrict_data_dir(data)  # not there yet: only the umask is set, nothing is created
    assert not data.exists()

    data.mkdir()
    (data / "recordings").mkdir()
    (data / "recordings" / "run.h5").write_bytes(b"x")  # open(..., 0o666) as h5py does
    fd = os.open(data / "tofpose.db", os.O_CREAT | os.O_WRONLY, 0o644)  # as SQLite does
    os.close(fd)

    assert mode(data) == mode(data / "recordings") == 0o700
    assert mode(data / "recordings" / "run.h5") == mode(data / "tofpose.db") == 0o600
    assert os.umask(0o077) == 0o077


def test_an_entry_that_cannot_be_changed_is_named_in_a_warning_and_the_rest_is_done(
    tmp_path, monkeypatch, caplog
):
    data = tmp_path / "data"
    _tree(data, {"a.h5": 0o644, "theirs.h5": 0o644, "z.h5": 0o644}, {".": 0o755})
    real_chmod = os.chmod

    def chmod(path, m, **kw):
        if path == "theirs.h5":  # another user's file: only its owner or root may chmod
            raise PermissionError(1, "Operation not permitted")
        return real_chmod(path, m, **kw)

    monkeypatch.setattr(file_modes.os, "chmod", chmod)
    with caplog.at_level(logging.WARNING, logger="tofpose.server"):
        restrict_data_dir(data)

    assert mode(data / "a.h5") == mode(data / "z.h5") == 0o600
    assert mode(data / "theirs.h5") == 0o644
    assert len(caplog.records) == 1
    assert str(data.resolve() / "theirs.h5") in caplog.records[0].getMessage()
