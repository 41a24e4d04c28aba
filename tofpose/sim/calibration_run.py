"""A simulated range-calibration run: the known target at known poses, each pose at
several integration times (docs/algorithm.md, "Real ToF range errors": the spread of
amplitudes at one distance is what separates the amplitude-related error)."""

from __future__ import annotations

from collections.abc import Iterable, Iterator

import numpy as np

from tofpose.core.camera import CameraModel
from tofpose.core.catalog import Catalog
from tofpose.core.geometry import RigidTransform
from tofpose.sim.pixel_truth import true_pixel_distances
from tofpose.sim.render import SensorModel, render_frame
from tofpose.sim.scene import TargetScene
from tofpose.sim.systematic import SystematicErrors

EXPOSURE_FRACTIONS = (1.0, 1 / 3, 1 / 10)  # of the auto-exposure time at the pose's depth


def calibration_frames(
    camera: CameraModel,
    catalog: Catalog,
    errors: SystematicErrors,
    poses: Iterable[RigidTransform],
    rng: np.random.Generator,
    *,
    exposure_fractions: tuple[float, ...] = EXPOSURE_FRACTIONS,
    time_s: float = 0.0,
) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """(measured distance, gray, true distance), each (H, W) float, per rendered frame:
    what ``fit_range_correction`` takes. ``time_s``: time since power-on (drift)."""
    scene = TargetScene(catalog)
    for T in poses:
        truth = true_pixel_distances(camera, catalog, T)
        t_auto_us = SensorModel().exposure_for(float(T.t_mm[2]))
        for frac in exposure_fractions:
            sensor = SensorModel(
                systematic=errors, auto_exposure=False, integration_time_us=t_auto_us * frac
            )
            f = render_frame(camera, scene, T, sensor, rng, time_s=time_s)
            yield f.distance_mm.astype(float), f.gray.astype(float), truth
