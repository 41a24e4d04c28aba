"""A campaign's raw recording: the project's HDF5 recording (docs/architecture.md §7)
with, per frame, when it was captured and where the turntable was and was sent.

The optional datasets use the layout of the recordings on demand (docs/server.md,
``backend.services.recordings``), so one reader (``tofpose.io.interop.motion_track``)
and the MCAP export's encoder and set-point channels serve both::

    /frames/wall_time_ns     int64 (N,)      UTC ns when the frame came from the driver
    /motion   attrs: axes (names), units (deg / mm): the set-point's axes (AXIS_COLUMNS)
    /motion/positions        float64 (N, A)  the encoders at the frame (a dynamic
                                             set-point's interpolated to its capture
                                             time: the measurement row's ``encoders``);
                                             NaN for an axis the frame has no reading of
    /motion/targets          float64 (N, A)  the set-point the frame was measured at;
                                             NaN for an axis it leaves where it is
    /motion/setpoint_index   int32 (N,)      that set-point's index in the campaign

A recording begun before these datasets existed is continued without them (all or
none, every one with a row per frame).
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

from tofpose.core.camera import CameraModel
from tofpose.core.catalog import Catalog
from tofpose.io.recording import RecordingWriter

#: the datasets ``CampaignRecordingWriter`` adds: (path, per-frame shape, dtype)
WALL_TIME = "frames/wall_time_ns"
POSITIONS = "motion/positions"
TARGETS = "motion/targets"
SETPOINT_INDEX = "motion/setpoint_index"


class CampaignRecordingWriter(RecordingWriter):
    """``RecordingWriter`` plus the module docstring's per-frame datasets, for the axes
    ``axes`` ({name: unit}); ``append_motion`` follows each ``append``."""

    def __init__(
        self,
        path: str | Path,
        camera: CameraModel,
        catalog: Catalog | None,
        *,
        axes: dict[str, str],
        with_truth: bool = False,
        with_reference: bool = False,
    ) -> None:
        super().__init__(
            path, camera, catalog, with_truth=with_truth, with_reference=with_reference
        )
        f, a = self._f, (len(axes),)
        self._columns: dict[str, h5py.Dataset] = {}
        for name, shape, dtype in (
            (WALL_TIME, (), np.int64),
            (POSITIONS, a, np.float64),
            (TARGETS, a, np.float64),
            (SETPOINT_INDEX, (), np.int32),
        ):
            self._columns[name] = f.create_dataset(
                name, (0, *shape), dtype, maxshape=(None, *shape), chunks=(256, *shape)
            )
        f["motion"].attrs["axes"] = list(axes)
        f["motion"].attrs["units"] = list(axes.values())
        self.axes = tuple(axes)

    @classmethod
    def reopen(cls, path: str | Path) -> CampaignRecordingWriter:
        """Continue a recording; without every dataset of this module at one row per
        frame (a recording begun by an earlier version) it goes on without them."""
        self = super().reopen(path)
        assert isinstance(self, CampaignRecordingWriter)  # RecordingWriter.reopen makes a cls
        f = self._f
        names = (WALL_TIME, POSITIONS, TARGETS, SETPOINT_INDEX)
        complete = all(n in f and f[n].shape[0] == self.n for n in names)
        self._columns = {n: f[n] for n in names} if complete else {}
        self.axes = tuple(str(a) for a in f["motion"].attrs["axes"]) if complete else ()
        return self

    def append_motion(
        self,
        wall_time_ns: int,
        encoders: dict[str, float],
        setpoint: dict[str, float],
        setpoint_index: int,
    ) -> None:
        """The last appended frame's row: its wall clock (UTC ns), encoders and set-point
        ({axis: deg / mm}; an axis missing is NaN). Nothing for a recording without the
        datasets (``reopen``)."""
        if not self._columns:
            return
        n = self.n - 1
        row = {
            WALL_TIME: int(wall_time_ns),
            POSITIONS: [float(encoders.get(a, np.nan)) for a in self.axes],
            TARGETS: [float(setpoint.get(a, np.nan)) for a in self.axes],
            SETPOINT_INDEX: int(setpoint_index),
        }
        for name, ds in self._columns.items():
            ds.resize(n + 1, axis=0)
            ds[n] = row[name]

    def truncate(self, n: int) -> None:
        super().truncate(n)
        for ds in getattr(self, "_columns", {}).values():
            ds.resize(n, axis=0)
