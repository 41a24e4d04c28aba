"""The extraction stage's arithmetic (§3.1-§3.2) per implementation: ``COMPILED`` (the
kernels, through ``extraction.frame_levels`` and ``extraction.find_candidate_blobs``)
and ``REFERENCE`` (``reference.extraction``, adapted here to ``extraction``'s records)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from tofpose.config import ExtractionConfig
from tofpose.core.camera import CameraModel
from tofpose.stages.extraction.constants import SATURATED_COUNTS
from tofpose.stages.extraction.extraction import (
    Blob,
    CandidateBlobs,
    FrameStats,
    RejectedBlob,
    WrongSizeBlob,
    find_candidate_blobs,
    frame_levels,
)
from tofpose.stages.extraction.reference import extraction as ref_extraction


@dataclass(frozen=True)
class ExtractionArithmetic:
    """§3.1-§3.2 in one implementation, with ``extraction``'s records in and out."""

    name: str
    frame_levels: Callable[..., FrameStats]
    find_candidate_blobs: Callable[..., CandidateBlobs]


def _reference_frame_levels(
    gray: np.ndarray, config: ExtractionConfig, *, saturated_counts: float = SATURATED_COUNTS
) -> FrameStats:
    """``reference.extraction.frame_levels`` as an ``extraction.FrameStats``."""
    v = ref_extraction.frame_levels(gray, config, saturated_counts=saturated_counts)
    return FrameStats(
        background=v.background,
        noise_sigma=v.noise_sigma,
        i_max=v.i_max,
        raw_threshold=v.raw_threshold,
        peak_threshold=v.peak_threshold,
        n_active=v.n_active,
        saturated_fraction=v.saturated_fraction,
        dark_level=v.dark_level,
    )


def _reference_find_candidate_blobs(
    gray: np.ndarray,
    distance_mm: np.ndarray,
    camera: CameraModel,
    diameters_mm: np.ndarray,
    config: ExtractionConfig,
    stats: FrameStats,
) -> CandidateBlobs:
    """``reference.extraction.find_candidates`` as ``extraction.find_candidate_blobs``
    returns it (``Blob`` records, the active mask as uint8)."""
    levels = ref_extraction.FrameLevels(
        stats.background,
        stats.noise_sigma,
        stats.i_max,
        stats.raw_threshold,
        stats.peak_threshold,
        stats.saturated_fraction,
        stats.dark_level,
        stats.n_active,
    )
    found = ref_extraction.find_candidates(
        gray,
        distance_mm,
        levels,
        fx=float(camera.fx),
        diameters_mm=np.asarray(diameters_mm, float),
        config=config,
    )
    # the reference's records carry Blob's fields under Blob's names
    accepted = [Blob(**b._asdict()) for b in found.accepted]
    oversize = [Blob(**b._asdict()) for b in found.oversize]
    v = found.levels
    applied = FrameStats(
        background=v.background,
        noise_sigma=v.noise_sigma,
        i_max=v.i_max,
        raw_threshold=v.raw_threshold,
        peak_threshold=v.peak_threshold,
        n_active=v.n_active,
        saturated_fraction=v.saturated_fraction,
        dark_level=v.dark_level,
        psf_sigma_px=float(found.psf_sigma_px),
        surface_level=stats.surface_level,
    )
    return CandidateBlobs(
        accepted,
        oversize,
        found.active_mask.astype(np.uint8),
        tuple(WrongSizeBlob(*(float(x) for x in w)) for w in found.wrong_size),
        tuple(
            RejectedBlob(float(r.u_px), float(r.v_px), float(r.diameter_px), r.reason)
            for r in found.rejected
        ),
        applied,
    )


COMPILED = ExtractionArithmetic("compiled", frame_levels, find_candidate_blobs)
REFERENCE = ExtractionArithmetic(
    "reference", _reference_frame_levels, _reference_find_candidate_blobs
)
