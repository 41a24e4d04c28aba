"""A campaign's raw recording as MCAP (``GET /api/campaigns/{id}/recording.mcap``).

The MCAP is made from a copy of the campaign's HDF5 recording (so a campaign resumed
meanwhile can append to the original) by ``tofpose.interop``'s export: frames,
references, and the pipeline's estimate of each frame with the recording's camera and
catalog and default settings (tracking off). It is kept beside the recording with a note
of the recording's size and modification time, and made again when they change. One
export per file at a time: a second request waits for the first.
"""

from __future__ import annotations

import json
import shutil
import threading
from pathlib import Path

_locks: dict[Path, threading.Lock] = {}
_locks_guard = threading.Lock()


def _lock_for(path: Path) -> threading.Lock:
    with _locks_guard:
        return _locks.setdefault(path, threading.Lock())


def _stamp(path: Path) -> dict[str, int]:
    st = path.stat()
    return {"size": st.st_size, "mtime_ns": st.st_mtime_ns}


def recording_mcap(recording_path: Path) -> Path:
    """The MCAP of ``recording_path`` (``.../campaign-N.h5`` -> ``.../campaign-N.mcap``),
    exported now unless one made from the recording as it is now exists."""
    from tofpose.interop.mcap_export import export_mcap  # lazy: loads foxglove-sdk
    from tofpose.pipeline import PosePipeline
    from tofpose.recording import open_recording

    out = recording_path.with_suffix(".mcap")
    note = recording_path.with_suffix(".mcap.json")
    with _lock_for(out):
        stamp = _stamp(recording_path)
        if out.exists() and note.exists() and json.loads(note.read_text()) == stamp:
            return out
        copy = recording_path.with_suffix(".export.h5")
        try:
            shutil.copyfile(recording_path, copy)
            with open_recording(copy) as rec:
                pipeline = (PosePipeline(rec.camera, rec.catalog)
                            if rec.catalog is not None else None)  # fmt: skip
                export_mcap(rec, out, pipeline, progress=False, overwrite=True)
        finally:
            copy.unlink(missing_ok=True)
        note.write_text(json.dumps(stamp))
    return out
