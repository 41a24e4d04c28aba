"""Tracking mode (ours, beyond the paper): once a pose is confident, the next frame is
searched only in small windows around each reflector's predicted image.

The paper processes every frame from scratch (§3-§5). Between two frames of a live stream
the target moves little, so the last pose predicts where each catalog reflector appears
and how large; the frame is thresholded only in a window around each prediction, the
component nearest the prediction is that reflector (the correspondence is known, no
annealing), and the pose is solved and verified as in acquisition. Policy, stated in
docs/algorithm.md ("Tracking mode"): the pipeline falls back to the full acquisition
pass in the same frame whenever a predicted reflector is not found in its window, a
component touches its window's edge (the target moved more than the window allows), the
fit is inconsistent or drops a reflector as an outlier, or the pose fails verification;
and every ``reacquire_every`` frames in any case, so that a re-appearing marker or a new
bright reflection elsewhere is seen. Tracking therefore never reports a pose the current
frame's pixels do not support.

Functions take and return arrays; shapes are given in each docstring.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tofpose.core.camera import CameraModel
from tofpose.core.records import CatalogRecord, camera_record
from tofpose.stages.extraction.extraction import Blob
from tofpose.stages.tracking.arithmetic import COMPILED, TrackingArithmetic
from tofpose.stages.tracking.constants import AT_EDGE, FOUND, NO_SIZE, NOT_FOUND


@dataclass(frozen=True)
class TrackState:
    """What the last confident pose leaves for the next frame."""

    R: np.ndarray
    t_mm: np.ndarray
    threshold_counts: float
    background_counts: float
    frames_since_acquisition: int = 0
    dark_counts: float = float("nan")  # the no-return level (``FrameStats.dark_level``)
    #: the lens blur the acquisition frame showed (``FrameStats.psf_sigma_px``), px
    psf_sigma_px: float = 0.0


@dataclass(frozen=True)
class Window:
    """A search window: catalog index, predicted centre (u, v) px, predicted diameter px,
    and the window's pixel bounds [u0, u1) x [v0, v1)."""

    catalog_index: int
    centre_uv: np.ndarray
    diameter_px: float
    u0: int
    u1: int
    v0: int
    v1: int


def predict_windows(
    camera: CameraModel,
    catalog_mm: np.ndarray,
    catalog_diameter_mm: np.ndarray,
    R: np.ndarray,
    t_mm: np.ndarray,
    *,
    margin_px: float,
    min_diameter_px: float,
    arithmetic: TrackingArithmetic = COMPILED,
) -> list[Window]:
    """Windows around the predicted image of every catalog reflector in view.

    catalog_mm : (N, 3) target frame; catalog_diameter_mm : (N,). Reflectors smaller than
    ``min_diameter_px``, whose window leaves the image, or whose disc would touch a
    neighbour's (closer than half their diameters plus 2 px: they merge into one blob,
    markers 7 and 8 beyond ~4.5 m) are skipped; the others carry the pose. The window is
    the predicted disc plus ``margin_px`` on every side.
    """
    catalog = CatalogRecord(
        xyz=np.ascontiguousarray(catalog_mm, dtype=float),
        radii_mm=np.ascontiguousarray(catalog_diameter_mm, dtype=float) / 2,
    )
    found = arithmetic.camera_windows(
        catalog,
        np.asarray(R, float),
        np.asarray(t_mm, float),
        camera_record(camera),
        float(margin_px),
        float(min_diameter_px),
    )
    return [
        Window(
            int(i),
            found.centres[n],
            float(found.diameters_px[n]),
            *(int(v) for v in found.bounds[n]),
        )
        for n, i in enumerate(found.catalog_index.tolist())
    ]


_WHY_NOT = {
    NOT_FOUND: "not found in its window",
    NO_SIZE: "no component of the predicted size in its window",
    AT_EDGE: "touches its window's edge (moved too far)",
}


def find_in_windows(
    gray: np.ndarray,
    windows: list[Window],
    threshold_counts: float,
    background_counts: float,
    *,
    arithmetic: TrackingArithmetic = COMPILED,
) -> list[Blob] | str:
    """Each window's reflector blob, or why one is not there (the first failing window).

    gray : (H, W) frame. Each window is thresholded at ``threshold_counts`` (the active
    pixel set's I_t of the last acquisition); of the 8-connected components, the one
    nearest the predicted centre is taken when its area is between a quarter and four
    times the predicted disc's (at least one pixel). A component touching the window's
    edge means the target moved more than the margin: refused. Two windows finding the
    same component (one blob serving two reflectors) are refused too. The blobs carry
    their moment centroid (the persistence motion gate's) and global pixel indices.
    """
    if not windows:
        return []
    bounds = np.array([(w.u0, w.u1, w.v0, w.v1) for w in windows], np.int64)
    centres = np.array([w.centre_uv for w in windows], np.float64)
    diameters = np.array([w.diameter_px for w in windows], np.float64)
    status, bbox, peak, centroid, starts, flat = arithmetic.search_windows(
        np.asarray(gray, np.float32),
        bounds,
        centres,
        diameters,
        np.float32(threshold_counts),
        float(background_counts),
    )
    for code in status.tolist():
        if code != FOUND:
            return _WHY_NOT[code]
    if arithmetic.any_shared(flat, starts, bbox):
        return "two windows found the same component"
    return [
        Blob(
            pixels=flat[starts[j] : starts[j + 1]],
            area_px=int(starts[j + 1] - starts[j]),
            bbox=tuple(bbox[j].tolist()),
            centroid_uv=centroid[j],
            peak_counts=float(peak[j]),
            source="tracking",
        )
        for j in range(len(windows))
    ]


def find_in_window(
    gray: np.ndarray,
    window: Window,
    threshold_counts: float,
    background_counts: float,
    *,
    arithmetic: TrackingArithmetic = COMPILED,
) -> Blob | str:
    """One window of ``find_in_windows``: the reflector's blob, or why it is not there."""
    found = find_in_windows(
        gray, [window], threshold_counts, background_counts, arithmetic=arithmetic
    )
    return found if isinstance(found, str) else found[0]
