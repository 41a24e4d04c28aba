"""Per-reflector measurement sigmas: the weights of Eq. 21 and the ML refinement.

The paper weights each reflector by its measurement quality but gives no noise model.
Ours has two parts, each checked against the simulator's truth over 0.7-15 m (see
docs/algorithm.md, "Measurement sigmas"):

Centroid (px, per image axis), independent terms in quadrature:

* shot noise propagated through Eq. 19, ``sqrt(sum G_p |p - c|^2) / sum (G_p - bg)``;
* a floor for what no pixel statistic sees (PSF, residual perspective bias);
* sampling: a blob of ``n`` pixels cannot locate its centre better than the pixel grid
  allows. One pixel leaves the centre uniform over the pixel (``1/sqrt(12)`` px); the
  error falls quickly as edge pixels are added, as ``n**-1.5`` over the simulated range.
  Without this term a 1-3 px blob at 10-15 m claims 0.03 px and the refinement
  over-trusts its bearing;
* for a blob cut out of a merged component (``CUT_FROM_MERGED`` sources: markers 7 and
  8 touching in the image, at any range once the target is tilted), the light of the
  contact band assigned to the wrong side of the cut, ``SPLIT_CENTROID_PX`` per axis.
  A band about half a pixel wide along the cut, misassigned, moves the centroid by its
  share of the light times its lever arm: ``0.5 L r / (pi r^2) ~ 0.5 / pi`` px for a
  cut of length L ~ r, whatever the disc's size r. Measured on the simulator's poses
  with up to 20 deg of tilt (true correspondences), per axis RMS: 0.08 px at 2 m
  (171-px parts), 0.06-0.14 px at 3 m in two sets of 40 frames (75-px parts; the
  errors are heavy-tailed), 0.085 px at 8 m (8-px halves). Without it the parts claimed
  0.03-0.04 px and the fit leaned on them, rejecting good markers instead (a frame at
  3 m: markers 5 and 6 dropped, 7 and 8 off by 0.35-0.48 px, the pose 7.8 sigma off).

* for a blob with a pixel at the camera's full scale (a saturated reflector), the
  contour quantisation of a binary image: a rim pixel covered more than 1/k of its area
  (k the overexposure) reads full scale like the core, so the blob is the coverage
  contour at 1/k cut by the pixel grid, and each of its ~2 pi r rim pixels is in or
  out. ``kernels.sigmas.clipped_contour_sigma_px``: sqrt(1 / (12 pi r)) px per axis,
  r = sqrt(n / pi). Measured with the true correspondences: on the simulator's
  ``saturating`` family at 3-8 m the clipped blobs' centroids were off 0.089 px per axis
  RMS at < 12 px, 0.059 at 12-30 px, 0.047 at 30-60 px and 0.046 above (1.5-2.3x their
  sigmas without the term; the simulator's blur softens the clipped edge, so the term
  is 1.2-1.5x wider there), and on the other renderer's saturating frames (pixels
  integrated over their area, no blur: crisp binary rims) the 35 mm markers' centroid
  errors were 2.0-2.4x, the 80 mm ones' 1.2-2.1x their sigmas without it.

Range (mm): the CW-ToF noise model ``sigma_pix = k sqrt(G) / A`` (Lange 2000; G the
pixel's gray level, A its amplitude above background) with ``k`` pooled over every blob
of the frame that has enough pixels to measure its own spread (robust MAD). A blob's
sigma is the larger of its own MAD and the pooled model, times the median's efficiency
(1.2533) over ``sqrt(n)``. Few-pixel blobs therefore no longer get the (low-biased) MAD of
3-5 samples, and 1-2 pixel blobs get a model value instead of a fixed guess.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from tofpose.core.records import SigmaConstants
from tofpose.stages.extraction.extraction import CUT_FROM_MERGED, Blob, pixel_lists
from tofpose.stages.extraction.kernels.sigmas import blob_sigmas

#: centroid sampling error of a single-pixel blob, px (uniform over one pixel)
SINGLE_PIXEL_SIGMA_PX = 1.0 / np.sqrt(12.0)
#: blobs with at least this many valid ranges measure their own spread for the pool
POOL_MIN_PIXELS = 8
#: sigma of a blob's range when no blob of the frame can calibrate the model, mm
UNCALIBRATED_RANGE_SIGMA_MM = 30.0
#: a blob cut out of a merged component keeps part of its neighbour's light at the cut
#: and loses part of its own: its centroid sigma gets this in quadrature, px per axis
#: (module docstring: 0.06-0.14 px measured at 2-8 m)
SPLIT_CENTROID_PX = 0.08
#: efficiency factor of the median of normal samples
MEDIAN_EFFICIENCY = 1.2533


@dataclass(frozen=True)
class SigmaFloors:
    """Lower bounds of the sigmas (what the pixel statistics cannot see):
    ``PipelineConfig``'s settings of the same names."""

    centroid_sigma_floor_px: float = 0.03
    range_sigma_floor_mm: float = 1.0


def sampling_sigma_px(n_pixels: np.ndarray) -> np.ndarray:
    """Centroid error from the pixel grid for blobs of ``n_pixels`` (B,), px, (B,)."""
    n = np.maximum(np.asarray(n_pixels, float), 1.0)
    return SINGLE_PIXEL_SIGMA_PX * n**-1.5


def kernel_constants(floors: SigmaFloors) -> SigmaConstants:
    """The floors and this module's constants as the compiled sigmas take them (a
    ``core.records.SigmaConstants``, ``kernels.sigmas.blob_sigmas``' last argument)."""
    return SigmaConstants(
        centroid_sigma_floor_px=float(floors.centroid_sigma_floor_px),
        range_sigma_floor_mm=float(floors.range_sigma_floor_mm),
        single_pixel_sigma_px=SINGLE_PIXEL_SIGMA_PX,
        split_centroid_px=SPLIT_CENTROID_PX,
        pool_min_pixels=POOL_MIN_PIXELS,
        median_efficiency=MEDIAN_EFFICIENCY,
        uncalibrated_range_sigma_mm=UNCALIBRATED_RANGE_SIGMA_MM,
    )


def measurement_sigmas(
    blobs: Sequence[Blob],
    gray: np.ndarray,
    distance_mm: np.ndarray,
    background_counts: float,
    floors: SigmaFloors = SigmaFloors(),
    full_scale_counts: float = np.inf,
) -> tuple[np.ndarray, np.ndarray]:
    """Centroid sigma (B,) px and range sigma (B,) mm of each blob.

    gray, distance_mm : (H, W) frame (or persistence-combined frame) the blobs came from;
    full_scale_counts : the camera's full scale (``CameraModel.full_scale_counts``; a
    blob with a pixel at or above it is clipped), inf: none is.
    """
    flat, starts = pixel_lists(blobs)
    centroids = np.array([b.centroid_uv for b in blobs], np.float64).reshape(-1, 2)
    split = np.array([b.source in CUT_FROM_MERGED for b in blobs], bool)
    return blob_sigmas(
        flat,
        starts,
        centroids,
        np.asarray(gray, np.float32),
        np.asarray(distance_mm, np.float32),
        float(background_counts),
        split,
        float(full_scale_counts),
        kernel_constants(floors),
    )
