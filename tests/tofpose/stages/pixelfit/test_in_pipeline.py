"""The pixel fit as the pipeline runs it (``PipelineConfig.pixel_fit``): an ok pose is
replaced by the fit's, with the fit's covariance, and says so; a disc the model cannot
explain leaves the centroid pose, with the reason; off by default."""

import numpy as np
from scipy.spatial.transform import Rotation

from tofpose import CameraModel, PipelineConfig, PosePipeline, paper_target
from tofpose.config import PixelFitConfig
from tofpose.core.geometry import RigidTransform, rotation_from_euler_deg
from tofpose.sim.bench import R_FACING
from tofpose.sim.render import SensorModel, render_frame
from tofpose.sim.scene import TargetScene
from tofpose.stages.pixelfit.fit import fit_pose_to_pixels

CAM = CameraModel()
CAT = paper_target()
ON = PipelineConfig(pixel_fit=PixelFitConfig(enabled=True))


def _frame(seed=3):
    T = RigidTransform(rotation_from_euler_deg(2, -3, 10) @ R_FACING, np.array([40, -20, 3000.0]))
    f = render_frame(
        CAM, TargetScene(), T, SensorModel(supersampling=32), np.random.default_rng(seed)
    )
    return T, f


def test_an_ok_pose_is_the_pixel_fits_and_within_its_covariance():
    T, f = _frame()
    plain = PosePipeline(CAM, CAT).process(f.gray, f.distance_mm)
    fitted = PosePipeline(CAM, CAT, ON).process(f.gray, f.distance_mm)
    assert plain.ok and plain.pixel_fit == "" and "pixel fit" not in plain.timings_ms
    assert fitted.ok and fitted.pixel_fit == "ok", fitted.pixel_fit
    assert "pixel fit" in fitted.timings_ms
    assert not np.allclose(fitted.t_mm, plain.t_mm)  # the fit moved the pose
    e = np.concatenate([Rotation.from_matrix(fitted.R @ T.R.T).as_rotvec(), fitted.t_mm - T.t_mm])
    assert e @ np.linalg.solve(fitted.covariance, e) < 20.06  # chi2_6 at 3 sigma
    assert np.allclose(fitted.euler_deg, plain.euler_deg, atol=0.2)
    # the fit's covariance is the model's, tighter than the centroid pose's
    assert np.trace(fitted.covariance[:3, :3]) < np.trace(plain.covariance[:3, :3])


def test_a_half_shadowed_disc_is_left_out_and_the_pose_says_so():
    """Disc 6's left half at 30 % of its light (a shadow, a smudge): the centroid pipeline
    still matches it; its pixels do not fit a disc, so the fit leaves it out, holds on
    the other seven, and the result names it."""
    T, f = _frame()
    gray = f.gray.copy()
    rows, cols = np.nonzero(f.surface_id == 3 + int(np.flatnonzero(CAT.ids == 6)[0]))
    left = cols < np.median(cols)
    gray[rows[left], cols[left]] = (gray[rows[left], cols[left]] * 0.3).astype(np.uint16)
    plain = PosePipeline(CAM, CAT).process(gray, f.distance_mm)
    fitted = PosePipeline(CAM, CAT, ON).process(gray, f.distance_mm)
    assert plain.ok and fitted.ok and 6 in [m.catalog_id for m in plain.matched]
    assert fitted.pixel_fit == "ok", fitted.pixel_fit
    assert fitted.pixel_fit_left_out.startswith("markers [6] left out: "), fitted.pixel_fit_left_out
    assert plain.pixel_fit_left_out == ""
    e = np.concatenate([Rotation.from_matrix(fitted.R @ T.R.T).as_rotvec(), fitted.t_mm - T.t_mm])
    assert e @ np.linalg.solve(fitted.covariance, e) < 20.06  # chi2_6 at 3 sigma


def _half_out_of_view(offset_mm: float):
    """A frame of the target ``offset_mm`` across the view at 3 m (its right side out of
    the image), the centroid pose, the pipeline's with the fit, and the fit run alone
    with the pipeline's options."""
    T = RigidTransform(
        rotation_from_euler_deg(3, -4, 5) @ R_FACING, np.array([offset_mm, 0, 3000.0])
    )
    f = render_frame(CAM, TargetScene(), T, SensorModel(supersampling=32), np.random.default_rng(5))
    plain = PosePipeline(CAM, CAT).process(f.gray, f.distance_mm)
    fitted = PosePipeline(CAM, CAT, ON).process(f.gray, f.distance_mm)
    assert plain.ok and fitted.ok and fitted.pixel_fit == "ok", (plain.reason, fitted.pixel_fit)
    own = fit_pose_to_pixels(
        f.gray,
        f.distance_mm,
        CAM,
        CAT,
        plain.R,
        plain.t_mm,
        [m.catalog_id for m in plain.matched],
        fit_range_offset=True,
        range_offset_sigma_mm=plain.range_offset.prior_sigma_mm,
    )
    assert own.ok and own.covariance is not None
    return plain, fitted, own


def test_three_markers_report_a_covariance_that_holds_the_centroid_poses():
    """With three markers in view (the target half out of the field of view) the fit
    cannot delete a disc and still fit the pose, so it cannot check its own covariance:
    the pipeline reports the envelope of the fit's and the centroid pose's (both
    ellipsoids inside it), the fit's pose kept."""
    plain, fitted, own = _half_out_of_view(1600.0)
    assert fitted.n_matched == 3 and not own.deletion_checked
    assert not np.allclose(fitted.t_mm, plain.t_mm)  # the fit's pose
    C = fitted.covariance
    for inner in (plain.covariance, own.covariance):  # C - inner is positive semi-definite
        assert np.linalg.eigvalsh(C - inner).min() > -1e-9 * np.abs(C).max()
    assert np.trace(C[:3, :3]) > 1.5 * np.trace(own.covariance[:3, :3])


def test_four_markers_keep_the_fits_checked_covariance():
    """With a fourth marker each disc can be deleted: the fit's own covariance stands."""
    _, fitted, own = _half_out_of_view(1500.0)
    assert fitted.n_matched == 4 and own.deletion_checked
    np.testing.assert_allclose(fitted.covariance, own.covariance, rtol=1e-6)
