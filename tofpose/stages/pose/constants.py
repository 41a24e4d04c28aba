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
