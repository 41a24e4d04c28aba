"""Metrics of ``bench/foreign.py``: per-frame outcomes against truth judged by the
project's rules (``tofpose.lab.pose_judgement``: pose error, Mahalanobis distance, success /
wrong / confidently wrong, beyond 3 sigma), range bins, the true correspondences of
measured blobs, and the per-marker measurement errors.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment

from tofpose.core.camera import CameraModel
from tofpose.core.catalog import Catalog
from tofpose.core.geometry import RigidTransform
from tofpose.lab.pose_judgement import (  # noqa: F401  (re-exported: bench/foreign.py's names)
    AXES,
    CHI2_6_3SIGMA,
    P_3SIGMA,
    SUCCESS_ATTITUDE_DEG,
    WRONG_ATTITUDE_DEG,
    WRONG_POSITION_FACTOR,
    mahalanobis2,
    pose_error,
    position_tolerance_mm,
)

#: a measured blob is the image of a reflector when its centroid lies within the
#: reflector's true apparent radius plus this many pixels of its true projection ...
ASSOCIATION_GATE_PX = 1.5
#: ... and its range within this of the true range to the reflector's centre (wide: a
#: blob that mixes the reflector with the plate behind it is still that reflector's)
ASSOCIATION_RANGE_GATE_MM = 300.0


@dataclass
class FrameOutcome:
    """One frame of one run against truth.

    frame : index in the recording; range_mm : true range |t_true|; ok, reason : the
    result's; error : (6,) pose error (NaN without a pose); covariance : (6, 6) reported,
    or None; n_matched : matched reflectors; mismatched : of those, how many the truth
    assigns to another reflector or to none (``true_correspondences``), -1 when unknown.
    """

    frame: int
    range_mm: float
    ok: bool
    reason: str = ""
    error: np.ndarray = field(default_factory=lambda: np.full(6, np.nan))
    covariance: np.ndarray | None = None
    n_matched: int = 0
    mismatched: int = -1

    @property
    def attitude_error_deg(self) -> float:
        return math.degrees(float(np.linalg.norm(self.error[:3])))

    @property
    def position_error_mm(self) -> float:
        return float(np.linalg.norm(self.error[3:]))

    @property
    def d2(self) -> float:
        """Squared Mahalanobis distance; NaN without a pose or a covariance."""
        if not self.ok or self.covariance is None:
            return math.nan
        return mahalanobis2(self.error, self.covariance)

    @property
    def success(self) -> bool:
        return bool(
            self.ok
            and self.attitude_error_deg <= SUCCESS_ATTITUDE_DEG
            and self.position_error_mm <= position_tolerance_mm(self.range_mm)
        )

    @property
    def wrong(self) -> bool:
        tol = position_tolerance_mm(self.range_mm)
        return bool(
            self.ok
            and (
                self.attitude_error_deg > WRONG_ATTITUDE_DEG
                or self.position_error_mm > WRONG_POSITION_FACTOR * tol
            )
        )

    @property
    def beyond_3sigma(self) -> bool:
        return bool(self.ok and not self.d2 <= CHI2_6_3SIGMA)  # NaN (no covariance) counts

    @property
    def confidently_wrong(self) -> bool:
        return self.wrong and self.beyond_3sigma

    def to_dict(self) -> dict:
        """JSON-ready record (NaN as None)."""

        def num(x: float) -> float | None:
            return float(x) if math.isfinite(x) else None

        return {
            "frame": self.frame,
            "range_mm": self.range_mm,
            "ok": self.ok,
            "reason": self.reason,
            "n_matched": self.n_matched,
            "mismatched": self.mismatched,
            "attitude_error_deg": num(self.attitude_error_deg),
            "position_error_mm": num(self.position_error_mm),
            "d2": num(self.d2),
            "success": self.success,
            "wrong": self.wrong,
            "confidently_wrong": self.confidently_wrong,
            "error": [num(x) for x in self.error],
            "sigma": None
            if self.covariance is None
            else [num(x) for x in np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))],
        }


#: the columns of a table of ``summarise`` results (success, wrong, confidently wrong, no
#: pose, beyond 3 sigma, NEES/6, medians), in this order
OUTCOME_HEADERS = (
    "success %",
    "wrong ok",
    "conf. wrong",
    "no pose",
    "ok > 3 sigma %",
    "NEES/6",
    "med att deg",
    "med pos mm",
)


def summarise(outcomes: list[FrameOutcome]) -> dict:
    """The table's numbers over some frames: frames, success_pct, wrong, confident_wrong,
    no_pose, beyond_3sigma_pct (share of ok poses), nees_over_6 (mean d2 / 6 over ok
    poses with a covariance), median_attitude_deg / median_position_mm (of successful
    poses), mismatch_frames (ok poses with at least one mismatched reflector, -1 when
    unknown), and spread_over_sigma (6,): per axis (``AXES``), the RMS over ok poses of
    the error over its reported sigma (1 when the covariance is right)."""
    n = len(outcomes)
    ok = [o for o in outcomes if o.ok]
    succ = [o for o in ok if o.success]
    with_cov = [o for o in ok if o.covariance is not None]
    d2 = np.array([o.d2 for o in with_cov])
    if with_cov:
        z2 = np.array([o.error**2 / np.diag(o.covariance) for o in with_cov])
        spread = np.sqrt(np.mean(z2, axis=0))
    else:
        spread = np.full(6, np.nan)
    known = [o for o in ok if o.mismatched >= 0]
    att = [o.attitude_error_deg for o in succ]
    pos = [o.position_error_mm for o in succ]
    return {
        "frames": n,
        "success_pct": 100.0 * len(succ) / n if n else math.nan,
        "wrong": sum(o.wrong for o in ok),
        "confident_wrong": sum(o.confidently_wrong for o in ok),
        "no_pose": n - len(ok),
        "beyond_3sigma_pct": 100.0 * sum(o.beyond_3sigma for o in ok) / len(ok) if ok else math.nan,
        "nees_over_6": float(np.mean(d2)) / 6.0 if len(d2) else math.nan,
        "median_attitude_deg": float(np.median(att)) if succ else math.nan,
        "median_position_mm": float(np.median(pos)) if succ else math.nan,
        "mismatch_frames": sum(o.mismatched > 0 for o in known) if len(known) == len(ok) else -1,
        "spread_over_sigma": spread.tolist(),
    }


# -- range bins ------------------------------------------------------------------------
def range_bins(
    range_mm: np.ndarray, width_m: float | None = None, gap_fraction: float = 0.1
) -> tuple[np.ndarray, list[str]]:
    """Bin frames by true range (N,) mm: (bin index per frame (N,) int, label per bin).

    ``width_m`` None: the distinct ranges present, clusters of sorted ranges split where
    one range exceeds the previous by more than ``gap_fraction`` (a recording of a few
    nominal distances with small offsets); labelled by their median, e.g. "4.7 m". With
    ``width_m``: bins [k w, (k + 1) w), labelled "4-5 m". Empty bins are left out.
    """
    r = np.asarray(range_mm, float)
    if width_m is not None:
        k = np.floor(r / (1000.0 * width_m)).astype(int)
        keys = sorted(set(k.tolist()))
        labels = [f"{key * width_m:g}-{(key + 1) * width_m:g} m" for key in keys]
        return np.searchsorted(keys, k), labels
    order = np.argsort(r, kind="stable")
    idx = np.empty(len(r), int)
    b = 0
    for j, i in enumerate(order):
        if j and r[i] > r[order[j - 1]] * (1.0 + gap_fraction):
            b += 1
        idx[i] = b
    labels = [f"{np.median(r[idx == k]) / 1000.0:.1f} m" for k in range(b + 1 if len(r) else 0)]
    return idx, labels


# -- true correspondences and per-marker errors -----------------------------------------
@dataclass(frozen=True)
class TrueImages:
    """Where the truth puts each catalog reflector (eta reflectors).

    point_mm : (eta, 3) centres in the camera frame; uv_px : (eta, 2) their projections
    (NaN behind the camera); range_mm : (eta,) true radial distance to the centre (the
    disc's front face: catalog points are the discs' centres, and the pipeline ranges the
    disc along the centroid's line of sight, ``stages.extraction.kernels.centroids.blob_ranges``);
    radius_px : (eta,) apparent radius; in_view : (eta,) bool, in front, facing the
    camera and projected inside the image.
    """

    point_mm: np.ndarray
    uv_px: np.ndarray
    range_mm: np.ndarray
    radius_px: np.ndarray
    in_view: np.ndarray


def true_images(camera: CameraModel, catalog: Catalog, T_true: RigidTransform) -> TrueImages:
    """The catalog's reflectors seen through ``camera`` at the true pose."""
    Y = catalog.positions_mm @ T_true.R.T + T_true.t_mm
    rng = np.linalg.norm(Y, axis=1)
    front = Y[:, 2] > 0
    uv = np.full((len(Y), 2), np.nan)
    if front.any():
        uv[front] = camera.project(Y[front])
    facing = (-Y @ T_true.R[:, 2]) > 0  # disc normal (target +z) towards the camera
    inside = (
        front
        & (uv[:, 0] >= -0.5)
        & (uv[:, 0] <= camera.width - 0.5)
        & (uv[:, 1] >= -0.5)
        & (uv[:, 1] <= camera.height - 0.5)
    )
    radius = 0.5 * camera.fx * catalog.diameters_mm / rng
    return TrueImages(Y, uv, rng, radius, inside & facing)


def true_correspondences(uv_px: np.ndarray, range_mm: np.ndarray, truth: TrueImages) -> np.ndarray:
    """The catalog index each measured blob is the image of, -1 for none: (n,) int.

    uv_px (n, 2) centroids, range_mm (n,) their ranges. One-to-one (assignment on image
    distance) among the pairs within the gates (``ASSOCIATION_GATE_PX`` beyond the true
    apparent radius, ``ASSOCIATION_RANGE_GATE_MM``) of reflectors in view.
    """
    uv = np.asarray(uv_px, float).reshape(-1, 2)
    rho = np.asarray(range_mm, float).reshape(-1)
    out = np.full(len(uv), -1, int)
    cand = np.flatnonzero(truth.in_view)
    if not len(uv) or not len(cand):
        return out
    dist = np.linalg.norm(uv[:, None, :] - truth.uv_px[None, cand, :], axis=-1)
    gate = (dist <= truth.radius_px[cand] + ASSOCIATION_GATE_PX) & (
        np.abs(rho[:, None] - truth.range_mm[None, cand]) <= ASSOCIATION_RANGE_GATE_MM
    )
    gate &= np.isfinite(dist)
    big = 1e9
    rows, cols = linear_sum_assignment(np.where(gate, dist, big))
    for k, j in zip(rows, cols, strict=True):
        if gate[k, j]:
            out[k] = cand[j]
    return out


@dataclass(frozen=True)
class MarkerError:
    """One matched reflector of one ok frame against truth.

    bin : range bin of the frame; diameter_mm : the catalog reflector's; correct : the
    truth assigns the blob to the reflector it was matched to; centroid_error_px (2,) :
    measured (bias-corrected) centroid minus the true projection of its centre;
    range_error_mm : measured range minus the true range to its centre; sigma_px,
    sigma_range_mm : the pipeline's sigmas for it.
    """

    bin: int
    diameter_mm: float
    correct: bool
    centroid_error_px: np.ndarray
    range_error_mm: float
    sigma_px: float
    sigma_range_mm: float


def marker_errors(result, truth: TrueImages, catalog: Catalog, bin_index: int) -> list[MarkerError]:
    """Per matched reflector of an ok ``PoseResult`` (``tofpose.pipeline``): its errors
    against ``truth`` (``true_images`` of the same catalog); [] without a pose."""
    if not result.ok or not result.matched:
        return []
    index_of = {int(i): k for k, i in enumerate(catalog.ids)}
    uv = np.array([m.centroid_uv for m in result.matched], float)
    rho = np.array([m.distance_mm for m in result.matched], float)
    claimed = np.array([index_of[int(m.catalog_id)] for m in result.matched])
    true_k = true_correspondences(uv, rho, truth)
    d = catalog.diameters_mm
    return [
        MarkerError(
            bin_index,
            float(d[c]),
            bool(t == c),
            uv[j] - truth.uv_px[c],
            float(rho[j] - truth.range_mm[c]),
            float(m.centroid_sigma_px),
            float(m.range_sigma_mm),
        )
        for j, (m, c, t) in enumerate(zip(result.matched, claimed, true_k, strict=True))
    ]


def marker_summary(errors: list[MarkerError], in_view: int) -> dict:
    """Numbers of one (range bin, diameter) group: in_view (reflectors of that size in
    view in the ok frames), matched, mismatched (left out of the rest), and over the
    correctly matched: centroid |e| median / p90 (px), signed median du, dv (px), range
    |e| median / p90 (mm), signed median range error (mm, the bias), and the RMS of the
    errors over the pipeline's sigmas (centroid per image axis, range)."""
    good = [e for e in errors if e.correct]
    out = {"in_view": in_view, "matched": len(errors), "mismatched": len(errors) - len(good)}
    if not good:
        return {
            **out,
            **dict.fromkeys(
                (
                    "centroid_p50_px",
                    "centroid_p90_px",
                    "du_median_px",
                    "dv_median_px",
                    "range_p50_mm",
                    "range_p90_mm",
                    "range_median_mm",
                    "centroid_z_rms",
                    "range_z_rms",
                ),
                math.nan,
            ),
        }
    c = np.array([e.centroid_error_px for e in good])
    cn = np.linalg.norm(c, axis=1)
    r = np.array([e.range_error_mm for e in good])
    sp = np.array([e.sigma_px for e in good])
    sr = np.array([e.sigma_range_mm for e in good])
    return {
        **out,
        "centroid_p50_px": float(np.median(cn)),
        "centroid_p90_px": float(np.percentile(cn, 90)),
        "du_median_px": float(np.median(c[:, 0])),
        "dv_median_px": float(np.median(c[:, 1])),
        "range_p50_mm": float(np.median(np.abs(r))),
        "range_p90_mm": float(np.percentile(np.abs(r), 90)),
        "range_median_mm": float(np.median(r)),
        "centroid_z_rms": float(np.sqrt(np.mean(cn**2 / (2.0 * sp**2)))),
        "range_z_rms": float(np.sqrt(np.mean((r / sr) ** 2))),
    }


def common_scale_error_px(
    result, truth: TrueImages, catalog: Catalog
) -> tuple[float, float] | None:
    """The common-mode (image-scale) error of an ok pose's correctly matched centroids:
    (c_px, random_px). c_px: kappa times the pattern's rms radius in the image (px), kappa
    the least-squares scale of the measured centroids' offsets from their mean against the
    true ones' (``pipeline.PipelineConfig.common_centroid_bias_px`` is its prior sigma);
    random_px: what the pipeline's own per-marker centroid sigmas alone would give it
    (rms sigma / sqrt(n)). None without a pose or with fewer than 4 correct matches."""
    if not result.ok or not result.matched:
        return None
    index_of = {int(i): k for k, i in enumerate(catalog.ids)}
    uv = np.array([m.centroid_uv for m in result.matched], float)
    rho = np.array([m.distance_mm for m in result.matched], float)
    claimed = np.array([index_of[int(m.catalog_id)] for m in result.matched])
    good = true_correspondences(uv, rho, truth) == claimed
    if good.sum() < 4:
        return None
    d_meas = uv[good] - uv[good].mean(axis=0)
    true_uv = truth.uv_px[claimed[good]]
    d_true = true_uv - true_uv.mean(axis=0)
    kappa = float((d_meas * d_true).sum() / (d_true * d_true).sum()) - 1.0
    r_rms = float(np.sqrt((d_true * d_true).sum(axis=1).mean()))
    sigma = np.array([m.centroid_sigma_px for m in result.matched], float)[good]
    return kappa * r_rms, float(np.sqrt(np.mean(sigma**2) / good.sum()))


def common_scale_excess_px(errors: list[tuple[float, float]]) -> float:
    """The common-mode centroid error beyond the random part, over frames: sqrt(max(0,
    mean c^2 - mean random^2)) (px); NaN without frames."""
    if not errors:
        return math.nan
    e = np.array(errors, float)
    return float(np.sqrt(max(0.0, np.mean(e[:, 0] ** 2) - np.mean(e[:, 1] ** 2))))
