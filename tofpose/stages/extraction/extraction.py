"""Reflector extraction (§3): active pixel set, nLoG, blob criteria, centroids, ellipses.

All functions take arrays. Range adaptivity (docs/architecture.md §4): instead of the paper's fixed
pixel-count window (H_min = 95, H_max = 225 px, tuned for one range), each connected
component's expected size is predicted from its measured distance and the catalog
diameters, ``d_px = f * D_mm / rho``; intensity thresholds are relative to the frame's
brightest pixel and its background. ``ExtractionConfig.paper()`` keeps the paper's
literal numbers as a preset.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from itertools import accumulate

import numpy as np

from tofpose.config import ExtractionConfig
from tofpose.core.camera import CameraModel
from tofpose.core.records import GateSettings
from tofpose.stages.extraction.constants import LEVEL_STRIDE, MAD_TO_SIGMA, SATURATED_COUNTS
from tofpose.stages.extraction.kernels.centroids import blob_centroids, blob_ranges, owner_map
from tofpose.stages.extraction.kernels.gates import ACCEPTED, OVERSIZE, label_table_and_gates
from tofpose.stages.extraction.kernels.levels import (
    checked_frame,
    clean_distance,
    frame_level_stats,
    threshold_mask,
)
from tofpose.stages.extraction.kernels.mixed_pixels import (
    blob_mixing,
    blob_surrounds,
    occluded_blobs,
)
from tofpose.stages.extraction.kernels.perspective import disc_centre_offsets


@dataclass(frozen=True, eq=False)
class Blob:
    """One candidate reflector blob in a frame.

    Attributes
    ----------
    pixels : ndarray of shape (P,) int, flat indices (row * W + col) of member pixels.
    area_px : int
    bbox : (x, y, w, h) in pixels.
    centroid_uv : ndarray (2,), intensity-weighted centroid (Eq. 19), refined later.
    distance_mm : robust radial distance to the blob centre (Eq. 20 variant), NaN if none.
    peak_counts : brightest pixel.
    eccentricity : from the second moments.
    penalty : q in [0, 1] (§3.4).
    ellipse : ((cx, cy), (major, minor), angle_deg) from the edge fit, or None.
    ellipse_residual_px : RMS edge-to-ellipse distance, or NaN.
    source : "morphology", or one of ``CUT_FROM_MERGED``: "ellipse" (inside an ellipse
        found on the outline of a component too large for one reflector, §3.3) or
        "split" (cut out of a merged component by threshold or two centres).
    fitted_uv : ndarray (2,), the centre from a model fit of the pixels
        (``pair_fit.fit_pair``: one of two markers imaged as one blob), which replaces
        the moment centroid in the measurement; None for the others.
    mixing : ndarray (``constants.MIX_FIELDS``,), the mixing sums of its
        support against its surround (measured with the centroid), or None.
    """

    pixels: np.ndarray
    area_px: int
    bbox: tuple[int, int, int, int]
    centroid_uv: np.ndarray = field(default_factory=lambda: np.full(2, np.nan))
    distance_mm: float = float("nan")
    peak_counts: float = 0.0
    eccentricity: float = 0.0
    penalty: float = 0.0
    ellipse: tuple | None = None
    ellipse_residual_px: float = float("nan")
    source: str = "morphology"
    mixing: np.ndarray | None = None
    fitted_uv: np.ndarray | None = None

    def with_values(self, **changes) -> Blob:
        """A new blob with the named fields changed: ``dataclasses.replace`` for the
        per-frame path (a copy of the field values, ~5x cheaper; the class has no
        ``__post_init__``, so nothing that ``replace`` would run is skipped)."""
        new = object.__new__(Blob)
        fields_of_new = new.__dict__
        fields_of_new.update(self.__dict__, **changes)
        if len(fields_of_new) != len(_BLOB_FIELDS):  # a name that is not a field
            raise TypeError(f"Blob has no field(s) {sorted(changes.keys() - _BLOB_FIELDS)}")
        return new


_BLOB_FIELDS = frozenset(Blob.__dataclass_fields__)


def pixel_lists(blobs: Sequence[Blob]) -> tuple[np.ndarray, np.ndarray]:
    """The blobs' pixels as the kernels take them: flat (P,) int64 flat indices, blob j's
    being ``flat[starts[j]:starts[j + 1]]``, and starts (B + 1,) int64."""
    if not blobs:
        return np.zeros(0, np.int64), np.zeros(1, np.int64)
    pieces = [b.pixels for b in blobs]
    sizes = [p.shape[0] for p in pieces]  # a list: accumulate then runs without Python calls
    starts = np.fromiter(accumulate(sizes, initial=0), np.int64, len(sizes) + 1)
    return np.concatenate(pieces).astype(np.int64, copy=False), starts


@dataclass(frozen=True)
class FrameStats:
    """Frame-level levels used by the thresholds (counts). ``raw_threshold`` is I_t and
    ``n_active`` the size of the active pixel set once ``active_pixel_mask`` has applied
    the N_max cap (``frame_levels`` gives the uncapped I_t and 0)."""

    background: float
    noise_sigma: float
    i_max: float
    raw_threshold: float
    peak_threshold: float
    n_active: int
    saturated_fraction: float
    #: the gray of pixels without a return (``kernels.levels.frame_level_stats``)
    dark_level: float = float("nan")
    #: the lens blur the frame's candidates show, px (1-sigma of a Gaussian PSF per
    #: axis; ``kernels.gates.psf_variance_px2``); 0 until the gates have run
    psf_sigma_px: float = 0.0
    #: the gray of a lit surface the thresholds sit above (``surface.above_surface``);
    #: NaN where none is lit
    surface_level: float = float("nan")


@dataclass(frozen=True)
class WrongSizeBlob:
    """A bright component (it passed criterion 1) whose size is outside the window the
    catalog's diameters predict at its range: evidence that the active catalog does not
    describe the target in view."""

    diameter_px: float
    expected_min_px: float
    expected_max_px: float
    distance_mm: float


@dataclass(frozen=True)
class RejectedBlob:
    """A connected component of the active set that is not a candidate, and why.

    u_px, v_px : centre of its bounding box; diameter_px : equivalent diameter of its area.
    reason : one of ``REJECT_REASONS`` (the gate that refused it).
    """

    u_px: float
    v_px: float
    diameter_px: float
    reason: str


#: the sources of blobs cut out of a component too large for one reflector (two markers
#: merged in the image): the cut assigns part of the contact band's light to the wrong
#: side (``uncertainty.SPLIT_CENTROID_PX``)
CUT_FROM_MERGED = ("ellipse", "split")

REJECT_REASONS = {
    "border": "cut by the image border (its centroid would be biased)",
    "dim": "no seed above I_peak (criterion 1, Eqs. 15-16)",
    "size": "size outside the window the catalog predicts at its range",
    "oversize": "too large for one reflector (merged markers?): left to ellipse confirmation",
    "nlog": "nLoG response below J_peak or J_t (criterion 2, Eqs. 17-18)",
    "shape": "too elongated for a disc within the tilt limit",
    "penalty": "penalty score q above q_max (§3.4)",
    "rank": "beyond the candidate limit (lower-ranked by penalty)",
}


@dataclass(frozen=True)
class CandidateBlobs:
    """What ``find_candidate_blobs`` found.

    accepted : candidate reflector blobs, best (lowest penalty) first.
    oversize : components too large for one reflector (merged markers), for §3.3.
    active_mask : (H, W) uint8, the active pixel set A (§3.1.1).
    wrong_size : bright components rejected by the size window (oversize ones included).
    rejected : every component of at least ``min_area_px`` that is not a candidate, with
        the gate that refused it (for display; ``REJECT_REASONS``).
    stats : the frame levels as applied (I_t after the N_max cap).
    """

    accepted: list[Blob]
    oversize: list[Blob]
    active_mask: np.ndarray
    wrong_size: tuple[WrongSizeBlob, ...]
    rejected: tuple[RejectedBlob, ...]
    stats: FrameStats


class FrameError(ValueError):
    """A frame that cannot be processed (wrong shape or dtype)."""


def check_frame(
    camera: CameraModel, gray: np.ndarray, distance_mm: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Validate a frame pair; return (gray float32, distance float32 with non-finite -> NaN).

    Raises
    ------
    FrameError naming what is wrong (shape, dtype, negative distances are allowed as
    invalid: they are set to NaN).
    """
    gray = np.asarray(gray)
    distance_mm = np.asarray(distance_mm)
    if gray.shape != camera.shape:
        raise FrameError(f"gray image has shape {gray.shape}, camera expects {camera.shape}")
    if distance_mm.shape != camera.shape:
        raise FrameError(
            f"distance image has shape {distance_mm.shape}, camera expects {camera.shape}"
        )
    if gray.dtype.kind not in "iuf":  # signed, unsigned integer or floating
        raise FrameError(f"gray image must be integer counts, got dtype {gray.dtype}")
    if distance_mm.dtype.kind != "f":
        raise FrameError(f"distance image must be float mm, got dtype {distance_mm.dtype}")
    if gray.dtype == np.uint16 and distance_mm.dtype in _CHECKED_DISTANCE_DTYPES:
        return checked_frame(gray, distance_mm)  # a camera's counts: one compiled pass
    g = gray.astype(np.float32)
    if gray.dtype.kind == "f" and not np.isfinite(g).all():
        g = np.nan_to_num(g, nan=0.0, posinf=0.0, neginf=0.0)
    return g, clean_distance(distance_mm)


#: distance dtypes whose frames ``check_frame`` converts in one compiled pass with uint16
#: counts (both compiled by ``warm_up``; others take NumPy's conversion, never a compile)
_CHECKED_DISTANCE_DTYPES = (np.dtype(np.float32), np.dtype(np.float64))


def frame_levels(
    gray: np.ndarray, config: ExtractionConfig, *, saturated_counts: float = SATURATED_COUNTS
) -> FrameStats:
    """Background, noise and the raw/peak thresholds I_t, I_peak of §3.1.1 and Eq. 16.

    Background and its noise come from a strided subsample (median and MAD);
    ``saturated_counts`` is the camera's full scale (``CameraModel.full_scale_counts``),
    at or above which a pixel counts as saturated.
    """
    gray32 = np.ascontiguousarray(gray, np.float32)
    bg, mad, n_sat, dark = frame_level_stats(gray32, LEVEL_STRIDE, float(saturated_counts))
    i_max = float(gray32.max())
    sigma = max(MAD_TO_SIGMA * mad, np.sqrt(max(bg, 1.0)))
    contrast = i_max - bg
    if config.raw_threshold_abs is not None:
        i_t = config.raw_threshold_abs
    else:
        i_t = max(bg + config.raw_threshold_rel * contrast, bg + config.noise_floor_sigma * sigma)
    i_peak = config.peak_abs if config.peak_abs is not None else bg + config.peak_rel * contrast
    sat = float(n_sat) / gray.size
    return FrameStats(
        background=bg,
        noise_sigma=sigma,
        i_max=i_max,
        raw_threshold=i_t,
        peak_threshold=max(i_peak, i_t),
        n_active=0,
        saturated_fraction=sat,
        dark_level=min(float(dark), bg),
    )


def active_pixel_mask(
    gray: np.ndarray, stats: FrameStats, n_max: int
) -> tuple[np.ndarray, FrameStats]:
    """Active pixel set A (§3.1.1): pixels >= I_t, at most N_max, dimmest dropped first.

    Returns a uint8 mask of shape (H, W) and the levels as applied (``raw_threshold``
    raised to the cut when the cap applies, ``n_active`` the mask's size).
    """
    mask, stats, _ = _active_set(gray, stats, n_max)
    return mask, stats


def _active_set(
    gray: np.ndarray, stats: FrameStats, n_max: int
) -> tuple[np.ndarray, FrameStats, np.ndarray]:
    """``active_pixel_mask`` and the set's runs (R, 3) (row, first column, last + 1), in
    one pass over the frame (``kernels.levels.threshold_mask``) unless the N_max cap
    applies."""
    gray32 = np.ascontiguousarray(gray, np.float32)
    threshold = stats.raw_threshold
    mask, runs, n, _ = threshold_mask(gray32, float(threshold))
    if n > n_max:
        values = gray32[mask.view(bool)]
        cut = np.partition(values, n - n_max)[n - n_max]
        threshold = float(cut)
        mask, runs, n, _ = threshold_mask(gray32, threshold)
    applied = FrameStats(
        background=stats.background,
        noise_sigma=stats.noise_sigma,
        i_max=stats.i_max,
        raw_threshold=threshold,
        peak_threshold=stats.peak_threshold,
        n_active=n,
        saturated_fraction=stats.saturated_fraction,
        dark_level=stats.dark_level,
        surface_level=stats.surface_level,
    )
    return mask, applied, runs


def predicted_diameter_window_px(
    fx: float, distance_mm: float, diameters_mm: np.ndarray, config: ExtractionConfig
) -> tuple[float, float]:
    """Accepted blob diameter window (d_min, d_max) in px at a radial distance.

    Face-on diameter is f * D / rho; a tilt up to ``max_tilt_deg`` shrinks the minor
    axis by cos(tilt); tolerance and margin cover blur and thresholding.
    """
    if not np.isfinite(distance_mm) or distance_mm <= 0:
        return 0.0, np.inf
    d_face = fx * diameters_mm / distance_mm
    cos_t = np.cos(np.radians(config.max_tilt_deg))
    d_min = d_face.min() * np.sqrt(cos_t) / config.size_tolerance - config.size_margin_px
    d_max = d_face.max() * config.size_tolerance + config.size_margin_px
    return max(d_min, 1.0), d_max


def find_candidate_blobs(
    gray: np.ndarray,
    distance_mm: np.ndarray,
    camera: CameraModel,
    diameters_mm: np.ndarray,
    config: ExtractionConfig,
    stats: FrameStats,
) -> CandidateBlobs:
    """Candidate reflector blobs (§3.1.2-§3.2): B1-B4 as reconstruction + gates.

    ``oversize`` holds components too large for one reflector (merged markers), which the
    ellipse stage may split (§3.3); ``wrong_size`` every bright component the size window
    refused, so that a failure can say the catalog does not fit what is in view.
    """
    mask, stats, runs = _active_set(gray, stats, config.n_max)
    gray32 = np.asarray(gray, np.float32)
    cos_t = np.cos(np.radians(config.max_tilt_deg))
    ecc_max = np.sqrt(1.0 - cos_t**2)
    # the components of A from its runs, numbered as cv2.connectedComponents numbers them
    # (kernels.components.run_labels), and every gate, in one call
    found = label_table_and_gates(
        runs,
        gray32,
        np.asarray(distance_mm, np.float32).reshape(-1),
        float(camera.fx),
        np.asarray(diameters_mm, np.float64),
        _gate_params(config, stats, cos_t, ecc_max),
        int(config.min_area_px),
    )
    table, gates = found.table, found.gates
    flat, starts = table.flat, table.starts
    # per component as Python numbers (the loop reads each a few times)
    area_k, bbox_k, peak_k = table.area.tolist(), table.bbox.tolist(), table.peak.tolist()
    rho_k, inner = found.rho.tolist(), found.inner.tolist()
    status, size, mom = gates.status.tolist(), gates.size.tolist(), gates.moments
    keep_flat, keep_starts = gates.keep_flat, gates.keep_starts.tolist()
    # the accepted blobs' centroids are rows of one copy; eccentricity and penalty numbers
    centroids, ecc_q = mom[:, :2].copy(), mom[:, 2:4].tolist()
    # (penalty, -peak, order found, blob): sorted as is, best first (ties in found order)
    ranked: list[tuple[float, float, int, Blob]] = []
    oversize: list[Blob] = []
    wrong_size: list[WrongSizeBlob] = []
    refused: list[tuple[int, RejectedBlob]] = []  # (label, why), listed in label order

    def reject(k: int, reason: str) -> None:
        x, y, bw, bh = bbox_k[k]
        d_eq = 2.0 * np.sqrt(area_k[k] / np.pi)
        refused.append((k, RejectedBlob(x + (bw - 1) / 2, y + (bh - 1) / 2, float(d_eq), reason)))

    for k in found.listed[~found.testable].tolist():
        reject(k, "border" if not inner[k] else "dim")
    for j, k in enumerate(found.which.tolist()):
        code = status[j]
        d_eq, low, high, inside = size[j]
        if inside == 0.0:
            wrong_size.append(WrongSizeBlob(d_eq, low, high, rho_k[k]))
        bbox = tuple(bbox_k[k])
        if code == OVERSIZE:
            oversize.append(
                Blob(
                    pixels=flat[starts[k] : starts[k + 1]].copy(),
                    area_px=area_k[k],
                    bbox=bbox,
                    peak_counts=peak_k[k],
                    distance_mm=rho_k[k],
                )
            )
        if code != ACCEPTED:
            reject(k, _GATE_REASONS[code])
            continue
        first, end = keep_starts[j], keep_starts[j + 1]
        eccentricity, penalty = ecc_q[j]
        ranked.append(
            (
                penalty,
                -peak_k[k],
                j,
                Blob(
                    pixels=keep_flat[first:end],
                    area_px=end - first,
                    bbox=bbox,
                    centroid_uv=centroids[j],
                    distance_mm=rho_k[k],
                    peak_counts=peak_k[k],
                    eccentricity=eccentricity,
                    penalty=penalty,
                ),
            )
        )
    ranked.sort()
    accepted = [r[3] for r in ranked]
    rejected = [r for _, r in sorted(refused, key=lambda kr: kr[0])]
    for b in accepted[config.max_candidates :]:
        u, v = (float(c) for c in b.centroid_uv)
        rejected.append(RejectedBlob(u, v, 2.0 * np.sqrt(b.area_px / np.pi), "rank"))
    stats = FrameStats(  # dataclasses.replace's, built directly (a tenth of its calls)
        background=stats.background,
        noise_sigma=stats.noise_sigma,
        i_max=stats.i_max,
        raw_threshold=stats.raw_threshold,
        peak_threshold=stats.peak_threshold,
        n_active=stats.n_active,
        saturated_fraction=stats.saturated_fraction,
        dark_level=stats.dark_level,
        psf_sigma_px=float(np.sqrt(found.blur_var_px2)),
        surface_level=stats.surface_level,
    )
    return CandidateBlobs(
        accepted[: config.max_candidates],
        oversize,
        mask,
        tuple(wrong_size),
        tuple(rejected),
        stats,
    )


_GATE_REASONS = {1: "oversize", 2: "size", 3: "nlog", 4: "shape", 5: "penalty"}


def _gate_params(
    config: ExtractionConfig, stats: FrameStats, cos_t: float, ecc_max: float
) -> GateSettings:
    """The scalar settings of ``kernels.gates.gate_components`` (a
    ``core.records.GateSettings``) for this frame."""
    if config.nlog_sigma_px is not None:  # the paper's preset: a fixed nLoG sigma, absolute J
        nlog_sigma_px = float(config.nlog_sigma_px)
        j_peak = _preset(config.nlog_peak_abs, "nlog_peak_abs")
        j_t = _preset(config.nlog_floor_abs, "nlog_floor_abs")
    else:  # matched to each blob, J relative to its contrast
        nlog_sigma_px, j_peak, j_t = -1.0, float(config.nlog_peak_rel), float(config.nlog_floor_rel)
    return GateSettings(
        h_min_px=-1.0 if config.h_min_px is None else float(config.h_min_px),
        h_max_px=-1.0 if config.h_max_px is None else float(config.h_max_px),
        cos_max_tilt=float(cos_t),
        size_tolerance=float(config.size_tolerance),
        size_margin_px=float(config.size_margin_px),
        nlog_sigma_px=nlog_sigma_px,
        j_peak=j_peak,
        j_t=j_t,
        background=float(stats.background),
        eccentricity_max=float(ecc_max),
        i_peak=float(stats.peak_threshold),
        i_t=float(stats.raw_threshold),
        q_max=float(config.q_max),
    )


def _preset(value: float | None, name: str) -> float:
    """A threshold the paper's preset sets (with ``nlog_sigma_px``); ``ValueError``
    naming it when it is not set."""
    if value is None:
        raise ValueError(
            f"ExtractionConfig.{name} must be set with nlog_sigma_px (the paper's preset)"
        )
    return float(value)


def measure_blobs(
    blobs: list[Blob],
    gray: np.ndarray,
    distance_mm: np.ndarray,
    camera: CameraModel,
    background: float,
    *,
    weighting: str = "coverage",
    dark: float = float("nan"),
    surround: tuple[np.ndarray, np.ndarray] | None = None,
) -> list[Blob]:
    """Centroid (Eq. 19) and radial distance (Eq. 20) of each blob: new blobs with
    ``centroid_uv`` and ``distance_mm`` measured (the inputs are not changed).

    Centroid over the blob dilated by one pixel (so partially covered edge pixels below
    I_t still pull the centre to sub-pixel accuracy), above the blob's own surround
    level (``kernels.mixed_pixels.blob_surrounds``: the median of a ring 2-3 px outside
    its box; ``background``, the frame's level, where there is no ring): a plate that is
    not black around a small marker would otherwise give the dilated ring's pixels a
    weight, which the ring's shape turns into a bias. Weights:

    * ``"intensity"``: the paper's Eq. 19, ``I - level``. A retro-reflector's
      brightness changes across its face (entrance-angle fall-off, 1/d^2), which pulls
      this centroid towards the bright side: ~0.8 px on a 48 px disc seen 7 deg
      off-normal.
    * ``"coverage"`` (default): the pixel's estimated coverage,
      ``(I - bg) / (max of its 3 x 3 neighbourhood - bg)`` clipped to [0, 1]: interior
      pixels count 1, edge pixels their covered fraction, so brightness gradients do
      not bias the centre. For 1-2 px blobs it reduces to intensity weighting.

    Distance: the median over member pixels of ``rho_p * (e_p . e_c)``, each pixel's
    point projected on the centroid's line of sight. For a disc facing the camera this
    is the centre's distance exactly (a plain mean of rho is biased long by
    ~R^2 / 4 rho); the median rejects flying pixels on the rim. With it, each blob's
    mixing sums (``kernels.mixed_pixels.blob_mixing``, with ``dark`` the frame's
    no-return level; NaN without one), from which the solver takes a small marker's
    range once it knows the marker's size. A blob partly hidden by something nearer
    than it (``kernels.mixed_pixels.occluded_blobs``) gets a NaN distance: its centroid
    and range are of the part left visible. ``surround`` : the (gray, distance) frame
    the surround (and the support's distances outside the blob) are read on when
    ``gray`` and ``distance_mm`` are combined frames (persistence's I-bar and D-bar
    hold values only inside the boxes and at the blobs' pixels); by default the frames
    given.
    """
    if not blobs:
        return []
    h, w = gray.shape
    flat, starts = pixel_lists(blobs)
    bbox = np.array([b.bbox for b in blobs], np.int64)
    owners = owner_map(flat, starts, bbox, h, w)  # whose pixel is it
    g32 = np.asarray(gray, np.float32)
    d32 = np.asarray(distance_mm, np.float32)
    sg, sd = (
        (g32, d32)
        if surround is None
        else (np.asarray(surround[0], np.float32), np.asarray(surround[1], np.float32))
    )
    surrounds = blob_surrounds(bbox, sg, sd, owners)
    level = np.where(np.isfinite(surrounds.gray), surrounds.gray, float(background))
    uv = blob_centroids(flat, starts, bbox, g32, level, weighting == "coverage", owners)
    mix = blob_mixing(
        flat,
        starts,
        bbox,
        g32,
        d32,
        sd,
        surrounds,
        float(dark),
        owners,
        float(camera.full_scale_counts),
    )
    bearings = camera.pixel_bearings().reshape(-1, 3)
    rho = blob_ranges(
        flat,
        starts,
        np.asarray(distance_mm, np.float32).reshape(-1),
        bearings,
        camera.bearings(uv),
    )
    # partly hidden by something nearer (read on the surround frame): no range
    hidden = occluded_blobs(flat, starts, bbox, sd, rho, owners)
    rho = np.where(hidden, np.nan, rho)
    return [
        b.with_values(centroid_uv=uv[j], distance_mm=float(rho[j]), mixing=mix[j])
        for j, b in enumerate(blobs)
    ]


def disc_image_centre_offsets_px(
    camera: CameraModel, centres_mm: np.ndarray, normal: np.ndarray, radii_mm: np.ndarray
) -> np.ndarray:
    """Perspective bias of projected discs: ellipse centre minus projected disc centre.

    A circle's image is an ellipse whose centre is not the image of the circle's centre
    (§3.3, "projected-circle bias"). With the disc's homography ``H = K [a b c]`` (a, b
    in-plane axes, c its centre), the image conic is ``Q = H^-T diag(1, 1, -r^2) H^-1``
    and the ellipse centre is ``-Q[:2, :2]^-1 Q[:2, 2]``. Distortion is ignored (it is
    second order here).

    centres_mm : (m, 3) disc centres in the camera frame; normal : (3,) shared normal
    (the plate's); radii_mm : (m,). Returns (m, 2) pixels.
    """
    c = np.ascontiguousarray(np.atleast_2d(np.asarray(centres_mm, float)))
    return disc_centre_offsets(
        np.ascontiguousarray(camera.K, dtype=float),
        c,
        np.ascontiguousarray(normal, dtype=float),
        np.ascontiguousarray(np.broadcast_to(np.asarray(radii_mm, float), (len(c),))),
    )


def disc_image_centre_offset_px(
    camera: CameraModel, centre_mm: np.ndarray, normal: np.ndarray, radius_mm: float
) -> np.ndarray:
    """One disc of ``disc_image_centre_offsets_px``: centre (3,), returns (2,) px."""
    return disc_image_centre_offsets_px(camera, centre_mm[None], normal, np.array([radius_mm]))[0]
