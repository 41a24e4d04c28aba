"""tofpose: 6-DOF pose of a cooperative target from Time-of-Flight frames.

Implements Zhu et al., "System Design for Pose Determination of Spacecraft Using
Time-of-Flight Sensors" (Space: Science & Technology, 2022). Lengths are millimetres,
angles radians inside the maths and degrees at the edges. See ``docs/architecture.md``.

The names below are imported on first use (PEP 562), so that ``import tofpose`` and the
command line's ``--help`` load neither numba's kernels nor OpenCV.
"""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from tofpose.core.camera import CameraModel
    from tofpose.core.catalog import Catalog, Reflector, paper_target
    from tofpose.pipeline import PipelineConfig, PosePipeline, PoseResult

#: each public name and the module that defines it
_LAZY = {
    "CameraModel": "tofpose.core.camera",
    "Catalog": "tofpose.core.catalog",
    "Reflector": "tofpose.core.catalog",
    "paper_target": "tofpose.core.catalog",
    "PipelineConfig": "tofpose.pipeline",
    "PosePipeline": "tofpose.pipeline",
    "PoseResult": "tofpose.pipeline",
}

__all__ = [
    "CameraModel",
    "Catalog",
    "PipelineConfig",
    "PosePipeline",
    "PoseResult",
    "Reflector",
    "paper_target",
]
__version__ = "0.1.0"


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        value = getattr(import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'tofpose' has no attribute {name!r}")
