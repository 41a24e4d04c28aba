"""A campaign's raw recording as MCAP (``GET /api/campaigns/{id}/recording.mcap``).

Either profile (``?profile=foxglove|ros2``, ``tofpose.io.interop.MCAP_PROFILES``):
Foxglove's schemas (``rec.mcap``) or ROS 2 messages (``rec.ros2.mcap``). The MCAP is
made from a copy of the campaign's HDF5 recording (so a campaign resumed meanwhile can
append to the original) by ``tofpose.io.interop``'s export: frames, references, and the
pipeline's estimate of each frame with the recording's camera and catalog and default
settings (tracking off). It is kept beside the recording with a note of the recording's
size and modification time, and made again when they change. One export per file at a
time: a second request waits for the first.
"""

from __future__ import annotations

import json
import shutil
import threading
from pathlib import Path

from tofpose.io.interop import DEFAULT_MCAP_PROFILE, MCAP_SUFFIXES

_locks: dict[Path, threading.Lock] = {}
_locks_guard = threading.Lock()


def _lock_for(path: Path) -> threading.Lock:
    with _locks_guard:
        return _locks.setdefault(path, threading.Lock())


def _stamp(path: Path) -> dict[str, int]:
    st = path.stat()
    return {"size": st.st_size, "mtime_ns": st.st_mtime_ns}


class ExportSpaceError(OSError):
    """Too little free disk space to export: the sentence says how much is needed."""


def _check_space(recording_path: Path, min_free_mb: float) -> None:
    """The export copies the recording and writes an MCAP of about its size: refuse
    (``ExportSpaceError``) unless twice its size plus ``min_free_mb`` are free, so that an
    export never fills the disk the database and recordings share."""
    need_mb = 2 * recording_path.stat().st_size / 2**20 + min_free_mb
    free_mb = shutil.disk_usage(recording_path.parent).free / 2**20
    if free_mb < need_mb:
        raise ExportSpaceError(
            f"not enough free disk space to export {recording_path.name} to MCAP: "
            f"{free_mb:.0f} MB free, {need_mb:.0f} MB needed (twice the recording, plus "
            f"TOFPOSE_RECORDING_MIN_FREE_MB = {min_free_mb:g})"
        )


def recording_mcap(
    recording_path: Path, min_free_mb: float = 0.0, profile: str = DEFAULT_MCAP_PROFILE
) -> Path:
    """The MCAP of ``recording_path`` in ``profile`` (``.../campaign-N.h5`` ->
    ``.../campaign-N.mcap``, ``.../campaign-N.ros2.mcap``), exported now unless one made
    from the recording as it is now exists; a new export needs twice the recording's size
    plus ``min_free_mb`` free (``ExportSpaceError``). ValueError naming an unknown profile."""
    from tofpose.io.interop.mcap_profiles import (  # lazy: loads foxglove-sdk
        check_profile,
        export_mcap_profile,
    )
    from tofpose.io.recording import open_recording
    from tofpose.pipeline import PosePipeline

    out = recording_path.with_suffix(MCAP_SUFFIXES[check_profile(profile)])
    note = out.with_name(out.name + ".json")
    with _lock_for(out):
        stamp = _stamp(recording_path)
        if out.exists() and note.exists() and json.loads(note.read_text()) == stamp:
            return out
        _check_space(recording_path, min_free_mb)
        copy = recording_path.with_suffix(f".{profile}.export.h5")  # profiles run at once
        try:
            shutil.copyfile(recording_path, copy)
            with open_recording(copy) as rec:
                pipeline = (
                    PosePipeline(rec.camera, rec.catalog) if rec.catalog is not None else None
                )
                export_mcap_profile(
                    rec, out, pipeline, profile=profile, progress=False, overwrite=True
                )
        finally:
            copy.unlink(missing_ok=True)
        note.write_text(json.dumps(stamp))
    return out
