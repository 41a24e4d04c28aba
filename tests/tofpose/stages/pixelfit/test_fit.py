"""The pixel fit against rendered truth: noiseless convergence, noisy accuracy against
the Cramer-Rao bound with consistent sigmas, and the fallback on a disc the model does
not explain."""

from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from bench.crlb import pose_crlb
from tofpose import CameraModel, PosePipeline, paper_target
from tofpose.core.geometry import RigidTransform, rotation_from_euler_deg
from tofpose.sim.bench import R_FACING
from tofpose.sim.render import SensorModel, render_frame
from tofpose.sim.scene import TargetScene
from tofpose.stages.pixelfit import fit as fit_module
from tofpose.stages.pixelfit.constants import MAX_ITERATIONS
from tofpose.stages.pixelfit.fit import PixelNoise, fit_pose_to_pixels

CAM = CameraModel()
CAT = paper_target()


def _error(R, t_mm, T):
    return np.concatenate([Rotation.from_matrix(R @ T.R.T).as_rotvec(), t_mm - T.t_mm])


def _pose(rng, range_mm):
    e = rng.uniform(-5.0, 5.0, 3)
    return RigidTransform(
        rotation_from_euler_deg(*e) @ R_FACING,
        np.array([*rng.uniform(-150.0, 150.0, 2), range_mm]),
    )


@pytest.mark.parametrize("range_mm", [3000.0, 6000.0])
def test_noiseless_frame_converges_to_truth_from_several_bounds_away(range_mm):
    # 64 x 64 samples per edge pixel: the renderer's own point sampling (16 x 16 leaves
    # +-10-40 counts on rim pixels) would be a model error of ~0.5-2 bounds
    sensor = SensorModel(noise=False, supersampling=64)
    T = RigidTransform(rotation_from_euler_deg(2, -3, 10) @ R_FACING, np.array([50, -30, range_mm]))
    f = render_frame(CAM, TargetScene(), T, sensor)
    pos_b, att_b = pose_crlb(f, T, CAM, CAT, sensor)
    rng = np.random.default_rng(0)
    w = rng.normal(size=3)
    dt = rng.normal(size=3)
    R0 = Rotation.from_rotvec(w / np.linalg.norm(w) * np.radians(5 * att_b)).as_matrix() @ T.R
    t0 = T.t_mm + dt / np.linalg.norm(dt) * 5 * pos_b
    res = fit_pose_to_pixels(
        f.gray, f.distance_mm, CAM, CAT, R0, t0, CAT.ids, noise=PixelNoise.from_sensor(sensor)
    )
    assert res.ok and res.converged, res.reason
    err = _error(res.R, res.t_mm, T)
    # what is left is the model's own error (0.4 bound in attitude at 3 m: see
    # bench/pixelfit.py's docstring), far below the 5 bounds of the start
    assert np.degrees(np.linalg.norm(err[:3])) < 0.5 * att_b
    assert np.linalg.norm(err[3:]) < 0.5 * pos_b
    assert np.all(res.marker_rms_sigma < 1.0)


def _rendered_fits(sensor, rng, range_mm, frames, variants, damage=None):
    """For ``frames`` poses drawn at ``range_mm``: the frame rendered, the centroid
    pipeline's pose and matches, then ``fit_pose_to_pixels`` from them once per entry of
    ``variants`` (keyword arguments of the fit; the noise defaults to the sensor's).
    ``damage(frame, distance, rng)`` alters the distance image in place before the fits.
    Yields (truth, frame, [result per variant])."""
    for _ in range(frames):
        T = _pose(rng, range_mm)
        f = render_frame(CAM, TargetScene(), T, sensor, rng)
        r = PosePipeline(CAM, CAT).process(f.gray, f.distance_mm)
        assert r.ok, r.reason
        distance = f.distance_mm.copy()
        if damage is not None:
            damage(f, distance, rng)
        ids = [m.catalog_id for m in r.matched]
        fits = []
        for kwargs in variants:
            options = {"noise": PixelNoise.from_sensor(sensor), **kwargs}
            res = fit_pose_to_pixels(f.gray, distance, CAM, CAT, r.R, r.t_mm, ids, **options)
            assert res.ok, res.reason
            fits.append(res)
        yield T, f, fits


@pytest.mark.parametrize(
    "range_mm",
    [
        pytest.param(
            1000.0,
            marks=pytest.mark.xfail(
                strict=False,
                reason="at 1 m the attitude RMS is 1.3-1.6 bounds (1.47 with these seeds, "
                "at the 1.5 limit): the gain-shape nuisance parameters cost 10-20 % over "
                "the bound, which knows the gain, and the renderer's 32 x 32 rim sampling "
                "is still an error of a few counts per rim pixel; its sigmas stay "
                "consistent (errors/sigmas ~1.0)",
            ),
        ),
        3000.0,
        6000.0,
    ],
)
def test_noisy_frames_reach_the_bound_with_consistent_sigmas(range_mm):
    sensor = SensorModel(supersampling=32)
    rng = np.random.default_rng([49, int(range_mm)])
    errs, covs, bounds = [], [], []
    for T, f, (res,) in _rendered_fits(sensor, rng, range_mm, 16, [{}]):
        errs.append(_error(res.R, res.t_mm, T))
        covs.append(res.covariance)
        bounds.append(pose_crlb(f, T, CAM, CAT, sensor))
    e = np.array(errs)
    b = np.array(bounds)
    rms_att = np.degrees(np.sqrt(np.mean(np.sum(e[:, :3] ** 2, axis=1))))
    rms_pos = np.sqrt(np.mean(np.sum(e[:, 3:] ** 2, axis=1)))
    assert rms_att < 1.5 * np.sqrt(np.mean(b[:, 1] ** 2))
    assert rms_pos < 1.5 * np.sqrt(np.mean(b[:, 0] ** 2))
    z_att = np.sqrt(
        np.mean(
            [x[:3] @ np.linalg.solve(C[:3, :3], x[:3]) / 3 for x, C in zip(e, covs, strict=True)]
        )
    )
    z_pos = np.sqrt(
        np.mean(
            [x[3:] @ np.linalg.solve(C[3:, 3:], x[3:]) / 3 for x, C in zip(e, covs, strict=True)]
        )
    )
    assert 0.7 < z_att < 1.3
    assert 0.7 < z_pos < 1.3


def _nees_per_dof(errs, covs, block):
    return float(
        np.mean(
            [
                x[block] @ np.linalg.solve(C[block, block], x[block]) / 3
                for x, C in zip(errs, covs, strict=True)
            ]
        )
    )


def _measured_against_none(sensor, rng, range_mm, frames, measured, none, damage=None):
    """Fits of ``frames`` rendered poses with the model error ``measured`` (a
    ``PixelNoise``) and with it set to 0 (``none``): (errors, covariances) of each, and
    the measured value (``PixelFitResult`` attribute of the same name as the noise
    field that is None) per frame. ``damage(frame, distance, rng)`` alters the distance
    image in place before the fit. Without the discs' deletion terms, whose safety net
    would hide what the noise model's own term does."""
    field = next(
        k for k in ("coverage_sigma", "disc_range_sigma_mm") if getattr(measured, k) is None
    )
    out = {"measured": ([], []), "none": ([], [])}
    values = []
    common = {"max_marker_rms_sigma": 10, "disc_deletion_terms": False}
    variants = [{"noise": measured, **common}, {"noise": none, **common}]
    for T, _, fits in _rendered_fits(sensor, rng, range_mm, frames, variants, damage):
        for name, res in zip(("measured", "none"), fits, strict=True):
            out[name][0].append(_error(res.R, res.t_mm, T))
            out[name][1].append(res.covariance)
        values.append(getattr(fits[0], field))
    return out["measured"], out["none"], values


BLOCKS = (slice(0, 3), slice(3, 6))  # attitude, position


def test_a_coarsely_sampled_rim_is_measured_as_model_error_and_widens_the_sigmas():
    """A renderer that samples each rim pixel at 4 x 4 points (as many renderers do)
    gets rim coverages wrong by a few hundredths of a pixel: the same in every frame of a
    pose, so the inverse Fisher covariance of the shot noise alone is several times too
    narrow. Measured on the frame's rim residuals, that error brings the sigmas back to
    the errors; given as 0, it does not."""
    sensor = SensorModel(supersampling=4)
    noise = PixelNoise.from_sensor(sensor)
    (errs, covs), (errs0, covs0), measured = _measured_against_none(
        sensor,
        np.random.default_rng([49, 4]),
        4000.0,
        12,
        noise,
        replace(noise, coverage_sigma=0.0),
    )
    # 16 points per pixel: a straight rim's coverage is off by up to ~1/8 of a pixel
    assert 0.015 < np.median(measured) < 0.15
    assert all(_nees_per_dof(errs0, covs0, b) > 2.5 for b in BLOCKS)
    assert all(0.4 < _nees_per_dof(errs, covs, b) < 1.8 for b in BLOCKS)


def test_range_errors_of_each_disc_are_measured_and_widen_the_sigmas():
    """An uncalibrated camera's range error differs from disc to disc (amplitude-related
    and per-pixel offsets): here each disc's distance pixels carry their own offset, drawn
    with sigma 6 mm. The fit measures that spread on the discs' mean residuals and
    carries one range nuisance per disc; told there is none, its sigmas are far too
    narrow."""

    def offsets(f, distance, rng):
        for i in CAT.ids:
            distance[_disc_pixels(f, i)] += rng.normal(0.0, 6.0)

    sensor = SensorModel(supersampling=32)
    base = replace(PixelNoise.from_sensor(sensor), coverage_sigma=0.0)
    (errs, covs), (errs0, covs0), measured = _measured_against_none(
        sensor,
        np.random.default_rng([49, 6]),
        3000.0,
        10,
        base,
        replace(base, disc_range_sigma_mm=0.0),
        damage=offsets,
    )
    assert 2.0 < np.median(measured) < 12.0
    assert all(_nees_per_dof(errs0, covs0, b) > 4.0 for b in BLOCKS)
    assert all(0.3 < _nees_per_dof(errs, covs, b) < 2.0 for b in BLOCKS)


def test_a_disc_with_a_range_error_of_its_own_is_found_by_deleting_it():
    """One disc's distance pixels all read 8 mm long (an error the fit, told that discs
    have no range errors of their own, absorbs into the pose's tilt). Its residuals
    stay small (RMS ~1.3 sigma), so the Fisher covariance alone is far too narrow;
    deleting each disc in turn finds the one whose deletion moves the pose beyond its
    expected move (and at times its neighbour on the same lever), and their moves widen
    the covariance to cover the error."""
    sensor = SensorModel(supersampling=32)
    noise = replace(PixelNoise.from_sensor(sensor), coverage_sigma=0.0, disc_range_sigma_mm=0.0)
    rng = np.random.default_rng([49, 25])

    def offset(f, distance, rng):
        distance[_disc_pixels(f, 7)] += 8.0

    common = {"noise": noise, "max_marker_rms_sigma": 10}
    variants = [{**common}, {**common, "disc_deletion_terms": False}]
    with_terms, without, flagged = ([], []), ([], []), []
    for T, _, fits in _rendered_fits(sensor, rng, 3000.0, 8, variants, offset):
        for out, res in zip((with_terms, without), fits, strict=True):
            out[0].append(_error(res.R, res.t_mm, T))
            out[1].append(res.covariance)
        flagged.append(fits[0].catalog_ids[fits[0].influential].tolist())
    # the damaged disc in every frame, and no other as often
    counts = {i: sum(i in f for f in flagged) for i in CAT.ids.tolist()}
    assert counts[7] == len(flagged)
    assert all(n < counts[7] for i, n in counts.items() if i != 7)
    assert all(_nees_per_dof(*without, b) > 3.0 for b in BLOCKS)
    assert all(_nees_per_dof(*with_terms, b) < 2.0 for b in BLOCKS)


def test_deleting_discs_of_frames_the_model_fits_leaves_the_covariance_near_fisher():
    """On finely rendered frames the model fits, the deletion statistics are chi-square:
    the variance factor stays near 1 and few discs are influential (the covariance is
    the Fisher one, neither widened by hand nor narrowed)."""
    sensor = SensorModel(supersampling=32)
    rng = np.random.default_rng([49, 26])
    factors, flagged, discs = [], 0, 0
    for _, _, (res,) in _rendered_fits(sensor, rng, 4000.0, 8, [{}]):
        factors.append(res.deletion_variance_factor)
        flagged += int(res.influential.sum())
        discs += len(res.influential)
    assert np.median(factors) < 1.4
    assert flagged <= 0.05 * discs + 1


def _frame_and_start(seed=5):
    sensor = SensorModel(supersampling=16)
    T = RigidTransform(rotation_from_euler_deg(2, -3, 10) @ R_FACING, np.array([0, 0, 3000.0]))
    f = render_frame(CAM, TargetScene(), T, sensor, np.random.default_rng(seed))
    return sensor, T, f


def _disc_pixels(f, catalog_id):
    return f.surface_id == 3 + int(np.flatnonzero(CAT.ids == catalog_id)[0])


def _damaged(damage: str):
    """The clean frame with disc 6 (or, ``dark``, disc 2) damaged: half occluded by an
    arm at the plate's level, a saturated glint on its rim, or wholly dark."""
    sensor, T, f = _frame_and_start()
    gray = f.gray.copy()
    disc = _disc_pixels(f, 2 if damage == "dark" else 6)
    rows, cols = np.nonzero(disc)
    if damage == "half occluded":  # an arm over the disc's left half: the plate's level
        gray[rows[cols < np.median(cols)], cols[cols < np.median(cols)]] = 6
    elif damage == "glint":  # a saturated glint on the disc's rim, 3 px wide, one side
        r0, c0 = rows.min(), cols.max()
        gray[r0 : r0 + 3, c0 - 1 : c0 + 2] = 4095
        gray[r0 + 3 : r0 + 6, c0 + 1 : c0 + 4] = 3000
    else:  # covered whole
        gray[disc] = 6
    return sensor, T, f, gray


@pytest.mark.parametrize(("damage", "disc"), [("half occluded", 6), ("glint", 6), ("dark", 2)])
def test_a_disc_the_model_does_not_explain_is_left_out_and_the_rest_hold(damage, disc):
    """The first fit names the damaged disc; fitted again without it (seven discs left)
    the pose holds, within its covariance of the truth, and says which disc it left out
    and why."""
    sensor, T, f, gray = _damaged(damage)
    res = fit_pose_to_pixels(
        gray, f.distance_mm, CAM, CAT, T.R, T.t_mm, CAT.ids, noise=PixelNoise.from_sensor(sensor)
    )
    assert res.ok, res.reason
    assert res.left_out.tolist() == [disc] and disc not in res.catalog_ids
    # the rule that named it: a dark disc's gain under the surround's noise, or its
    # residuals
    rule = ("dark", "unexplained") if damage == "dark" else ("unexplained",)
    assert any(res.left_out_reason.startswith(f"{disc} ({r}") for r in rule), res.left_out_reason
    e = np.concatenate([Rotation.from_matrix(res.R @ T.R.T).as_rotvec(), res.t_mm - T.t_mm])
    assert e @ np.linalg.solve(res.covariance, e) < 20.06  # chi2_6 at 3 sigma


@pytest.mark.parametrize(("damage", "disc"), [("half occluded", 6), ("glint", 6), ("dark", 2)])
def test_a_damaged_disc_among_four_falls_back_naming_it(damage, disc):
    """Four discs fitted: without the damaged one three would be left, too few to check
    the covariance by deleting each (``MIN_DELETION_DISCS``), so the fit falls back
    and names it."""
    sensor, T, f, gray = _damaged(damage)
    ids = [1, 3, 5, disc] if disc == 6 else [1, 2, 5, 6]
    res = fit_pose_to_pixels(
        gray, f.distance_mm, CAM, CAT, T.R, T.t_mm, ids, noise=PixelNoise.from_sensor(sensor)
    )
    assert not res.ok and len(res.left_out) == 0
    assert str(disc) in res.reason


def test_clean_frame_is_ok_and_reports_its_pixels():
    sensor, T, f = _frame_and_start()
    res = fit_pose_to_pixels(
        f.gray, f.distance_mm, CAM, CAT, T.R, T.t_mm, CAT.ids, noise=PixelNoise.from_sensor(sensor)
    )
    assert res.ok, res.reason
    assert res.covariance.shape == (6, 6)
    assert res.n_gray_pixels > 0 and res.n_distance_pixels > 0
    assert list(res.catalog_ids) == list(CAT.ids)


def test_a_frame_without_a_usable_distance_fits_on_gray_alone():
    """Every distance pixel invalid (NaN: saturated cores, a camera that gave none): no
    distance residual rows at all. The fit still runs on the gray pixels, which fix the
    pose's bearings, and says it used no distance pixel (the other renderer's saturating
    frames made the Jacobian's empty distance block fail to reshape)."""
    sensor, T, f = _frame_and_start()
    no_distance = np.full_like(f.distance_mm, np.nan)
    res = fit_pose_to_pixels(
        f.gray, no_distance, CAM, CAT, T.R, T.t_mm, CAT.ids, noise=PixelNoise.from_sensor(sensor)
    )
    assert res.n_distance_pixels == 0 and res.n_gray_pixels > 0
    assert np.degrees(np.linalg.norm(_error(res.R, res.t_mm, T)[:3])) < 0.1


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"catalog_ids": [1, 2]}, "needs 3"),
        ({"catalog_ids": [1, 2, 42]}, "not in the catalog"),
        ({"gray": np.zeros((10, 10))}, "camera's shape"),
        ({"t_mm": np.zeros(2)}, "t_mm"),
        ({"jacobian": "forward"}, "jacobian must be 'analytic' or 'central-differences'"),
    ],
)
def test_bad_inputs_are_named(kwargs, message):
    sensor, T, f = _frame_and_start()
    args = {
        "gray": f.gray,
        "distance_mm": f.distance_mm,
        "R": T.R,
        "t_mm": T.t_mm,
        "catalog_ids": CAT.ids,
    }
    args.update(kwargs)
    if message == "needs 3":
        res = fit_pose_to_pixels(camera=CAM, catalog=CAT, **args)
        assert not res.ok and message in res.reason
        return
    with pytest.raises(ValueError, match=message):
        fit_pose_to_pixels(camera=CAM, catalog=CAT, **args)


@pytest.mark.parametrize(
    "rms, expected",
    [
        ([0.7, 0.8, 2.6, 1.2], [False, False, True, False]),  # one disc unlike the rest
        ([1.9, 2.1, 2.0, 2.2], [False, False, False, False]),  # all alike: the frame's
        ([0.5, 0.6, 1.9, 0.5], [False, False, False, False]),  # within 2 sigma
        ([0.9, 3.4, 1.0, 1.1], [False, True, False, False]),  # beyond 3 sigma
    ],
)
def test_a_disc_unlike_its_siblings_is_unexplained(rms, expected):
    """A glint on a disc's rim leaves that disc's residuals well above the others': the
    rim model error is the discs' median, so the disc cannot hide in it."""
    from tofpose.stages.pixelfit.fit import PixelFitResult, _unexplained, _verdict

    res = PixelFitResult(
        ok=False,
        reason="",
        R=np.eye(3),
        t_mm=np.zeros(3),
        covariance=np.eye(6),
        catalog_ids=np.arange(1, 5),
        marker_rms_sigma=np.array(rms),
        gains=np.tile([2000.0, 0, 0, 0, 0, 0], (4, 1)),
        levels=np.full(4, 100.0),
        converged=True,
    )
    assert _unexplained(res, 3.0).tolist() == expected
    verdict = _verdict(res, 0.0, 3.0)
    assert verdict["ok"] == (not any(expected))
    for i, bad in zip(res.catalog_ids, expected, strict=True):
        assert (f" {i} (" in verdict["reason"]) == bad, verdict["reason"]


def _pipeline_frame(range_mm, seed):
    sensor = SensorModel(supersampling=16)
    rng = np.random.default_rng([49, int(range_mm), seed])
    T = _pose(rng, range_mm)
    f = render_frame(CAM, TargetScene(), T, sensor, rng)
    r = PosePipeline(CAM, CAT).process(f.gray, f.distance_mm)
    assert r.ok, r.reason
    return sensor, f, r


def _fit_pipeline_frame(sensor, f, r, **options):
    """``fit_pose_to_pixels`` on a ``_pipeline_frame`` from the pipeline's pose and matches,
    with the sensor's noise and ``options`` (jacobian, implementation)."""
    ids = [m.catalog_id for m in r.matched]
    noise = PixelNoise.from_sensor(sensor)
    return fit_pose_to_pixels(
        f.gray, f.distance_mm, CAM, CAT, r.R, r.t_mm, ids, noise=noise, **options
    )


@pytest.mark.parametrize("range_mm", [1000.0, 3000.0, 8000.0])
def test_analytic_and_numeric_jacobians_converge_to_the_same_pose(range_mm):
    """The analytic pose derivatives change the iterations' path a little (central
    differences err by up to 1e-2 of a derivative on a few rim pixels: see
    test_derivatives.py); the converged poses agree to well under their sigma, and so do
    their Fisher covariances (without the discs' deletion terms, whose variance factor
    is a statistic of the residuals: a Jacobian 1e-2 off on rim pixels moves it by a
    few per cent)."""
    for seed in range(2):
        sensor, f, r = _pipeline_frame(range_mm, seed)
        fits = [
            _fit_pipeline_frame(sensor, f, r, jacobian=jacobian, disc_deletion_terms=False)
            for jacobian in ("analytic", "central-differences")
        ]
        assert all(x.ok for x in fits), [x.reason for x in fits]
        diff = _error(fits[0].R, fits[0].t_mm, RigidTransform(fits[1].R, fits[1].t_mm))
        sigma = np.sqrt(np.diag(fits[1].covariance))
        assert np.all(np.abs(diff) < 0.05 * sigma), diff / sigma
        np.testing.assert_allclose(np.sqrt(np.diag(fits[0].covariance)), sigma, rtol=0.02)


def fit_with_every_parameter(noise_options, *, clip=True, **options):
    """``fit_pose_to_pixels`` on a 3 m pipeline frame with a common range offset (a 5 mm
    prior), the sensor's noise changed by ``noise_options`` and, with ``clip``, disc 6's
    brightest pixels clipped (censored rows); ``options`` to the fit."""
    sensor, f, r = _pipeline_frame(3000.0, 0)
    gray = f.gray.copy()
    if clip:
        bright = gray > np.percentile(gray[_disc_pixels(f, 6)], 70)
        gray[bright & _disc_pixels(f, 6)] = 4095
    return fit_pose_to_pixels(
        gray,
        f.distance_mm,
        CAM,
        CAT,
        r.R,
        r.t_mm,
        [m.catalog_id for m in r.matched],
        noise=replace(PixelNoise.from_sensor(sensor), **noise_options),
        fit_range_offset=True,
        range_offset_sigma_mm=5.0,
        **options,
    )


def test_jacobian_is_the_residuals_derivative_in_every_parameter(monkeypatch):
    """``fit._jacobian`` at an iteration of a fit with every kind of parameter (pose,
    gain terms, levels, a common range offset with its prior, each disc's own range
    error) and censored pixels, against central differences of the whitened residuals
    (``fit._residuals`` at the same sigmas): pose steps 1e-8 rad and 1e-5 mm (the
    images' derivatives are exact: test_derivatives.py), 1e-3 counts or mm for the rest
    (the gray is linear in them, the distance smooth). The reference implementation
    forms J (the compiled one its normal equations: kernels/test_normal.py)."""
    from tofpose.stages.pixelfit import fit

    seen = []
    original = fit._jacobian

    def spy(pb, s, images, pred, sig, d_images=None):
        J = original(pb, s, images, pred, sig, d_images)
        if pb.disc_range_sigma_mm > 0 and not seen:
            seen.append((pb, s, sig, J))
        return J

    monkeypatch.setattr(fit, "_jacobian", spy)
    fit_with_every_parameter(
        {"disc_range_sigma_mm": 3.0, "coverage_sigma": 0.02}, implementation="reference"
    )
    pb, s, sig, J = seen[0]
    assert len(pb.sat_rows) > 0 and pb.fit_offset
    columns = np.flatnonzero(pb.free)
    assert J.shape == (
        len(fit._residuals(pb, pb.predict(pb.images(s.R, s.t_mm), s), sig, s)),
        len(columns),
    )
    for j, col in enumerate(columns):
        h = 1e-8 if col < 3 else 1e-5 if col < 6 else 1e-3
        delta = np.zeros(pb.n_params)
        delta[col] = h
        out = []
        for sign in (1.0, -1.0):
            st = s.stepped(sign * delta, pb.layout)
            out.append(fit._residuals(pb, pb.predict(pb.images(st.R, st.t_mm), st), sig, st))
        numeric = (out[0] - out[1]) / (2 * h)
        scale = np.abs(numeric).max()
        assert scale > 0, col
        np.testing.assert_allclose(J[:, j], numeric, rtol=0, atol=1e-5 * scale, err_msg=str(col))


def test_reference_implementation_fits_the_same_pose():
    """The NumPy images and derivatives (``implementation="reference"``) and the compiled
    kernels are one arithmetic: the same iterations and the same pose to rounding."""
    sensor, f, r = _pipeline_frame(3000.0, 0)
    fits = [
        _fit_pipeline_frame(sensor, f, r, implementation=implementation)
        for implementation in ("compiled", "reference")
    ]
    assert all(x.ok for x in fits), [x.reason for x in fits]
    assert fits[0].iterations == fits[1].iterations
    diff = _error(fits[0].R, fits[0].t_mm, RigidTransform(fits[1].R, fits[1].t_mm))
    assert np.all(np.abs(diff) < 1e-6 * np.sqrt(np.diag(fits[1].covariance))), diff


def test_the_plates_edge_in_a_window_is_modelled_not_mixed_into_the_plates_level(monkeypatch):
    """At 6 m the plate's right edge crosses disc 8's window (35 mm beyond its rim, the
    window's 3 px margin is 55 mm), and beyond it is nothing. On a light plate (0.9, its
    level ~55 counts) the surround's two parts (``_plate_surround``) fit disc 8's plate
    level as its siblings' (within 15 % of their median) and the fit lands within its
    sigmas on every seed; with one level per window (the plate's fraction held at 1)
    disc 8's is pulled halfway to the dark beyond (the other renderer's frames: its
    residuals beyond its siblings', and the fit fell back on 46 of 96 frames)."""
    from tofpose.stages.pixelfit import fit

    sensor = SensorModel(supersampling=16)
    scene = TargetScene(wall_distance_mm=None, plate_reflectance=0.9)
    T = RigidTransform(rotation_from_euler_deg(3, -4, 8) @ R_FACING, np.array([-300, 200, 6000.0]))
    frames = [render_frame(CAM, scene, T, sensor, np.random.default_rng(s)) for s in range(3)]

    def disc_8_level_over_median(f):
        r = PosePipeline(CAM, CAT).process(f.gray, f.distance_mm)
        assert r.ok and [m.catalog_id for m in r.matched][-1] == 8, r.reason
        res = _fit_pipeline_frame(sensor, f, r)
        assert res.ok, res.reason
        return res, res.levels[-1] / np.median(res.levels)

    for f in frames:
        res, ratio = disc_8_level_over_median(f)
        assert abs(ratio - 1) < 0.15, res.levels
        e = _error(res.R, res.t_mm, T)
        assert e @ np.linalg.solve(res.covariance, e) < 20.06  # chi2_6 at 0.9973
    original = fit._plate_surround

    def one_level(win, images, saturated, k_count):
        plate, _, _ = original(win, images, saturated, k_count)
        assert np.any(plate == 0)  # the edge is in a window, and pixels beyond it
        return np.ones(win.n_pixels), np.zeros(win.n_pixels), np.zeros(k_count)

    monkeypatch.setattr(fit, "_plate_surround", one_level)
    for f in frames:
        assert disc_8_level_over_median(f)[1] < 0.6


def test_a_glint_in_a_discs_window_is_left_out_and_the_fit_holds():
    """A marker-like glint (a Gaussian spot of 0.7 px sigma, 600 counts) 4.5 px beyond
    disc 6's rim, diagonally, in its window: its pixels are left out
    (``n_glint_pixels``) and the fit lands within its sigmas; the same spot 1.5 px
    beyond the rim lights the rim too, is not left out as a glint (the model's own error
    next to a disc is to be seen, not left out), so the first fit names the disc, and the
    fit holds without it (``left_out``)."""
    sensor, T, f = _frame_and_start()
    disc = _disc_pixels(f, 6)
    rows, cols = np.nonzero(disc)
    centre = np.array([rows.mean(), cols.mean()])
    radius = (cols.max() - cols.min() + 1) / 2
    vv, uu = np.mgrid[0 : CAM.height, 0 : CAM.width]
    noise = PixelNoise.from_sensor(sensor)
    for beyond_rim_px, holds in ((4.5, True), (1.5, False)):
        d = (radius + beyond_rim_px) / np.sqrt(2)
        r2 = (vv - centre[0] - d) ** 2 + (uu - centre[1] - d) ** 2
        gray = np.minimum(f.gray + 600.0 * np.exp(-r2 / (2 * 0.7**2)), 4095)
        res = fit_pose_to_pixels(gray, f.distance_mm, CAM, CAT, T.R, T.t_mm, CAT.ids, noise=noise)
        assert res.ok, res.reason
        e = _error(res.R, res.t_mm, T)
        assert e @ np.linalg.solve(res.covariance, e) < 20.06
        if holds:
            assert res.n_glint_pixels >= 3 and len(res.left_out) == 0
        else:
            assert res.n_glint_pixels == 0 and res.left_out.tolist() == [6]
            assert res.left_out_reason.startswith("6 (unexplained"), res.left_out_reason


def test_a_solve_whose_measured_range_noise_cycles_ends_at_the_truth():
    # at 13 m (seed 2) the distance noise constant, measured again at each iteration on
    # the residuals' median, and the state alternated between two values until the
    # iteration limit ("not converged in 34 iterations"); held after
    # NOISE_FREEZE_ITERATIONS, the solve ends where the frame puts the pose
    rng = np.random.default_rng(2)
    T = RigidTransform(rotation_from_euler_deg(2, -3, 10) @ R_FACING, np.array([0, -30, 13000.0]))
    f = render_frame(CAM, TargetScene(), T, SensorModel(), rng)
    res = PosePipeline(CAM, CAT).process(f.gray, f.distance_mm)
    assert res.ok
    fit = fit_pose_to_pixels(
        f.gray, f.distance_mm, CAM, CAT, res.R, res.t_mm, [m.catalog_id for m in res.matched]
    )
    assert fit.converged and fit.ok, fit.reason
    assert fit.iterations < 2 * MAX_ITERATIONS
    err = _error(fit.R, fit.t_mm, T)
    assert err @ np.linalg.solve(fit.covariance, err) < 22.5  # chi-square(6), 0.999


def test_a_held_noise_constant_is_the_one_the_fit_reports_in_both_arithmetics(monkeypatch):
    # at 11 m (seed 5) the last solve runs past NOISE_FREEZE_ITERATIONS and holds the
    # distance's noise constant; the information is with it, so the disc-deletion
    # check's shares, the residuals, the verdict and the reported constant must be too
    # (they had measured it again at the last state), in the NumPy arithmetic as in the
    # kernels
    held = []
    solve = fit_module._levenberg_marquardt

    def spy(*args):
        solved = solve(*args)
        held.append(solved.held_range_k_mm)
        return solved

    monkeypatch.setattr(fit_module, "_levenberg_marquardt", spy)
    rng = np.random.default_rng(5)
    T = RigidTransform(rotation_from_euler_deg(2, -3, 10) @ R_FACING, np.array([0, -30, 11000.0]))
    f = render_frame(CAM, TargetScene(), T, SensorModel(), rng)
    res = PosePipeline(CAM, CAT).process(f.gray, f.distance_mm)
    ids = [m.catalog_id for m in res.matched]
    fits = [
        fit_pose_to_pixels(
            f.gray, f.distance_mm, CAM, CAT, res.R, res.t_mm, ids, implementation=implementation
        )
        for implementation in ("compiled", "reference")
    ]
    assert all(x.ok for x in fits), [x.reason for x in fits]
    assert fits[0].iterations == fits[1].iterations
    last_solves = held[len(held) // 2 - 1], held[-1]  # each fit's last solve
    for fit, k in zip(fits, last_solves, strict=True):
        assert k is not None and fit.range_k_mm == k
    assert fits[1].range_k_mm == pytest.approx(fits[0].range_k_mm, rel=1e-9)
    np.testing.assert_array_equal(fits[1].influential, fits[0].influential)
    assert fits[1].deletion_variance_factor == pytest.approx(
        fits[0].deletion_variance_factor, rel=1e-6
    )
    np.testing.assert_allclose(fits[1].covariance, fits[0].covariance, rtol=1e-6, atol=1e-12)
