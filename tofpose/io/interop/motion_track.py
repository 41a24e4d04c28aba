"""The turntable's encoders and set-points of a recording, per frame (docs/interop.md).

Recordings made by the server carry them in ``/motion`` (the recordings on demand,
``backend.services.recordings``; a campaign's raw recording,
``backend.services.campaigns.campaign_recording``)::

    /motion   attrs: axes (names), units (deg / mm)
    /motion/positions        float64 (N, A)  encoders at each frame, NaN = no reading
    /motion/targets          float64 (N, A)  the set-point, NaN = not commanded
    /motion/setpoint_index   int32 (N,)      a campaign's set-point index   optional

Read here beside ``tofpose.io.recording`` (whose ``Recording`` skips optional groups),
for the MCAP export's ``/tofpose/motion/*`` channels.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np


@dataclass(frozen=True)
class MotionTrack:
    """axes : names, e.g. ("yaw", "pitch", "roll", "rail"); units : one per axis ("deg",
    "mm"); positions, targets : ndarray of shape (N, A); setpoint_index : ndarray of shape
    (N,) int, or None (a recording on demand has no set-point numbers)."""

    axes: tuple[str, ...]
    units: tuple[str, ...]
    positions: np.ndarray
    targets: np.ndarray
    setpoint_index: np.ndarray | None = None

    @property
    def fields(self) -> tuple[str, ...]:
        """Each axis' JSON field: its name and unit (``yaw_deg``, ``rail_mm``)."""
        return tuple(f"{a}_{u}" for a, u in zip(self.axes, self.units, strict=True))


def _text(values) -> tuple[str, ...]:
    return tuple(v.decode() if isinstance(v, bytes) else str(v) for v in values)


def read_motion_track(path: str | Path, n_frames: int) -> MotionTrack | None:
    """The ``/motion`` group of the recording at ``path`` (``n_frames`` frames), None when
    it has none; ValueError naming the file and the dataset whose shape does not hold a
    row per frame and a column per axis."""
    with h5py.File(path, "r") as f:
        group = f.get("motion")
        if group is None:
            return None
        axes, units = _text(group.attrs.get("axes", ())), _text(group.attrs.get("units", ()))
        if not axes or len(units) != len(axes):
            raise ValueError(
                f"{path}: /motion needs the attributes axes and units, one unit per axis "
                f"(has {len(axes)} axes and {len(units)} units)"
            )
        arrays = {}
        for name in ("positions", "targets"):
            ds = group.get(name)
            if ds is None or ds.shape != (n_frames, len(axes)):
                shape = None if ds is None else ds.shape
                raise ValueError(
                    f"{path}: /motion/{name} has shape {shape}, expected ({n_frames}, {len(axes)})"
                )
            arrays[name] = np.asarray(ds[...], float)
        index = group.get("setpoint_index")
        if index is not None and index.shape != (n_frames,):
            raise ValueError(
                f"{path}: /motion/setpoint_index has shape {index.shape}, expected ({n_frames},)"
            )
        return MotionTrack(
            axes,
            units,
            arrays["positions"],
            arrays["targets"],
            None if index is None else np.asarray(index[...], np.int64),
        )
