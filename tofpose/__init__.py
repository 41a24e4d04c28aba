"""tofpose: 6-DOF pose of a cooperative target from Time-of-Flight frames.

Implements Zhu et al., "System Design for Pose Determination of Spacecraft Using
Time-of-Flight Sensors" (Space: Science & Technology, 2022). Lengths are millimetres,
angles radians inside the maths and degrees at the edges. See ``docs/architecture.md``.
"""

from tofpose.core.camera import CameraModel
from tofpose.core.catalog import Catalog, Reflector, paper_target
from tofpose.pipeline import PipelineConfig, PosePipeline, PoseResult

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
