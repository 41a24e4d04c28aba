"""The pose stage's arithmetic (§5) per implementation: ``COMPILED`` (its kernels) and
``REFERENCE`` (``reference``), each field with the kernel's calling convention."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from tofpose.stages.pose.kernels import pose, solve, verify
from tofpose.stages.pose.reference import pose as ref_pose
from tofpose.stages.pose.reference import solve as ref_solve
from tofpose.stages.pose.reference import verify as ref_verify


@dataclass(frozen=True)
class PoseArithmetic:
    """§5 and what the pipeline reports of it: the fit, its checks, its covariances."""

    name: str
    solve_pairs: Callable
    pose_check: Callable
    aperture_returns: Callable
    facing_cosine: Callable
    absolute_orientation: Callable
    concluding_covariances: Callable
    covariance_envelope: Callable
    point_residuals_mm: Callable
    pattern_scale_sigma: Callable


_FIELDS = (
    "facing_cosine",
    "absolute_orientation",
    "concluding_covariances",
    "covariance_envelope",
    "point_residuals_mm",
    "pattern_scale_sigma",
)

COMPILED = PoseArithmetic(
    "compiled",
    solve.solve_pairs,
    verify.pose_check,
    verify.aperture_returns,
    **{f: getattr(pose, f) for f in _FIELDS},
)
REFERENCE = PoseArithmetic(
    "reference",
    ref_solve.solve_pairs,
    ref_verify.pose_check,
    ref_verify.aperture_returns,
    **{f: getattr(ref_pose, f) for f in _FIELDS},
)
