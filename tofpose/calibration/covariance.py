"""The reported pose covariance calibrated against truth, per range (docs/algorithm.md).

The per-reflector sigmas (``tofpose.stages.extraction.uncertainty``) are a model with floors for
what the
pixel statistics cannot see on a real camera (intrinsic calibration error, PSF
asymmetry, calibration residuals), so on a given camera the covariance they give is
wider or narrower than the errors by a factor that depends on range (where the floors
dominate, where the shot noise does). A recording of the known target with a reference
pose per frame measures that factor: the normalised estimation error squared

    NEES = e^T Sigma^-1 e,   e = (rotation vector of R R_ref^T, t - t_ref)   (6,)

has mean 6 when Sigma is right. ``fit_covariance_scale`` groups the frames by range
(nearest knot in log range) and takes each group's mean NEES / 6 as the factor by
which the covariance is scaled there, leaving out failed poses: frames whose NEES is
more than ``OUTLIER_MEDIANS`` times the group's median (a chi-square with 6 degrees of
freedom exceeds 20 times its median with a probability of ~1e-20, while the NEES of
poses from 3-4 markers has a heavier tail than that, up to ~15 times the median in the
simulator; one wrong pose with a NEES of 400 among 100 frames would otherwise double
the factor); ``CovarianceScale.factor_at`` interpolates it in
log range and holds the end values beyond the knots. It scales only what is reported:
the fit, its weights and its outlier tests are unchanged, so the poses are the same.
A factor above 1 widens a covariance that claims more than the camera gives.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

#: a frame whose NEES exceeds this many times its group's median is a failed pose, not
#: part of the covariance's error distribution (module docstring)
OUTLIER_MEDIANS = 20.0

#: a knot's factor needs this many frames (the mean NEES of n frames of a consistent
#: covariance has a relative sigma of sqrt(2 / (6 n)): 13 % at 20 frames)
MIN_FRAMES_PER_KNOT = 20


def pose_nees(
    R: np.ndarray, t_mm: np.ndarray, covariance: np.ndarray, R_ref: np.ndarray, t_ref_mm: np.ndarray
) -> float:
    """NEES of one pose (R (3, 3), t (3,) mm) with its covariance (6, 6) over (rotation
    vector rad, translation mm), the pipeline's left perturbation, against a reference."""
    e = np.concatenate(
        [
            Rotation.from_matrix(R @ np.asarray(R_ref).T).as_rotvec(),
            np.asarray(t_mm) - np.asarray(t_ref_mm),
        ]
    )
    return float(e @ np.linalg.solve(covariance, e))


@dataclass(frozen=True)
class CovarianceScale:
    """Covariance factors at increasing target distances (module docstring).

    ranges_mm : (k,) knots, increasing; factors : (k,) positive multipliers of the
    reported covariance there.
    """

    ranges_mm: tuple[float, ...]
    factors: tuple[float, ...]

    def __post_init__(self) -> None:
        r, f = np.asarray(self.ranges_mm, float), np.asarray(self.factors, float)
        if r.ndim != 1 or len(r) == 0 or r.shape != f.shape:
            raise ValueError(
                f"a covariance scale needs as many factors as ranges (at least one), got "
                f"{len(self.ranges_mm)} ranges and {len(self.factors)} factors"
            )
        if not (np.all(np.isfinite(r)) and np.all(r > 0) and np.all(np.diff(r) > 0)):
            raise ValueError(f"covariance scale ranges must be positive and increasing, got {r}")
        if not (np.all(np.isfinite(f)) and np.all(f > 0)):
            raise ValueError(f"covariance scale factors must be positive, got {f}")

    def factor_at(self, range_mm: float) -> float:
        """The factor at a target distance, linear in log range between the knots."""
        logs = [math.log(r) for r in self.ranges_mm]
        return float(np.interp(math.log(max(range_mm, 1e-9)), logs, self.factors))

    def to_dict(self) -> dict:
        return {
            "ranges_mm": [float(v) for v in self.ranges_mm],
            "factors": [float(v) for v in self.factors],
        }

    @staticmethod
    def from_dict(d: dict) -> CovarianceScale:
        """Parse ``to_dict``'s form; ``ValueError`` naming what is missing or wrong."""
        try:
            return CovarianceScale(
                tuple(float(v) for v in d["ranges_mm"]), tuple(float(v) for v in d["factors"])
            )
        except KeyError as exc:
            raise ValueError(f"covariance scale lacks {exc.args[0]!r}") from None
        except TypeError as exc:
            raise ValueError(
                f"covariance scale: ranges_mm and factors must be lists of numbers ({exc})"
            ) from None


@dataclass(frozen=True)
class CovarianceFit:
    """The fitted scale and the data behind each knot: frames (k,), the mean NEES (k,) of
    the unscaled covariance over the frames used, and the frames left out as failed
    poses (k,)."""

    scale: CovarianceScale
    frames: tuple[int, ...]
    mean_nees: tuple[float, ...]
    outliers: tuple[int, ...]


def fit_covariance_scale(
    range_mm: Sequence[float],
    nees: Sequence[float],
    knots_mm: Sequence[float],
    min_frames: int = MIN_FRAMES_PER_KNOT,
) -> CovarianceFit:
    """Factors at ``knots_mm`` from frames at target distances ``range_mm`` (n,) whose
    unscaled covariance gave ``nees`` (n,). ``ValueError`` naming the knots with fewer
    than ``min_frames`` frames."""
    r = np.asarray(range_mm, float)
    v = np.asarray(nees, float)
    knots = np.sort(np.asarray(knots_mm, float))
    if r.shape != v.shape:
        raise ValueError(f"{len(r)} ranges for {len(v)} NEES values")
    ok = np.isfinite(r) & np.isfinite(v) & (r > 0)
    nearest = np.argmin(np.abs(np.log(r[ok])[:, None] - np.log(knots)[None]), axis=1)
    counts = np.bincount(nearest, minlength=len(knots))
    thin = [f"{k:.0f} mm ({c})" for k, c in zip(knots, counts, strict=True) if c < min_frames]
    if thin:
        raise ValueError(
            f"a covariance factor needs >= {min_frames} frames per range, too few at "
            + ", ".join(thin)
        )
    means, outliers = [], []
    for i in range(len(knots)):
        group = v[ok][nearest == i]
        used = group[group <= OUTLIER_MEDIANS * np.median(group)]
        means.append(float(np.mean(used)))
        outliers.append(len(group) - len(used))
    scale = CovarianceScale(tuple(float(k) for k in knots), tuple(m / 6.0 for m in means))
    return CovarianceFit(scale, tuple(int(c) for c in counts), tuple(means), tuple(outliers))


def auto_knots(
    range_mm: Sequence[float], ratio: float = 1.5, min_frames: int = MIN_FRAMES_PER_KNOT
) -> list[float]:
    """Knots every ``ratio`` in distance over the frames' span, those that would get
    fewer than ``min_frames`` frames (nearest knot in log range) removed one at a time,
    the thinnest first; at least one knot (the geometric mean) remains."""
    logs = np.log(np.asarray([r for r in range_mm if np.isfinite(r) and r > 0], float))
    if len(logs) == 0:
        raise ValueError("no frame with a pose: nothing to calibrate the covariance from")
    n = max(int(np.ceil((logs.max() - logs.min()) / math.log(ratio))), 0) + 1
    knots = list(np.linspace(logs.min(), logs.max(), n)) if n > 1 else [float(logs.mean())]
    while len(knots) > 1:
        counts = np.bincount(
            np.argmin(np.abs(logs[:, None] - np.array(knots)[None]), axis=1), minlength=len(knots)
        )
        if counts.min() >= min_frames:
            break
        knots.pop(int(np.argmin(counts)))
    return [float(np.exp(k)) for k in knots]
