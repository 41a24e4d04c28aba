"""A recording's MCAP export refuses to start when it could fill the disk (it copies the
recording and writes an MCAP of about its size), and names what it needs."""

from __future__ import annotations

from collections import namedtuple

import pytest

from backend.services.campaigns import mcap_files
from backend.services.campaigns.mcap_files import ExportSpaceError, recording_mcap

Usage = namedtuple("Usage", "total used free")


def test_an_export_that_would_fill_the_disk_is_refused_before_anything_is_written(
    tmp_path, monkeypatch
):
    rec = tmp_path / "campaign-1.h5"
    rec.write_bytes(b"\0" * (3 * 2**20))  # 3 MB: the export needs 6 MB + the floor
    monkeypatch.setattr(mcap_files.shutil, "disk_usage", lambda _p: Usage(10**12, 0, 100 * 2**20))
    with pytest.raises(ExportSpaceError, match=r"100 MB free, 106 MB needed .*= 100\)"):
        recording_mcap(rec, min_free_mb=100)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["campaign-1.h5"]  # nothing written
