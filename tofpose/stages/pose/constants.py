"""The pose stage's constants, shared by its kernels, its reference statement and its
orchestration (defined once: numba freezes a module global into the compiled code as it
reads here)."""

from __future__ import annotations

#: refinement modes of ``fit_pose`` (``PipelineConfig.refinement``: "none", "ml", "los")
REFINE_NONE, REFINE_ML, REFINE_LOS = 0, 1, 2
#: medians of chi^2 with 1 (a range residual) and 2 (a lateral pair) degrees of freedom,
#: to five digits (scipy.stats.chi2(k).median(): 0.454936..., 2 ln 2 = 1.386294...)
MEDIAN_CHI2_1DOF = 0.45494
MEDIAN_CHI2_2DOF = 1.38629
#: outcomes of ``pose_check``
CONSISTENT, BEHIND_CAMERA, DARK_REFLECTOR = 0, 1, 2
#: fewest reflectors whose leave-one-out fits are determined (each keeps 3 x 3
#: measurements for the 6 pose parameters)
MIN_LEAVE_ONE_OUT = 4

#: the a-posteriori variance factor narrows the fit's covariance (``pipeline.
#: variance_factor``) only from this many reflectors (chi^2 of 3 n - 6 >= 9 degrees of
#: freedom): with fewer, a small chi^2 by luck is too common to be evidence
NARROWING_MIN_REFLECTORS = 5
#: ... and only to the upper bound of the variance factor at this confidence: chi^2 /
#: chi^2_dof(0.05), so that a frame whose sigmas are right is narrowed in 5 % of cases
NARROWING_CONFIDENCE = 0.95
#: ... and never below this (sigmas at most 5x narrower than the noise model's): a chi^2
#: near 0 is a degenerate fit, not a perfect one
MIN_VARIANCE_FACTOR = 0.04
