"""Tracking mode in one compiled call per frame (``kernels.tracking_frame.track_frame``;
with ``implementation="reference"``, its statement ``reference.tracking_frame``).

``PosePipeline`` tracks through ``CompiledTracker``, with or without a calibrated range
correction; this is the one implementation of tracking. Its stages are tested against
``tofpose.reference`` (each kernel's test, and every tracked pose against the reference
ML fit of its own measurements in ``tests/tofpose/stages/tracking/test_tracking_frame.py``); the A/B
harness ``bench/ab.py`` holds its answers fixed across changes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tofpose.calibration.range import RangeCorrection, correction_kernel_arguments
from tofpose.config import SolveConfig, TrackingConfig
from tofpose.core.camera import CameraModel
from tofpose.core.catalog import Catalog
from tofpose.core.records import FrameRecord, camera_record, catalog_record
from tofpose.stages.extraction.saturation import pixel_lists_at_full_scale
from tofpose.stages.extraction.uncertainty import SigmaFloors, kernel_constants
from tofpose.stages.persistence.persistence import Persistence, PersistenceInfo
from tofpose.stages.pose.records import NO_OFFSET, RangeOffsetPrior
from tofpose.stages.pose.solve import (
    Measurements,
    PoseSolver,
    Solution,
    ThresholdedFrame,
    fit_settings,
    matched_observations,
)
from tofpose.stages.tracking.arithmetic import COMPILED, TrackingArithmetic
from tofpose.stages.tracking.constants import TRACKED
from tofpose.stages.tracking.tracking import TrackState


@dataclass(frozen=True)
class Tracked:
    """A tracked frame: the solved pose, the measurements it came from, what
    persistence combined, and ``saturated`` (n,) bool: whether each of the n measured
    blobs has a pixel at the camera's full scale in this frame."""

    solution: Solution
    measurements: Measurements
    persistence: PersistenceInfo
    saturated: np.ndarray


class CompiledTracker:
    """Runs tracking frames through ``track_frame`` for one pipeline's camera, catalog,
    §5 and tracking settings, solver and persistence history."""

    def __init__(
        self,
        camera: CameraModel,
        catalog: Catalog,
        config: SolveConfig,
        tracking: TrackingConfig,
        solver: PoseSolver,
        persistence: Persistence,
        correction: RangeCorrection | None = None,
        *,
        arithmetic: TrackingArithmetic = COMPILED,
    ) -> None:
        """``correction``: the camera's calibrated range correction, or None;
        ``arithmetic``: whose ``track_frame`` and ``camera_windows`` run the frames
        (``tofpose.arithmetic``)."""
        self.camera = camera
        self._arithmetic = arithmetic
        self.config = config
        self.tracking = tracking
        self._solver = solver
        self._persistence = persistence
        self._xyz = np.ascontiguousarray(catalog.positions_mm, dtype=float)
        # the arguments of ``track_frame`` that do not change from frame to frame, as the
        # kernels' records (``core.records``), built where the acquisition path builds them
        self._camera_record = camera_record(camera)
        self._catalog_record = catalog_record(catalog)
        self._fit_args = (
            correction_kernel_arguments(correction),
            kernel_constants(
                SigmaFloors(
                    centroid_sigma_floor_px=config.centroid_sigma_floor_px,
                    range_sigma_floor_mm=config.range_sigma_floor_mm,
                )
            ),
            fit_settings(config),
        )

    def _offset_prior(self, track: TrackState, cat_idx: np.ndarray) -> RangeOffsetPrior:
        """The common range offset's prior for this frame: the solver's, for the windowed
        reflectors at their ranges at the predicted pose (the calibrated sigma only where
        the range correction's span holds them all; their image size and the acquisition
        frame's lens blur set the image scale's part, ``solve.centroid_bias_factor``)."""
        if not self.config.estimate_range_offset:
            return NO_OFFSET
        p = self._xyz[cat_idx] @ np.asarray(track.R).T + np.asarray(track.t_mm)
        range_mm = np.sqrt((p * p).sum(axis=1))  # |p| (linalg.norm's)
        return self._solver.offset_prior(range_mm, cat_idx, track.psf_sigma_px)

    def track(self, g: np.ndarray, d: np.ndarray, track: TrackState) -> Tracked | None:
        """One frame; None means "fall back to the acquisition pass" (fewer reflectors to
        track than a pose needs, one lost or not persistent, a range missing, one dropped
        as an outlier, verification failed or the fit inconsistent), and leaves the
        persistence history as it was."""
        cfg, tc, arith = self.config, self.tracking, self._arithmetic
        camera, catalog = self._camera_record, self._catalog_record
        windows = arith.camera_windows(
            catalog,
            track.R,
            track.t_mm,
            camera,
            float(tc.margin_px),
            float(tc.min_diameter_px),
        )
        cat_idx = windows.catalog_index
        if len(cat_idx) < cfg.min_matches:
            return None
        frame = FrameRecord(
            gray=g,
            distance=d,
            background=float(track.background_counts),
            dark=float(track.dark_counts),
        )
        out = arith.track_frame(
            frame,
            np.float32(track.threshold_counts),
            windows,
            self._persistence.history(g, d),
            camera,
            catalog,
            *self._fit_args,
            self._offset_prior(track, cat_idx),
        )
        if out.code != TRACKED:
            return None
        n = len(cat_idx)
        active = ThresholdedFrame(g, track.threshold_counts, track.psf_sigma_px)
        solved = self._solver.conclude(matched_observations(out.solved), out.solved.result, active)
        if not isinstance(solved, Solution):
            return None
        if solved.ml.chi2 > cfg.outlier_chi2_per_dof * max(3 * n - 6, 1):
            return None  # an inconsistent fit: the windows may hold the wrong blobs
        self._persistence.commit(out.centroids, out.flat, g, d, out.n_used, out.motion)
        # every blob is ranged and matched, in order: the fit's observed ranges are its own
        c, observed = out.candidates, out.solved.observed
        area = out.starts[1:] - out.starts[:-1]
        meas = Measurements(
            (), area, c.uv_px, observed.rho, c.y_mm, c.weights, c.sigma_px, observed.sr
        )
        saturated = pixel_lists_at_full_scale(
            g, out.flat, out.starts, self.camera.full_scale_counts
        )
        return Tracked(solved, meas, PersistenceInfo(1 + out.n_used, out.motion, 0), saturated)
