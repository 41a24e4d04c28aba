"""The measurement's arithmetic (§3.4, Eqs. 7-9) per implementation: ``COMPILED``
(``kernels.measure``, ``CameraModel.bearings``) and ``REFERENCE`` (``reference.measure``,
``core.reference.camera``)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from tofpose.core.camera import CameraModel
from tofpose.core.reference import camera as ref_camera
from tofpose.stages.persistence.kernels import measure
from tofpose.stages.persistence.reference import measure as ref_measure


@dataclass(frozen=True)
class PersistenceArithmetic:
    """Persistence, centroids and back-projection of every blob in one call
    (``kernels.measure.measure_and_back_project``'s arguments and returns) and Eq. 9's
    bearings as ``CameraModel.bearings(camera, uv)``."""

    name: str
    measure_and_back_project: Callable
    bearings: Callable[[CameraModel, np.ndarray], np.ndarray]


def _reference_bearings(camera: CameraModel, uv: np.ndarray) -> np.ndarray:
    """Eq. 9 (``core.reference.camera.bearings``) for ``CameraModel.bearings``' arguments."""
    return ref_camera.bearings(np.asarray(uv, float).reshape(-1, 2), camera.K, camera.dist_array)


COMPILED = PersistenceArithmetic("compiled", measure.measure_and_back_project, CameraModel.bearings)
REFERENCE = PersistenceArithmetic(
    "reference", ref_measure.measure_and_back_project, _reference_bearings
)
