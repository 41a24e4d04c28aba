"""HDF5 recording -> MCAP file (``tofpose export mcap``; docs/interop.md).

The file is written by ``foxglove-sdk``'s MCAP writer through ``ToFChannels``: one frame
at a time (memory stays bounded by the writer's chunk, ~1 MiB, whatever the length of
the recording), log times = the frames' capture times. A recording with ``/motion``
(the server's: recordings on demand, a campaign's raw recording) adds the turntable's
encoders and set-point of each frame (``motion_track``). What no channel carries (the
camera and catalog JSON, the pipeline's settings and version) is the MCAP metadata
record ``tofpose``.
"""

from __future__ import annotations

import dataclasses
import json
import sys
from pathlib import Path

import foxglove
import numpy as np
from tqdm import tqdm

import tofpose
from tofpose.io.interop import topics
from tofpose.io.interop.channels import ToFChannels
from tofpose.io.interop.foxglove_messages import time_ns_from_seconds
from tofpose.io.interop.motion_track import read_motion_track
from tofpose.io.recording import Recording
from tofpose.pipeline import PosePipeline

MCAP_FORMAT = "tofpose-mcap"
MCAP_VERSION = 1


def export_metadata(rec: Recording, pipeline: PosePipeline | None) -> dict[str, str]:
    """The ``tofpose`` metadata record (MCAP metadata values are strings)."""
    catalog = pipeline.catalog if pipeline is not None else rec.catalog
    camera = pipeline.camera if pipeline is not None else rec.camera
    return {
        "format": MCAP_FORMAT,
        "version": str(MCAP_VERSION),
        "tofpose_version": tofpose.__version__,
        "source": rec.path.name,
        "n_frames": str(rec.n_frames),
        "camera": camera.to_json(),
        "recording_camera": rec.camera.to_json(),
        "catalog": catalog.to_json() if catalog is not None else "",
        "recording_catalog": rec.catalog.to_json() if rec.catalog is not None else "",
        "pipeline_config": (
            json.dumps(dataclasses.asdict(pipeline.config), default=str)
            if pipeline is not None
            else ""
        ),
        "distance_unit": topics.DISTANCE_CHANNEL_METADATA["unit"],
        "has_truth": str(rec.truth_R is not None).lower(),
        "has_reference": str(rec.reference_R is not None).lower(),
    }


def pose_at(
    R: np.ndarray | None, t_mm: np.ndarray | None, i: int
) -> tuple[np.ndarray, np.ndarray] | None:
    """(R (3, 3), t (3,) mm) of frame ``i`` of a recording's reference poses (R (N, 3, 3),
    t (N, 3)), None where the recording has none (it holds both or neither)."""
    if R is None or t_mm is None:
        return None
    return R[i], t_mm[i]


def message_times_ns(rec) -> list[int]:
    """Each frame's message time (Unix ns): the wall clock when the recording has it
    (``Recording.wall_time_ns``: a recording made by the server), else its own time
    stamps (a simulated or imported recording's clock, which may start at 0)."""
    if rec.wall_time_ns is not None:
        return [int(t) for t in rec.wall_time_ns]
    return [time_ns_from_seconds(float(t)) for t in rec.time_s]


def export_mcap(
    rec: Recording,
    out: str | Path,
    pipeline: PosePipeline | None = None,
    *,
    progress: bool = True,
    overwrite: bool = False,
    previews: bool = True,
) -> dict[str, int]:
    """Write ``rec`` to ``out``; with a ``pipeline``, each frame's estimate too; with
    ``previews``, the images viewers display as they are (8-bit gray, coloured distance).

    Returns {"frames": N, "ok": frames with a pose}. ValueError (naming the frame) for a
    capture time MCAP cannot hold (negative)."""
    out = Path(out)
    if out.exists() and not overwrite:
        raise ValueError(f"{out} exists (pass --force to overwrite it)")
    times_ns = message_times_ns(rec)
    motion = read_motion_track(rec.path, rec.n_frames)
    context = foxglove.Context()
    channels = ToFChannels(
        context,
        rec.camera,
        estimate=pipeline is not None,
        truth=rec.truth_R is not None,
        reference=rec.reference_R is not None,
        previews=previews,
        trail=True,
        motion_fields=motion.fields if motion is not None else (),
    )
    n_ok = 0
    partial = out.with_name(out.name + ".partial")  # renamed when complete
    writer = foxglove.open_mcap(partial, allow_overwrite=True, context=context)
    done = False
    try:
        writer.write_metadata(topics.METADATA_NAME, export_metadata(rec, pipeline))
        for i in tqdm(
            range(rec.n_frames),
            desc="export mcap",
            unit="frame",
            disable=not progress,
            file=sys.stderr,
        ):
            gray, dist, t = rec.frame(i)
            result = pipeline.process(gray, dist, t) if pipeline is not None else None
            n_ok += int(result is not None and result.ok)
            truth = pose_at(rec.truth_R, rec.truth_t_mm, i)
            lab = pose_at(rec.reference_R, rec.reference_t_mm, i)
            channels.log_frame(i, gray, dist, t, times_ns[i], result, truth, lab)
            if motion is not None:
                sp = motion.setpoint_index
                channels.log_motion(
                    i,
                    motion.positions[i],
                    motion.targets[i],
                    int(sp[i]) if sp is not None and sp[i] >= 0 else None,
                    times_ns[i],
                )
        done = True
    finally:
        writer.close()
        channels.close()
        if done:
            partial.replace(out)
        else:
            partial.unlink(missing_ok=True)
    return {"frames": rec.n_frames, "ok": n_ok}
