"""The reference statement of ``kernels.solve.solve_pairs``
(``tofpose.stages.pose.reference.solve``)
against the compiled call on the inputs the pipeline gives it on rendered frames (each
refinement mode, the offset prior on and off, completion, mixed-pixel ranges, a planted
outlier), and its pieces (completion, the perspective bias) against the kernels and
truth.

Tolerances: the steps before the fit are the same arithmetic (1e-9 px, mm); the fit is
``pose.fit_with_outliers``'s: the same kept reflectors, the pose to 1e-3 of its sigma
where SciPy's optimum replaces the Gauss-Newton steps (ml), 1e-8 sigma otherwise, and the
common range offset to 0.1 of its sigma (``test_pose``: the kernel's Jacobian leaves out
a small term, which moves its offset by 1-5 % of its sigma).
"""

from __future__ import annotations

from dataclasses import replace
from functools import cache

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tests.conftest import facing_pose, render
from tofpose import PosePipeline
from tofpose.config import PipelineConfig
from tofpose.core.camera import CameraModel
from tofpose.core.catalog import paper_target
from tofpose.core.records import Candidates
from tofpose.stages.extraction.constants import MIX_FIELDS
from tofpose.stages.extraction.reference import mixed_pixels
from tofpose.stages.pose.constants import REFINE_ML
from tofpose.stages.pose.kernels import solve as kernel
from tofpose.stages.pose.kernels.pose import class_scale_covariance, range_bias_covariance
from tofpose.stages.pose.kernels.solve import complete_pairs, solve_pairs
from tofpose.stages.pose.records import Reflectors
from tofpose.stages.pose.reference import pose as reference_pose
from tofpose.stages.pose.reference import solve as reference

#: configurations of the pipeline whose solver inputs are replayed
CONFIGS = {
    "default": {},  # ml, offset prior, mixed-pixel ranges, perspective bias, completion
    "no-offset": {"estimate_range_offset": False},
    "none": {"refinement": "none"},
    "los": {"refinement": "los"},
    "paper": dict(refinement="los", mixed_pixel_radius_px=0.0, correct_perspective_bias=False),
}
DISTANCES_MM = (1500.0, 4000.0, 8000.0)
#: the truth of the rendered frames
POSE = {"pitch_deg": 4, "yaw_deg": -6, "roll_deg": 12, "offset_mm": (-110.0, -55.0)}
OPTIMISER_SIGMA = 1e-3
EXACT_SIGMA = 1e-8


@cache
def _captured(config_name, distance_mm):
    """The arguments of the pipeline's first ``solve_pairs`` call on a rendered frame of
    the paper target at ``distance_mm`` (its inputs from real extraction and matching)."""
    calls = []

    def recording(*args):
        calls.append(args)
        return solve_pairs(*args)

    config = replace(PipelineConfig(), **CONFIGS[config_name])
    frame = render(facing_pose(distance_mm, **POSE), seed=1)
    pipeline = PosePipeline(CameraModel(), paper_target(), config)
    # the solver's calls go through its Arithmetic record: record them there
    solver = pipeline._solver
    solver.arithmetic = replace(solver.arithmetic, solve_pairs=recording)
    pipeline.process(frame.gray, frame.distance_mm)
    assert calls, "the pipeline did not reach the solver"
    return calls[0]


def _sigmas(R, t, R_ref, t_ref, cov):
    d = np.concatenate((Rotation.from_matrix(R @ R_ref.T).as_rotvec(), t - t_ref))
    return float(np.sqrt(d @ np.linalg.solve(cov, d)))


def _compare(args):
    """solve_pairs and its reference on ``args``: equal as the module docstring says.
    Returns both outputs (``SolvedPairs``)."""
    got, want = reference.solve_pairs(*args), kernel.solve_pairs(*args)
    np.testing.assert_array_equal(got.k_idx, want.k_idx)  # pairs after completion
    np.testing.assert_array_equal(got.i_idx, want.i_idx)
    np.testing.assert_allclose(got.uv, want.uv, rtol=1e-12, atol=1e-9)  # before the fit
    for a, b in zip(got.observed, want.observed, strict=True):  # x, e, rho, sr, sb
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-9)
    g, w = got.result, want.result
    np.testing.assert_array_equal(g.kept, w.kept)
    fit, prior = args[5], args[7]
    ml = fit.refinement == REFINE_ML
    if g.offset_mm != 0.0 or w.offset_mm != 0.0:  # the offset was estimated: within 0.1 sigma
        assert abs(g.offset_mm - w.offset_mm) < 0.1 * g.offset_sigma_mm
        assert g.offset_sigma_mm == pytest.approx(w.offset_sigma_mm, rel=1e-3)
        # and the refit at the kernel's offset is the kernel's
        x, e, rho, sr, sb = (a[w.kept] for a in want.observed)
        shifted = Reflectors(x=x, e=e, rho=rho - w.offset_mm, sr=sr, sb=sb)
        cap = fit.max_systematic_centroid_sigma_px / args[4].fx
        refit = reference_pose.fit_adaptive(shifted, fit, cap)
        assert _sigmas(refit.R, refit.t, w.fit.R, w.fit.t, w.fit.covariance) < OPTIMISER_SIGMA
        return got, want
    assert (
        (g.offset_mm, g.offset_sigma_mm)
        == (w.offset_mm, w.offset_sigma_mm)
        == (
            0.0,
            prior.sigma_mm,
        )
    )
    tol = OPTIMISER_SIGMA if ml else EXACT_SIGMA
    assert _sigmas(g.fit.R, g.fit.t, w.fit.R, w.fit.t, w.fit.covariance) < tol
    np.testing.assert_allclose(g.fit.sr, w.fit.sr, rtol=1e-9, atol=25.0 / 2**16 * ml)
    assert g.fit.chi2 == pytest.approx(w.fit.chi2, rel=1e-5 if ml else 1e-8)
    cov, want_cov = g.fit.covariance, w.fit.covariance
    np.testing.assert_allclose(cov, want_cov, rtol=1e-5, atol=1e-9 * np.abs(want_cov).max())
    return got, want


@pytest.mark.parametrize("distance_mm", DISTANCES_MM)
@pytest.mark.parametrize("config_name", CONFIGS)
def test_solve_pairs_equals_the_kernel_on_the_pipelines_inputs(config_name, distance_mm):
    """The pipeline's own solver inputs replayed; the pose within 5 sigma of the truth."""
    got, _ = _compare(_captured(config_name, distance_mm))
    truth = facing_pose(distance_mm, **POSE)
    fit = got.result.fit
    assert got.result.kept.all() and len(got.k_idx) == len(paper_target())
    assert _sigmas(fit.R, fit.t, truth.R, truth.t_mm, fit.covariance) < 6.0


@pytest.mark.parametrize("distance_mm", DISTANCES_MM)
@pytest.mark.parametrize("config_name", ["default", "none", "los", "paper"])
def test_a_planted_outlier_is_dropped_as_by_the_kernel(config_name, distance_mm):
    """60 mm added to one matched candidate's range (its point and mixing sums moved
    with it): the kernel and the reference keep the same reflectors; with the ML fit
    exactly the planted one is dropped; with the SVD pose alone it is too (perhaps with
    another); the line of sight's excess range sigma (up to 25 mm) may hide it at 8 m,
    in the kernel as here."""
    args = list(_captured(config_name, distance_mm))
    k = int(args[1][2])
    candidates = args[0]
    y, rho = candidates.y_mm.copy(), candidates.range_mm.copy()
    mix = candidates.mixing.copy()
    y[k] *= (rho[k] + 60.0) / rho[k]
    rho[k] += 60.0
    if np.isfinite(mix[k, 0]):
        mixed_pixels.shift_mixing(mix[k], 60.0)
    args[0] = candidates._replace(y_mm=y, range_mm=rho, mixing=mix)
    got, _ = _compare(tuple(args))
    kept = got.result.kept
    if config_name in ("default", "none"):
        assert not kept[list(got.k_idx).index(k)]
    if config_name == "default":
        assert kept.sum() == len(kept) - 1


@pytest.mark.parametrize("distance_mm", DISTANCES_MM)
def test_completion_restores_pairs_left_out_as_the_kernel_does(distance_mm):
    """Two matched pairs left out of the input: completion adds them back (to the
    blobs they came from), the rest as before."""
    args = list(_captured("default", distance_mm))
    k_idx, i_idx = args[1], args[2]
    args[1], args[2] = k_idx[:-2].copy(), i_idx[:-2].copy()
    got, _ = _compare(tuple(args))
    assert dict(zip(got.k_idx.tolist(), got.i_idx.tolist(), strict=True)) == dict(
        zip(k_idx.tolist(), i_idx.tolist(), strict=True)
    )
    args[6] = 0.0  # no completion: the pairs stay out
    got, _ = _compare(tuple(args))
    assert len(got.k_idx) == len(k_idx) - 2


@pytest.mark.parametrize("distance_mm", DISTANCES_MM)
def test_the_covariances_of_the_real_fit_equal_the_kernels(distance_mm):
    """range_bias_covariance and class_scale_covariance (the catalog's size classes) at
    the fit of a rendered frame: to 1e-6 (the reference's Jacobian by central
    differences)."""
    args = _captured("no-offset", distance_mm)
    out = kernel.solve_pairs(*args)
    kept, fit = out.result.kept, out.result.fit
    x, e, rho, _, _ = (a[kept] for a in out.observed)
    fitted = Reflectors(x=x, e=e, rho=rho, sr=fit.sr, sb=fit.sb)
    fit_args = (fitted, fit.R, fit.t)
    got = reference_pose.range_bias_covariance(*fit_args, 15.0)
    want = range_bias_covariance(*fit_args, 15.0)
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-9 * np.abs(want).max())
    _, size_class = np.unique(np.round(paper_target().diameters_mm, 3), return_inverse=True)
    group = size_class[out.i_idx[kept]]
    n = int(size_class.max()) + 1
    assert n > 1
    got = reference_pose.class_scale_covariance(*fit_args, group, n, 0.05 / 300, 0.002)
    want = class_scale_covariance(*fit_args, group, n, 0.05 / 300, 0.002)
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-9 * np.abs(want).max())


def test_solve_pairs_of_noiseless_measurements_is_the_true_pose():
    """Points, centroids and ranges made from the truth (perspective bias included in
    the centroids, no mixing sums): the true pose, chi^2 ~ 0, nothing dropped."""
    cam, cat = CameraModel(), paper_target()
    truth = facing_pose(3000.0, **POSE)
    centres = cat.positions_mm @ truth.R.T + truth.t_mm
    radii = cat.diameters_mm / 2
    uv = cam.project(centres) + reference.disc_centre_offsets(cam.K, centres, truth.R[:, 2], radii)
    rho = np.linalg.norm(centres, axis=1)
    n = len(cat)
    args = _captured("default", 4000.0)
    catalog, camera, fit, prior = args[3], args[4], args[5], args[7]
    order = np.arange(n)[::-1].copy()  # candidate k shows reflector order[k]
    candidates = Candidates(
        uv_px=uv[order],
        range_mm=rho[order],
        y_mm=centres[order],
        weights=np.ones(n),
        sigma_px=np.full(n, 0.1),
        sigma_range_mm=np.full(n, 3.0),
        mixing=np.full((n, MIX_FIELDS), np.nan),
    )
    out = reference.solve_pairs(candidates, np.arange(n), order, catalog, camera, fit, 0.0, prior)
    assert out.result.kept.all()
    f = out.result.fit
    assert _sigmas(f.R, f.t, truth.R, truth.t_mm, f.covariance) < 1e-4
    assert f.chi2 < 1e-6


def test_disc_centre_offsets_and_completion_equal_the_kernels():
    """disc_centre_offsets (the conic's centre) against the kernel's pole of the line at
    infinity over ranges and tilts (1e-10 px); complete_pairs against the kernel on
    random scenes (equal)."""
    from tofpose.stages.extraction.kernels.perspective import disc_centre_offsets

    cam = CameraModel()
    rng = np.random.default_rng(3)
    for _ in range(100):
        z = rng.uniform(400.0, 12000.0)
        centres = np.column_stack(
            (
                rng.uniform(-0.4, 0.4, 8) * z,
                rng.uniform(-0.3, 0.3, 8) * z,
                z + rng.uniform(-200.0, 200.0, 8),
            )
        )
        normal = np.array([*rng.uniform(-1.5, 1.5, 2), -1.0])
        radii = rng.uniform(5.0, 40.0, 8)
        np.testing.assert_allclose(
            reference.disc_centre_offsets(cam.K, centres, normal, radii),
            disc_centre_offsets(cam.K, centres, normal, radii),
            atol=1e-10,
        )
    for _ in range(100):
        e = int(rng.integers(4, 10))
        xyz = rng.uniform(-200, 200, (e, 3))
        R = Rotation.random(random_state=int(rng.integers(1 << 31))).as_matrix()
        t = np.array([10.0, -40.0, 3000.0])
        y = np.vstack(
            (
                xyz[rng.permutation(e)] @ R.T + t + rng.normal(0, 3.0, (e, 3)),
                rng.uniform(-300, 300, (2, 3)) + t,
            )
        )
        n = int(rng.integers(0, e + 1))
        k_idx, i_idx = np.arange(n), rng.permutation(e)[:n]
        got = reference.complete_pairs(y, k_idx, i_idx, xyz, R, t, 8.0)
        want = complete_pairs(y, k_idx, i_idx, xyz, R, t, 8.0)
        np.testing.assert_array_equal(got[0], want[0])
        np.testing.assert_array_equal(got[1], want[1])


def test_a_tilted_disc_images_off_its_centre_and_a_face_on_one_does_not():
    cam = CameraModel()
    centres = np.array([[0.0, 0.0, 1000.0], [300.0, -100.0, 1000.0]])
    radii = np.array([40.0, 17.5])
    face_on = reference.disc_centre_offsets(cam.K, centres, np.array([0.0, 0.0, -1.0]), radii)
    assert np.abs(face_on).max() < 1e-9  # a fronto-parallel circle images as a circle
    tilted = reference.disc_centre_offsets(cam.K, centres, np.array([0.3, -0.2, -1.0]), radii)
    assert np.abs(tilted[0]).max() > 0.01
    # truth: the centre of the imaged rim's points, by a conic fit through them
    import cv2

    n = np.array([0.3, -0.2, -1.0]) / np.linalg.norm([0.3, -0.2, -1.0])
    a = np.cross(n, [1.0, 0.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(n, a)
    th = np.linspace(0, 2 * np.pi, 720, endpoint=False)
    rim = centres[0] + radii[0] * (np.outer(np.cos(th), a) + np.outer(np.sin(th), b))
    p = rim @ cam.K.T
    (cu, cv_), _, _ = cv2.fitEllipse((p[:, :2] / p[:, 2:]).astype(np.float32))
    q = cam.K @ centres[0]
    np.testing.assert_allclose(tilted[0], [cu - q[0] / q[2], cv_ - q[1] / q[2]], atol=2e-3)
