"""Compile (or load from numba's on-disk cache) every pipeline kernel before live frames.

The pipeline's inner loops are compiled on first use (``tofpose.core.compiled``): about a minute on
a
fresh install, ~0.3 s once the cache exists. The warm-up does it once, at a moment of the
caller's choosing: ``tofpose warm-up`` after installing (``make test`` and the Dockerfile
run it), and the server in a background thread while its acquisition loop already runs
(``backend/services/live/kernel_warmup.py``). It has two stages, what a live loop needs first:

1. ``warm_up_reference()``: the few kernels that the reference implementation
   (``PosePipeline(..., implementation="reference")``, every stage in NumPy/SciPy) still
   calls, the ones ``tofpose.arithmetic`` names as not covered: the frame check's float32
   conversion (``stages.extraction.kernels.levels.checked_frame``, ``clean_distance``, once per
   distance
   dtype), the persistence history's pixel masks
   (``stages.persistence.kernels.persistence.pixel_mask``)
   and the camera's bearings and projection (``core.kernels.camera``, built into the
   pipeline's camera record; the 3-D scene projects with them). About 1 s from an empty
   cache. After it a reference pipeline compiles nothing, so a server can measure with
   it while the second stage compiles in another thread: a kernel first called from the
   live loop would compile there, stopping the loop for as long (numba compiles one
   kernel at a time, process-wide).
2. ``warm_up()``: the compiled pipeline over a few simulated frames that take every
   compiled path (acquisition, persistence over the full history, tracking in one call
   with and without a range correction, merged markers split by ellipse confirmation, the
   paper's LOS refinement, the RANSAC matcher). It runs ``warm_up_reference`` first, then the
   live loop's configuration (tracking on), where most of its time goes.
"""

from __future__ import annotations

import time

import numpy as np

from tofpose.calibration.range import RangeCorrection
from tofpose.config import PixelFitConfig, TrackingConfig
from tofpose.core.camera import CameraModel
from tofpose.core.catalog import paper_target
from tofpose.core.geometry import RigidTransform, rotation_from_euler_deg
from tofpose.pipeline import PipelineConfig, PosePipeline
from tofpose.sim.bench import R_FACING
from tofpose.sim.render import SensorModel, render_frame
from tofpose.sim.scene import TargetScene
from tofpose.stages.ellipses.kernels.pair_fit import fit_pair_lm
from tofpose.stages.ellipses.kernels.two_centres import two_centre_split
from tofpose.stages.extraction.kernels.levels import checked_frame, clean_distance
from tofpose.stages.persistence.kernels.persistence import pixel_mask

_done = False
_reference_done = False


def warm_up_reference() -> float:
    """Compile the kernels the reference pipeline calls (stage 1, module docstring), once
    per process (later calls return at once); returns the seconds it took."""
    global _reference_done
    if _reference_done:
        return 0.0
    t0 = time.perf_counter()
    # distance images arrive as float32 (cameras) or float64 (some recordings), counts
    # as uint16 or as floats: the frame check compiles once per dtype
    for distance_dtype in (np.float32, np.float64):
        clean_distance(np.zeros((1, 1), distance_dtype))
        checked_frame(np.zeros((1, 1), np.uint16), np.zeros((1, 1), distance_dtype))
    # a tracked frame's candidate pixels (flat indices) as the history keeps them
    pixel_mask(np.zeros(1, np.int64), 1)
    cam = CameraModel()
    cam.bearings(np.zeros((1, 2)))
    cam.project(np.array([[0.0, 0.0, 1000.0]]))
    _reference_done = True
    return time.perf_counter() - t0


def warm_up() -> float:
    """Run ``warm_up_reference``, then the compiled pipeline on simulated frames through
    every compiled path, once per process (later calls return at once); returns the
    seconds it took (the compile or cache-load time, 0 when already done)."""
    global _done
    if _done:
        return 0.0
    t0 = time.perf_counter()
    warm_up_reference()
    cam, cat = CameraModel(), paper_target()
    rng = np.random.default_rng(0)
    R = rotation_from_euler_deg(2.0, -3.0, 10.0) @ R_FACING
    configs = (
        PipelineConfig(tracking=TrackingConfig(enabled=True)),  # the live loop's
        PipelineConfig.paper(),
        PipelineConfig(matcher="ransac"),
        PipelineConfig(refinement="none"),
        PipelineConfig(pixel_fit=PixelFitConfig(enabled=True)),  # estimate --pixel-fit
    )
    # 1.5 m (ellipses confirmed), 6 m (markers 7 and 8 merge: split by threshold)
    for z_mm in (1500.0, 6000.0):
        T = RigidTransform(R, np.array([0.0, -30.0, z_mm]))
        frames = [render_frame(cam, TargetScene(), T, SensorModel(), rng) for _ in range(7)]
        for i, config in enumerate(configs):
            pipe = PosePipeline(cam, cat, config)
            for f in frames if i == 0 else frames[:2]:
                pipe.process(f.gray, f.distance_mm)
        # a range-corrected camera: the correction kernel in acquisition and tracking
        correction = RangeCorrection(SensorModel().unambiguous_range_mm)
        pipe = PosePipeline(cam, cat, configs[0], range_correction=correction)
        for f in frames[:3]:
            pipe.process(f.gray, f.distance_mm)
    # the merged-pair fit runs only where two reflectors merge (and a frame at 6 m need
    # not have them merged): compiled here on a one-pixel problem
    p0 = np.array([0.0, 0.0, 1.0, 0.0, 1.0, 1.0, 1.0, 0.5, 0.0])
    fit_pair_lm(
        np.zeros((1, 9)), np.zeros((1, 9)), np.ones(1), p0, p0 - 1.0, p0 + 1.0, 1, 1e-4, 1e-9
    )
    two_centre_split(np.array([0.0, 1.0, 2.0]), np.zeros(3), np.ones(3), 1)
    _done = True
    return time.perf_counter() - t0
