"""The study store's per-frame columns (a pyarrow schema), shared by the chunk task
(``frames``), the store (``store``, an empty table) and the per-cell summary."""

from __future__ import annotations

import pyarrow as pa

from tofpose.lab.pose_judgement import AXES

_F, _I, _B, _S = pa.float64(), pa.int32(), pa.bool_(), pa.string()
#: the store's per-frame columns. Cell axes; the physics the frame drew; truth
#: (T_camera_target, mm and quaternion w, x, y, z); the result (ok, reason, matched
#: reflectors, estimate); its error (rotation vector in deg and position in mm, the
#: pipeline's left perturbation in the camera frame, ``tofpose.lab.pose_judgement``) and
#: the reported 1-sigma of the same components; d2 (squared Mahalanobis distance of the
#: error against the reported covariance); the rules' verdicts
COLUMNS = pa.schema(
    [
        ("cell", _I),
        ("frame", _I),
        ("range_m", _F),
        ("attitude_deg", _F),
        ("offset_fraction", _F),
        ("ambient_lux", _F),
        ("physics", _S),
        ("catalog", _S),
        ("preset", _S),
        ("plate_reflectance", _F),
        ("wall_distance_mm", _F),
        ("blur_sigma_px", _F),
        ("psf_halo_fraction", _F),
        ("gain_min", _F),
        ("gain_max", _F),
        ("retro_falloff_exponent", _F),
        ("true_range_mm", _F),
        ("true_x_mm", _F),
        ("true_y_mm", _F),
        ("true_z_mm", _F),
        ("true_qw", _F),
        ("true_qx", _F),
        ("true_qy", _F),
        ("true_qz", _F),
        ("ok", _B),
        ("reason", _S),
        ("n_matched", _I),
        ("est_x_mm", _F),
        ("est_y_mm", _F),
        ("est_z_mm", _F),
        ("est_qw", _F),
        ("est_qx", _F),
        ("est_qy", _F),
        ("est_qz", _F),
    ]
    + [(f"err_{a}_{'deg' if a[0] == 'r' else 'mm'}", _F) for a in AXES]
    + [(f"sigma_{a}_{'deg' if a[0] == 'r' else 'mm'}", _F) for a in AXES]
    + [
        ("d2", _F),
        ("attitude_error_deg", _F),
        ("position_error_mm", _F),
        ("success", _B),
        ("wrong", _B),
        ("beyond_3sigma", _B),
        ("confidently_wrong", _B),
    ]
)
ERROR_COLUMNS = [f"err_{a}_{'deg' if a[0] == 'r' else 'mm'}" for a in AXES]
SIGMA_COLUMNS = [f"sigma_{a}_{'deg' if a[0] == 'r' else 'mm'}" for a in AXES]
