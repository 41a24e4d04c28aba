"""A campaign's raw recording as MCAP (``GET /api/campaigns/{id}/recording.mcap``).

The MCAP is made once from the campaign's HDF5 recording by ``tofpose.interop``'s
export (frames, references, and the pipeline's estimate of each frame with the
recording's camera and catalog) and kept beside it; it is made again only when the
recording is newer. One export per file at a time: a second request waits for the first.
"""

from __future__ import annotations

import threading
from pathlib import Path

from tofpose.interop.mcap_export import export_mcap
from tofpose.pipeline import PosePipeline
from tofpose.recording import open_recording

_locks: dict[Path, threading.Lock] = {}
_locks_guard = threading.Lock()


def _lock_for(path: Path) -> threading.Lock:
    with _locks_guard:
        return _locks.setdefault(path, threading.Lock())


def recording_mcap(recording_path: Path) -> Path:
    """The MCAP of ``recording_path`` (``.../campaign-N.h5`` -> ``.../campaign-N.mcap``),
    exported now unless an export newer than the recording exists."""
    out = recording_path.with_suffix(".mcap")
    with _lock_for(out):
        if out.exists() and out.stat().st_mtime_ns >= recording_path.stat().st_mtime_ns:
            return out
        with open_recording(recording_path) as rec:
            pipeline = PosePipeline(rec.camera, rec.catalog) if rec.catalog is not None else None
            export_mcap(rec, out, pipeline, progress=False, overwrite=True)
    return out
