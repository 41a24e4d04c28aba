"""The tracking stage's arithmetic per implementation: ``COMPILED`` (its kernels) and
``REFERENCE`` (``reference``), each field with the kernel's calling convention."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from tofpose.stages.tracking.kernels import tracking, tracking_frame
from tofpose.stages.tracking.reference import tracking as ref_tracking
from tofpose.stages.tracking.reference import tracking_frame as ref_tracking_frame


@dataclass(frozen=True)
class TrackingArithmetic:
    """Search windows around the predicted reflectors and the one-call tracked frame."""

    name: str
    camera_windows: Callable
    search_windows: Callable
    any_shared: Callable
    track_frame: Callable


COMPILED = TrackingArithmetic(
    "compiled",
    tracking.camera_windows,
    tracking.search_windows,
    tracking.any_shared,
    tracking_frame.track_frame,
)
REFERENCE = TrackingArithmetic(
    "reference",
    ref_tracking.camera_windows,
    ref_tracking.search_windows,
    ref_tracking.any_shared,
    ref_tracking_frame.track_frame,
)
