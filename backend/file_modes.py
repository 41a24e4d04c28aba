"""Owner-only file modes for the server's data: the database, recordings, study and
re-processing outputs and the API token are readable by the user who runs the server
only (files 0600, directories 0700), not by every account on the lab machine.

``restrict_data_dir`` does two things, at the start of the server (before it creates
anything in the data directory):

- sets the process umask to ``0o077``, so that every file and directory the server
  creates from then on (SQLite's database and journal, HDF5 recordings, study outputs)
  is born owner-only, whatever the library that creates it asks for;
- tightens what is already there from an earlier run or an older version: every
  directory under ``data_dir`` (and ``data_dir`` itself) to 0700, every regular file to
  0600. Symbolic links are neither changed nor followed (a link in the data directory
  may point at a shared file elsewhere: its target is not ours to tighten); sockets,
  FIFOs and devices are left as they are. ``data_dir`` itself may be a link (a data
  directory on another disk): its target is the directory tightened.

The walk holds each directory open (``os.fwalk``), so a directory swapped for a link
while it runs is not followed. A file swapped for a link between its check and its
``chmod`` would be followed: only someone who can write into the data directory can do
that, and after the first tightening that is the server's own user alone.

The umask is process-wide: files the server writes elsewhere (a report saved to a path
the user names) are owner-only too.
"""

from __future__ import annotations

import logging
import os
import stat
from pathlib import Path

log = logging.getLogger("tofpose.server")

UMASK = 0o077
DIR_MODE = 0o700
FILE_MODE = 0o600


def restrict_data_dir(data_dir: Path) -> None:
    """Set the umask to 0o077 and make everything under ``data_dir`` owner-only.

    Parameters
    ----------
    data_dir : Path
        The server's data directory (``Settings.data_dir``). When it does not exist yet
        only the umask is set (it is then created owner-only).

    A file or directory whose mode cannot be changed (another user's) is logged as a
    warning and left as it is; the server still starts.
    """
    os.umask(UMASK)
    root = Path(data_dir).resolve()
    if not root.is_dir():
        return
    for path, _dirs, files, dir_fd in os.fwalk(root, follow_symlinks=False):
        _chmod_dir(dir_fd, Path(path))
        for name in files:
            _chmod_file(dir_fd, name, Path(path) / name)


def _chmod_dir(dir_fd: int, path: Path) -> None:
    """Tighten the directory open at ``dir_fd`` (no link can stand in for it)."""
    try:
        if stat.S_IMODE(os.fstat(dir_fd).st_mode) != DIR_MODE:
            os.fchmod(dir_fd, DIR_MODE)
    except OSError as exc:
        log.warning("cannot make %s owner-only (mode %o): %s", path, DIR_MODE, exc)


def _chmod_file(dir_fd: int, name: str, path: Path) -> None:
    """Tighten the entry ``name`` of the directory at ``dir_fd`` when it is a regular
    file (``os.fwalk`` lists links and special files among the files too)."""
    try:
        st = os.stat(name, dir_fd=dir_fd, follow_symlinks=False)
        if stat.S_ISREG(st.st_mode) and stat.S_IMODE(st.st_mode) != FILE_MODE:
            os.chmod(name, FILE_MODE, dir_fd=dir_fd)
    except OSError as exc:
        log.warning("cannot make %s owner-only (mode %o): %s", path, FILE_MODE, exc)
