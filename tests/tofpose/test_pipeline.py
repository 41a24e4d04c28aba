import numpy as np
import pytest

from tests.conftest import facing_pose, render
from tofpose import CameraModel, PipelineConfig, PosePipeline, paper_target
from tofpose.calibration.covariance import pose_nees
from tofpose.core.geometry import RigidTransform, rotation_angle_deg
from tofpose.sim.scene import Clutter, TargetScene
from tofpose.stages.extraction.extraction import FrameError

# (distance mm, (pitch, yaw, roll) deg, offset mm, median position error mm, median angle
# deg, per-frame maxima mm / deg). The bounds are about twice what the pipeline measured
# over these six seeded frames (medians 0.50/0.20/0.14/0.62/0.61/2.3/3.9/6.7 mm and
# 0.23/0.037/0.033/0.043/0.14/0.45/1.5/2.8 deg from 0.5 to 12 m): a regression that
# doubles the error fails here. The common range offset is estimated (the default); on
# this simulator, which has none, that costs position where the image scale carries a
# centroid bias common to the markers into the offset: at 3 m 0.62 mm median (0.24 mm
# while the focal length was given a 0.2 % prior for every camera, which kept the
# offset near its zero prior; the camera states its intrinsics exact now). At 8 m,
# where the image scale hardly fixes the distance, the offset's 15 mm prior (round 5;
# 8 mm before) lets its estimate carry the scale's noise into the range: 2.3 mm median
# (max 4.1) against 1.1 (2.3),
# inside the 40 mm a pose there may be off, for the 10-25 mm of a real camera's offset
# it takes out at 2-5 m.
RANGE_CASES = [
    (500.0, (2, -3, 5), (220.0, -90.0), 1.1, 0.5, 1.5, 0.7),  # markers 1, 2, 4 fit at 0.5 m
    (700.0, (3, 2, -10), (0.0, 0.0), 0.4, 0.08, 0.5, 0.11),
    (1500.0, (5, -4, 10), (30.0, -40.0), 0.45, 0.08, 0.55, 0.1),
    (3000.0, (-6, 8, 30), (0.0, 0.0), 1.2, 0.14, 1.6, 0.2),
    (5712.0, (4, 1, -2), (5.0, -2.0), 1.2, 0.3, 1.5, 0.45),
    (8000.0, (2, -3, 15), (0.0, 0.0), 5.0, 0.95, 9.0, 1.75),
    # at 10 m annealing often returns a mirror assignment; the triplet fallback fixes it
    (10000.0, (2, -3, 10), (0.0, 0.0), 8.0, 3.0, 11.0, 4.9),
    (12000.0, (2, 2, -20), (0.0, 0.0), 14.0, 5.8, 17.0, 7.0),
]


@pytest.mark.parametrize(
    ("z", "angles", "offset", "pos_med", "ang_med", "pos_max", "ang_max"), RANGE_CASES
)
def test_end_to_end_pose_over_the_operating_range(
    z, angles, offset, pos_med, ang_med, pos_max, ang_max
):
    cam, cat = CameraModel(), paper_target()
    T = facing_pose(z, *angles, offset_mm=offset)
    pipe = PosePipeline(cam, cat)
    results = [
        pipe.process(*(lambda f: (f.gray, f.distance_mm))(render(T, seed=s)), s / 30)
        for s in range(6)
    ]
    ok = [r for r in results if r.ok]
    assert len(ok) == 6, [r.reason for r in results if not r.ok]
    pos = [np.linalg.norm(r.t_mm - T.t_mm) for r in ok]
    ang = [rotation_angle_deg(r.R, T.R) for r in ok]
    assert np.median(pos) < pos_med and np.median(ang) < ang_med, (pos, ang)
    assert max(pos) < pos_max and max(ang) < ang_max, (pos, ang)
    for r in ok:
        assert r.n_matched >= 3 and np.isfinite(r.residual_mm)
        stages = {"levels", "blobs", "measurement", "matching", "refine", "total"}
        assert set(r.timings_ms) >= stages
        assert r.covariance is not None and np.all(np.linalg.eigvalsh(r.covariance) > 0)


def test_matched_ids_are_the_true_reflectors():
    cam, cat = CameraModel(), paper_target()
    T = facing_pose(2500.0, 3, -2, 40)
    r = PosePipeline(cam, cat).process(render(T).gray, render(T).distance_mm)
    uv_true = dict(zip(cat.ids, cam.project(T.apply(cat.positions_mm)), strict=True))
    assert r.ok and r.n_matched == 8
    for m in r.matched:
        assert np.linalg.norm(m.centroid_uv - uv_true[m.catalog_id]) < 0.3


@pytest.mark.parametrize("refinement", ["ml", "los", "none"])
def test_every_refinement_mode_gives_the_pose(refinement):
    T = facing_pose(2000.0, 4, 3, -8)
    f = render(T, seed=3)
    r = PosePipeline(CameraModel(), paper_target(), PipelineConfig(refinement=refinement)).process(
        f.gray, f.distance_mm
    )
    assert r.ok
    assert np.linalg.norm(r.t_mm - T.t_mm) < 2.0 and rotation_angle_deg(r.R, T.R) < 0.7
    if refinement == "los":
        assert r.iterations >= 1


def test_the_svd_pose_before_refinement_is_reported_beside_the_refined_one():
    """``R_svd``/``t_svd_mm`` are Eqs. 40-50 on the matched reflectors: with no
    refinement (and no range offset estimated, which would move the ranges) they are the
    reported pose itself; with the ML refinement a different, nearby pose, in acquisition
    and tracking alike."""
    T = facing_pose(3000.0, 4, -3, 12)
    cam, cat = CameraModel(), paper_target()
    plain = PipelineConfig(refinement="none", estimate_range_offset=False)
    f = render(T, seed=5)
    r = PosePipeline(cam, cat, plain).process(f.gray, f.distance_mm)
    assert r.ok
    np.testing.assert_allclose(r.R_svd, r.R, atol=1e-12)
    np.testing.assert_allclose(r.t_svd_mm, r.t_mm, atol=1e-9)
    from tofpose.config import TrackingConfig

    pipe = PosePipeline(cam, cat, PipelineConfig(tracking=TrackingConfig(enabled=True)))
    for seed, mode in ((5, "acquisition"), (6, "tracking")):
        f = render(T, seed=seed)
        r = pipe.process(f.gray, f.distance_mm)
        assert r.ok and r.mode == mode
        moved_deg = rotation_angle_deg(r.R_svd, r.R)
        assert 1e-6 < moved_deg < 0.5, moved_deg
        assert rotation_angle_deg(r.R_svd, T.R) < 0.7
        assert 1e-6 < np.linalg.norm(r.t_svd_mm - r.t_mm) < 5.0


def test_refinement_modes_compared_on_the_same_frames():
    """Ten frames at 2 m: weighted SVD alone is dominated by range noise (measured median
    0.26 mm / 0.11 deg); both refinements cut its attitude error by more than half and its
    position error by at least a fifth (ML 0.18 mm / 0.044 deg, the paper's LOS
    0.09 mm / 0.037 deg: ML also estimates a common range offset this simulator does not
    have, from the image scale, which costs it a little position here); ML and LOS agree
    with each other within 0.03 deg."""
    cam, cat = CameraModel(), paper_target()
    T = facing_pose(2000.0, 4, 3, -8)
    frames = [render(T, seed=s) for s in range(10)]
    err = {}
    for mode in ("ml", "los", "none"):
        pipe = PosePipeline(cam, cat, PipelineConfig(refinement=mode))
        rs = []
        for f in frames:
            pipe.reset()
            rs.append(pipe.process(f.gray, f.distance_mm))
        assert all(r.ok for r in rs)
        err[mode] = (
            np.median([np.linalg.norm(r.t_mm - T.t_mm) for r in rs]),
            np.median([rotation_angle_deg(r.R, T.R) for r in rs]),
            [r.R for r in rs],
        )
    for mode in ("ml", "los"):
        assert err[mode][1] < 0.5 * err["none"][1], err
        assert err[mode][0] < 0.8 * err["none"][0], err
    gap = [rotation_angle_deg(a, b) for a, b in zip(err["ml"][2], err["los"][2], strict=True)]
    assert np.median(gap) < 0.03


def test_paper_preset_runs_on_the_paper_scene():
    T = facing_pose(697.0, 0, 0, 0, offset_mm=(2.0, -10.0))
    pipe = PosePipeline(CameraModel(), paper_target(), PipelineConfig.paper())
    f = render(T, seed=0)
    r = pipe.process(f.gray, f.distance_mm)
    assert r.ok, r.reason
    assert np.linalg.norm(r.t_mm - T.t_mm) < 5.0


def test_spurious_bright_blobs_do_not_change_the_answer():
    clutter = (
        Clutter((250.0, 180.0, 20.0), 60.0, 1.2),
        Clutter((-420.0, -230.0, 10.0), 40.0, 0.8),
        Clutter((0.0, 0.0, 5.0), 50.0, 1.0),
    )
    T = facing_pose(2500.0, 2, -3, 12)
    scene = TargetScene(clutter=clutter)
    pipe = PosePipeline(CameraModel(), paper_target())
    f = render(T, seed=1, scene=scene)
    r = pipe.process(f.gray, f.distance_mm)
    assert r.ok and r.n_matched >= 6 and len(r.unmatched) >= 2
    assert np.linalg.norm(r.t_mm - T.t_mm) < 2.0


def test_jumping_scene_is_never_reported_stale():
    """A recording jumping between poses: each frame right (or refused), never the old pose."""
    cam, cat = CameraModel(), paper_target()
    pipe = PosePipeline(cam, cat)
    poses = [
        facing_pose(2000.0, 0, 0, 0),
        facing_pose(2000.0, 0, 0, 25),
        facing_pose(2600.0, 3, -4, -10),
    ]
    seq = [0, 0, 0, 0, 1, 1, 2, 0, 2]
    for n, k in enumerate(seq):
        f = render(poses[k], seed=n)
        r = pipe.process(f.gray, f.distance_mm, n / 30)
        if r.ok:
            assert rotation_angle_deg(r.R, poses[k].R) < 0.3, f"frame {n}"
            assert np.linalg.norm(r.t_mm - poses[k].t_mm) < 3.0, f"frame {n}"
        else:
            assert r.reason
        if n > 0 and seq[n] != seq[n - 1]:
            assert r.frames_used == 1 and r.motion


def test_slewing_roll_axis_tracks_each_frame():
    """Roll slewing 0.5 deg per frame: persistence must not lag the estimate."""
    cam, cat = CameraModel(), paper_target()
    pipe = PosePipeline(cam, cat)
    for n in range(10):
        T = facing_pose(1800.0, 0, 0, 0.5 * n)
        f = render(T, seed=n)
        r = pipe.process(f.gray, f.distance_mm)
        assert r.ok
        assert rotation_angle_deg(r.R, T.R) < 0.15


def test_bad_frames_give_errors_or_reasons():
    pipe = PosePipeline(CameraModel(), paper_target())
    with pytest.raises(FrameError, match="gray image has shape"):
        pipe.process(np.zeros((10, 10), np.uint16), np.zeros((240, 320), np.float32))
    with pytest.raises(FrameError, match="float mm"):
        pipe.process(np.zeros((240, 320), np.uint16), np.zeros((240, 320), np.uint16))
    dark = pipe.process(np.full((240, 320), 3, np.uint16), np.full((240, 320), np.nan, np.float32))
    assert not dark.ok and "all-dark" in dark.reason
    sat = pipe.process(
        np.full((240, 320), 4095, np.uint16), np.full((240, 320), np.nan, np.float32)
    )
    assert not sat.ok and "saturated" in sat.reason
    f = render(facing_pose(2000.0), seed=0)
    d = f.distance_mm.copy()
    d[:, ::2] = np.inf
    d[::3] = np.nan
    r = pipe.process(f.gray, d)
    # half the columns and a third of the rows without a range: every blob still has
    # valid pixels, so the pose is found and right
    assert r.ok, r.reason
    assert r.n_matched == 8 and np.linalg.norm(r.t_mm - facing_pose(2000.0).t_mm) < 1.0
    # With history, the temporal median (§3.4) may fill ranges from consistent recent
    # frames; a fresh pipeline has nothing to fall back on.
    pipe.reset()
    nodist = pipe.process(f.gray, np.full((240, 320), np.nan, np.float32))
    assert not nodist.ok and "valid range" in nodist.reason


def test_ransac_matcher_recovers_the_pose_with_clutter():
    """The benchmark alternative (random triplets within a time budget) works on a
    cluttered frame, and reports which blobs it left unmatched."""
    from tofpose.pipeline import PipelineConfig
    from tofpose.sim.scenarios import get_scenario, make_bench

    sc = get_scenario("clutter")
    bench = make_bench(sc, seed=4)
    bf = bench.capture(0.0)
    # the budget is wall-clock: with a cold numba cache (after `make kernels-clean`) the
    # first call compiles the hypothesis kernel inside it (`tofpose warm-up` does that
    # after installing), so the same frame goes once through RANSAC without a budget
    unbudgeted = PipelineConfig(
        matcher="ransac", ransac_time_budget_ms=None, ransac_confidence=0.99
    )
    assert (
        PosePipeline(CameraModel(), paper_target(), unbudgeted)
        .process(bf.frame.gray, bf.frame.distance_mm)
        .ok
    )
    cfg = PipelineConfig(matcher="ransac", ransac_time_budget_ms=200.0)
    res = PosePipeline(CameraModel(), paper_target(), cfg).process(
        bf.frame.gray, bf.frame.distance_mm
    )
    assert res.ok, res.reason
    assert np.linalg.norm(res.t_mm - bf.T_true.t_mm) < 10.0
    assert len(res.unmatched) >= 1


def test_covered_markers_do_not_veto_a_well_determined_pose():
    """Two markers covered (in view, dark): six matches still give the pose; the dark-marker
    check only guards poses from few matches."""
    from tofpose.core.catalog import Catalog

    cat = paper_target()
    covered = Catalog(cat.name, tuple(r for r in cat.reflectors if r.id not in (3, 6)))
    T = facing_pose(3000.0, pitch_deg=2.0, yaw_deg=-3.0)
    f = render(T, seed=5, scene=TargetScene(covered))
    res = PosePipeline(CameraModel(), cat).process(f.gray, f.distance_mm)
    assert res.ok, res.reason
    assert sorted(m.catalog_id for m in res.matched) == [1, 2, 4, 5, 7, 8]
    assert np.linalg.norm(res.t_mm - T.t_mm) < 2.0
    strict = PipelineConfig(dark_check_max_matches=8)
    pipe = PosePipeline(CameraModel(), cat, strict)
    refused = pipe.process(f.gray, f.distance_mm)
    assert not refused.ok and "dark" in refused.reason
    # the compiled check (stages.pose.kernels.verify.pose_check) against the rule written out over
    # the whole thresholded frame
    from tofpose.core.geometry import RigidTransform
    from tofpose.stages.pose.solve import ThresholdedFrame

    g = f.gray.astype(np.float32)
    matched = {int(np.flatnonzero(cat.ids == i)[0]) for i in (1, 2, 4, 5, 7, 8)}
    verdict = pipe._solver.verify(
        RigidTransform(res.R, res.t_mm), ThresholdedFrame(g, 400.0), np.array(sorted(matched))
    )
    assert verdict == _dark_reflector_reference(res.R, res.t_mm, cat, matched, g >= 400.0)
    assert "reflector 3 should be visible" in verdict


def _dark_reflector_reference(R, t, cat, matched, active):
    """The dark-marker rule of ``PoseSolver.verify`` in NumPy over a whole active mask."""
    cam = CameraModel()
    centres = cat.positions_mm @ R.T + t
    uv = cam.project(centres)
    d_px = cam.fx * cat.diameters_mm / centres[:, 2]
    h, w = active.shape
    for i in range(len(centres)):
        if i in matched or d_px[i] < 2.5:
            continue
        u, v = uv[i]
        m = 0.75 * d_px[i] + 2
        if not (m <= u < w - m and m <= v < h - m):
            continue
        sep = np.linalg.norm(uv - uv[i], axis=1)
        sep[i] = np.inf
        if np.min(sep) < 1.5 * d_px[i]:
            continue
        r = max(1, int(round(d_px[i] / 3)))
        iu, iv = int(round(u)), int(round(v))
        if not active[iv - r : iv + r + 1, iu - r : iu + r + 1].any():
            return (
                f"reflector {int(cat.ids[i])} should be visible at ({u:.0f}, {v:.0f}) px "
                "but the frame is dark there"
            )
    return ""


def test_ten_metres_gives_a_pose_on_almost_every_frame():
    """At 10 m the 35 mm markers light 1-2 pixels and markers 7 and 8 merge into one
    blob; the pose must still come from the small markers (these used to be rejected for
    the 'eccentricity' of two pixels side by side, failing a third of the frames)."""
    cam, cat = CameraModel(), paper_target()
    pipe = PosePipeline(cam, cat)
    rng = np.random.default_rng(5)
    n_ok = 0
    for s in range(12):
        T = facing_pose(10000.0, *rng.uniform(-5, 5, 3))
        pipe.reset()
        r = pipe.process(*(lambda f: (f.gray, f.distance_mm))(render(T, seed=s)))
        if r.ok:
            n_ok += 1
            assert np.linalg.norm(r.t_mm - T.t_mm) < 25.0
            assert rotation_angle_deg(r.R, T.R) < 6.0
    assert n_ok >= 11


@pytest.mark.parametrize(
    ("reject", "consistency_p", "expect_good"),
    [(True, 1 - 1e-6, True), (False, 1 - 1e-6, True), (False, None, False)],
)
def test_a_reflection_beside_a_marker_is_dropped_not_fitted(reject, consistency_p, expect_good):
    """An 80 mm bright disc 60 mm in front of marker 6 and 20 mm to its side passes the
    matching tolerance in its place; fitted, it bends the pose. The outlier step
    (residual > 6 predicted sigmas) drops it and keeps the others. Without that step the
    fit with it is refused by the acceptance test (a misfit no noise can produce) and the
    triplet fallback finds the consistent match without it; with neither, the bent pose
    is reported."""
    T = facing_pose(3000.0, 2, -3, 12)
    scene = TargetScene(clutter=(Clutter((120.0, 60.0, 210.0), 80.0, 1.0),))
    f = render(T, seed=1, scene=scene)
    config = PipelineConfig(reject_outliers=reject, consistency_p=consistency_p)
    r = PosePipeline(CameraModel(), paper_target(), config).process(f.gray, f.distance_mm)
    assert r.ok
    good = np.linalg.norm(r.t_mm - T.t_mm) < 2.0 and rotation_angle_deg(r.R, T.R) < 0.3
    assert good == expect_good, (np.linalg.norm(r.t_mm - T.t_mm), rotation_angle_deg(r.R, T.R))
    if expect_good:
        assert max(m.residual_mm for m in r.matched) < 3.0
    if reject:  # the outlier step dropped the reflection matched as marker 6
        assert 6 not in [m.catalog_id for m in r.matched]


@pytest.mark.parametrize("visible", [(1, 2, 3, 4), (1, 4, 6, 8), (2, 5, 6, 7)])
def test_half_the_target_covered_still_gives_the_right_pose(visible):
    """Four of eight markers covered: four matches are not ambiguous (a mirror assignment
    of a nearly planar pattern needs the target to face away, which verification
    refuses), so the dark predicted markers are taken as occluded."""
    from tofpose.core.catalog import Catalog

    cat = paper_target()
    scene = TargetScene(Catalog(cat.name, tuple(r for r in cat.reflectors if r.id in visible)))
    T = facing_pose(3000.0, pitch_deg=3.0, yaw_deg=-2.0, roll_deg=8.0)
    res = PosePipeline(CameraModel(), cat).process(
        *(lambda f: (f.gray, f.distance_mm))(render(T, seed=2, scene=scene))
    )
    assert res.ok, res.reason
    assert sorted(m.catalog_id for m in res.matched) == list(visible)
    assert np.linalg.norm(res.t_mm - T.t_mm) < 3.0
    assert rotation_angle_deg(res.R, T.R) < 0.5


def test_an_inconsistent_fit_reports_an_uncertainty_that_covers_its_error():
    """With the outlier step off, the reflection beside marker 6 bends the pose by ~30 mm.
    (J^T J)^-1 alone would claim < 1 mm; scaled by chi^2/dof the reported 1-sigma covers
    the error within a few sigma. A consistent fit is not inflated."""
    from tofpose.pipeline import variance_factor

    assert variance_factor(14.0, 8) == 1.0 and variance_factor(90.0, 8) == 5.0
    assert variance_factor(10.0, 2) == 1.0  # no redundancy, nothing to judge by
    T = facing_pose(3000.0, 2, -3, 12)
    scene = TargetScene(clutter=(Clutter((120.0, 60.0, 210.0), 80.0, 1.0),))
    f = render(T, seed=1, scene=scene)
    # the acceptance test off too: it refuses this fit (tested above)
    config = PipelineConfig(reject_outliers=False, consistency_p=None)
    r = PosePipeline(CameraModel(), paper_target(), config).process(f.gray, f.distance_mm)
    err_mm = np.linalg.norm(r.t_mm - T.t_mm)
    sigma_mm = np.sqrt(np.trace(r.covariance[3:, 3:]))
    assert err_mm > 10.0 and err_mm / sigma_mm < 5.0


@pytest.mark.parametrize(("chi2_per_dof", "expect_biased"), [(4.0, False), (1e9, True)])
def test_a_biased_blob_absorbed_by_the_fit_is_found_by_leave_one_out(chi2_per_dof, expect_biased):
    """At 15 m in bright light markers 7 and 8 sometimes merge into one blob, matched to
    one of them with its centroid ~1 px off. With 5+ matches the fit absorbs the error
    (no point > 6 sigma), but chi^2 is high; predicting each point from the others finds
    it. Frames 0-29 of this seed include such cases (the check off: disabled by a huge
    chi^2 threshold)."""
    from dataclasses import replace

    from bench.accuracy import random_pose
    from tofpose.sim.render import SensorModel, render_frame

    cam, cat = CameraModel(), paper_target()
    # the acceptance test off: it would refuse some of these fits itself
    config = PipelineConfig(outlier_chi2_per_dof=chi2_per_dof, consistency_p=None)
    pipe = PosePipeline(cam, cat, config)
    ids, scene = list(cat.ids), TargetScene(cat)
    sensor = replace(SensorModel(), ambient_lux=10000.0)
    rng = np.random.default_rng([5, 10000])
    biased = 0
    for _ in range(30):
        T = random_pose(15.0, rng)
        f = render_frame(cam, scene, T, sensor, rng)
        pipe.reset()
        r = pipe.process(f.gray, f.distance_mm)
        if not r.ok or r.n_matched < 5:
            continue
        proj = cam.project(T.apply(cat.positions_mm))
        biased += any(
            np.linalg.norm(m.centroid_uv - proj[ids.index(m.catalog_id)]) > 0.5 for m in r.matched
        )
    assert (biased > 0) == expect_biased


@pytest.mark.parametrize("diameter_mm", [5.0, 20.0])
def test_a_catalog_the_camera_cannot_see_says_so(diameter_mm):
    """Paper target in view, but a catalog of much smaller markers active: the reason
    names the bright blobs that do not have the catalog's size, not just '0 candidates'."""
    from tofpose.core.catalog import Catalog, Reflector

    scene_cat = paper_target()
    tiny = Catalog(
        "tiny",
        tuple(Reflector(r.id, r.position_mm, diameter_mm) for r in scene_cat.reflectors),
    )
    frame = render(facing_pose(2000.0, 2, -3, 5))
    r = PosePipeline(CameraModel(), tiny).process(frame.gray, frame.distance_mm, 0.0)
    assert not r.ok
    assert "do not have a size the catalog 'tiny' predicts" in r.reason, r.reason
    assert "is the right catalog active?" in r.reason and "unambiguous" not in r.reason
    n = int(r.reason.split("; ")[1].split()[0])
    assert n >= 4  # the 80 mm markers at least; each one is refused for its size


def test_markers_7_and_8_merged_into_one_blob_are_split_and_both_matched():
    """At 5.5 m markers 7 and 8 (80 mm, 90 mm apart) image as one component too long for
    one reflector, whose few-pixel outline gives no elliptical arcs; thresholding it again
    at rising levels splits it into the two markers' cores (ours, after §3.3)."""
    T = facing_pose(5500.0, 1.0, -2.0, 3.0)
    f = render(T, seed=3)
    cam = CameraModel()
    p7, p8 = cam.project(paper_target().positions_mm[6:8] @ T.R.T + T.t_mm)
    assert np.linalg.norm(p7 - p8) < 8.0  # they do touch in the image
    r = PosePipeline(cam, paper_target()).process(f.gray, f.distance_mm)
    assert r.ok, r.reason
    assert sorted(m.catalog_id for m in r.matched) == list(range(1, 9))
    assert any(b.reason == "oversize" for b in r.rejected)  # the merged component
    for m in r.matched:
        if m.catalog_id in (7, 8):
            truth = (p7, p8)[m.catalog_id - 7]
            assert np.linalg.norm(m.centroid_uv - truth) < 0.6
    assert np.linalg.norm(r.t_mm - T.t_mm) < 5.0 and rotation_angle_deg(r.R, T.R) < 0.6
    # and the reported covariance holds it: inside chi2_6's 3-sigma quantile (20.06)
    from tofpose.calibration.covariance import pose_nees

    assert pose_nees(r.R, r.t_mm, r.covariance, T.R, T.t_mm) < 20.06


@pytest.mark.parametrize("corrected", [False, True], ids=["plain", "range-corrected"])
def test_the_compiled_measurement_is_the_reference_statement(corrected):
    """``_measure`` (one compiled call: persistence, centroids, ranges, the range
    correction, back-projection, sigmas and weights, then the pipeline's records of
    them) against the same method of a pipeline of the reference statement
    (``stages.persistence.reference.measure``: the history's combination, Eqs. 19-20,
    the correction as ``RangeCorrection.error_mm`` defines it, the reference sigmas,
    Eq. 8 by OpenCV's camera and Eq. 21), each pipeline with its own history, on the
    same blobs of a stream whose history builds up, with the split halves of the
    merged markers 7 and 8 at 8 m: the same blobs kept, ranged and combined, centroids
    to 1e-9 px, ranges, sigmas, points and weights to 1e-12 relative (float64 sums and
    medians taken in another order), the mixing sums to 1e-12 relative or 1e-6."""
    from tofpose.calibration.range import RangeCorrection
    from tofpose.pipeline import _Timer
    from tofpose.sim.render import SensorModel
    from tofpose.stages.extraction.extraction import check_frame, frame_levels

    cam, cat = CameraModel(), paper_target()
    correction = (
        RangeCorrection(
            SensorModel().unambiguous_range_mm,
            offset_mm=3.0,
            harmonics_mm=((2.0, -1.5),),
            amplitude_mm_per_decade=1.5,
            pixel_offsets_mm=np.random.default_rng(7).normal(0.0, 2.0, cam.shape),
        )
        if corrected
        else None
    )
    compiled = PosePipeline(cam, cat, range_correction=correction)
    reference = PosePipeline(cam, cat, range_correction=correction, implementation="reference")
    sources = set()
    with_sums = combined = 0
    poses = [facing_pose(8000.0, 2, -3, 10)] * 4 + [facing_pose(1500.0, 3, 2, -5)] * 3
    for k, T in enumerate(poses):
        f = render(T, seed=k)
        g, d = check_frame(cam, f.gray, f.distance_mm)
        found, blobs = compiled._candidates(
            g, d, frame_levels(g, compiled.config.extraction), _Timer()
        )
        sources |= {b.source for b in blobs}
        bg, dark = found.stats.background, found.stats.dark_level
        meas, unranged, n_kept, info = compiled._measure(blobs, g, d, bg, dark)
        want, want_unranged, want_kept, want_info = reference._measure(blobs, g, d, bg, dark)
        assert (n_kept, info) == (want_kept, want_info)
        combined = max(combined, info.frames_used)
        assert all(b is r for b, r in zip(meas.blobs, want.blobs, strict=True))
        np.testing.assert_allclose(
            np.reshape(unranged, (-1, 3)), np.reshape(want_unranged, (-1, 3)), rtol=0, atol=1e-9
        )
        np.testing.assert_array_equal(meas.area_px, want.area_px)
        np.testing.assert_allclose(meas.uv_px, want.uv_px, rtol=0, atol=1e-9)
        for name in ("range_mm", "y_mm", "weights", "sigma_px", "sigma_range_mm"):
            got_v, want_v = getattr(meas, name), getattr(want, name)
            np.testing.assert_allclose(got_v, want_v, rtol=1e-12, atol=1e-12, err_msg=name)
        np.testing.assert_allclose(meas.mixing, want.mixing, rtol=1e-12, atol=1e-6)
        with_sums += int(np.isfinite(meas.mixing[:, :6]).all(axis=1).sum())
    assert "split" in sources
    assert combined == 4  # the four frames at 8 m combined
    assert with_sums > 0  # blobs whose surround has a range (the plate at 1.5 m) have sums


def test_two_markers_imaged_as_one_blob_do_not_push_good_ones_out_of_the_fit():
    """At 7.9 m, tilted 19 deg, markers 7 and 8 image 2.5 px apart as one 18 px blob,
    matched as marker 8 with its centroid 1.2 px off and its range 27 mm long. Its sigma
    is that of a bright disc, so it drags the fit towards itself and the 80 mm markers 5
    and 6 get the large residuals: the outlier step used to drop them, leaving a pose 4
    deg off whose covariance put it beyond 19 sigma (seeds 5 and 8). A fit without each
    reflector shows which one is biased."""
    from tofpose.sim.render import SensorModel, render_frame

    R = np.array(
        [
            [0.9443705985205454, -0.11765043327753799, -0.3071197619814697],
            [-0.06575149816011774, -0.9825131901121944, 0.17419693379982082],
            [-0.32224356182807906, -0.14431287816812022, -0.9355922616477684],
        ]
    )
    T = RigidTransform(R, np.array([-1451.7402105090484, -84.59967201244098, 7866.720616412314]))
    cam, cat = CameraModel(), paper_target()
    pipe = PosePipeline(cam, cat)
    for seed in (5, 8, 0, 1):
        f = render_frame(cam, TargetScene(cat), T, SensorModel(), np.random.default_rng(seed))
        pipe.reset()
        r = pipe.process(f.gray, f.distance_mm)
        assert r.ok, r.reason
        assert {5, 6} <= {m.catalog_id for m in r.matched}, seed
        assert rotation_angle_deg(r.R, T.R) < 1.0, seed


def _glinty_frame(seed):
    """The paper target at 4-7 m with 25 small bright discs scattered over and around its
    image, 0-200 mm in front of its plate (marker-like clutter): (frame, true pose)."""
    from tofpose.core.geometry import rotation_from_euler_deg
    from tofpose.sim.bench import R_FACING
    from tofpose.sim.render import SensorModel, render_frame

    rng = np.random.default_rng(seed)
    z = rng.uniform(4000, 7000)
    T = RigidTransform(
        rotation_from_euler_deg(*rng.uniform(-15, 15, 3)) @ R_FACING,
        np.array([rng.uniform(-300, 300), rng.uniform(-200, 200), z]),
    )
    clutter = tuple(
        Clutter(
            (rng.uniform(-450, 550), rng.uniform(-300, 200), rng.uniform(0, 200)),
            float(rng.uniform(20, 40)),
            float(rng.uniform(0.5, 1.0)),
        )
        for _ in range(25)
    )
    cam, cat = CameraModel(), paper_target()
    return render_frame(cam, TargetScene(cat, clutter=clutter), T, SensorModel(), rng), T


@pytest.mark.parametrize("seed", [0, 14])
def test_triplet_hypotheses_match_when_clutter_leaves_annealing_without_a_rigid_match(seed):
    """Among 25 marker-like discs annealing's soft assignment finds no rigidly consistent
    match (the answer without the fallback); the triplet hypotheses over every blob
    then find the target, and the pose holds the truth within its covariance."""
    from dataclasses import replace

    from scipy.spatial.transform import Rotation

    f, T = _glinty_frame(seed)
    cam, cat = CameraModel(), paper_target()
    without = PosePipeline(cam, cat, replace(PipelineConfig(), triplet_fallback=False))
    alone = without.process(f.gray, f.distance_mm)
    assert not alone.ok and alone.reason.startswith("matching failed: no rigidly consistent")
    result = PosePipeline(cam, cat).process(f.gray, f.distance_mm)
    assert result.ok, result.reason
    err = np.concatenate([Rotation.from_matrix(result.R @ T.R.T).as_rotvec(), result.t_mm - T.t_mm])
    d2 = float(err @ np.linalg.solve(result.covariance, err))
    assert d2 < 22.46  # chi^2_6 at 0.999
    assert rotation_angle_deg(result.R, T.R) < 1.0


def test_the_variance_factor_narrows_only_to_what_the_residuals_bound():
    """chi^2 well below its degrees of freedom: the reflectors agree better than their
    sigmas say, and the factor is the 95 % upper bound chi^2 / chi^2_dof(0.05) (from 5
    reflectors; never below 0.04); a chi^2 that luck makes likely leaves it at 1."""
    from scipy.stats import chi2

    from tofpose.pipeline import variance_factor

    dof = 3 * 8 - 6
    assert variance_factor(3.0, 8) == pytest.approx(3.0 / chi2.ppf(0.05, dof))
    assert variance_factor(chi2.ppf(0.05, dof) + 0.1, 8) == 1.0  # plausible by luck
    assert variance_factor(0.5, 4) == 1.0  # 6 degrees of freedom: not evidence enough
    assert variance_factor(0.0, 8) == 0.04


def test_a_sharp_near_frame_reports_sigmas_its_errors_fill():
    """At 1 m on sharp frames the reflectors agree far better than the sigma floors
    (0.03 px, 1 mm) say, and the camera states exact intrinsics: the errors fill at
    least 0.35 of the reported sigmas (RMS of error / sigma over the six axes and 12
    frames: 0.44; 0.18 with the variance factor at 1 and a 0.2 % focal-length prior),
    and none lies beyond 3 sigma (chi^2_6 20.06)."""
    from tofpose.lab.pose_judgement import mahalanobis2, pose_error

    pipe = PosePipeline(CameraModel(), paper_target())
    ratios, d2 = [], []
    rng = np.random.default_rng(11)
    for seed in range(12):
        angles = rng.uniform(-12, 12, 3)
        T = facing_pose(1000.0, *angles, offset_mm=tuple(rng.uniform(-60, 60, 2)))
        pipe.reset()
        res = pipe.process(*_frame(T, seed))
        assert res.ok, res.reason
        e = pose_error(res.R, res.t_mm, T.R, T.t_mm)
        ratios.append(e / np.sqrt(np.diag(res.covariance)))
        d2.append(mahalanobis2(e, res.covariance))
    assert np.sqrt(np.mean(np.square(ratios))) > 0.35
    assert max(d2) < 20.06


def _frame(T, seed):
    f = render(T, seed=seed)
    return f.gray, f.distance_mm


def test_the_focal_length_uncertainty_is_the_cameras_unless_the_config_sets_one():
    """The image scale fixes the range to the focal length's accuracy: a camera that
    states 0.2 % gets a z sigma of about 0.2 % of 2 m (4 mm), one that states exact
    intrinsics under half of it (what is left: the markers' common centroid bias);
    ``PipelineConfig.focal_length_sigma_rel`` overrides the camera's."""
    T = facing_pose(2000.0, 4, -3, 8, offset_mm=(40.0, -30.0))
    gray, dist = _frame(T, 3)

    def z_sigma(camera, config=None):
        res = PosePipeline(camera, paper_target(), config).process(gray, dist)
        assert res.ok, res.reason
        return float(np.sqrt(res.covariance[5, 5]))

    exact, stated = z_sigma(CameraModel()), z_sigma(CameraModel(focal_length_sigma_rel=0.002))
    assert 2.5 < stated < 5.0 and exact < 0.5 * stated
    assert z_sigma(CameraModel(), PipelineConfig(focal_length_sigma_rel=0.002)) == stated


def test_pose_shift_chi2_is_the_shifts_mahalanobis_distance():
    """A pose 0.01 rad about x and 2 mm along z from the result's, under sigmas 0.005 rad
    and 1 mm: (0.01 / 0.005)^2 + (2 / 1)^2 = 8."""
    from scipy.spatial.transform import Rotation

    from tofpose.pipeline import PoseResult, pose_shift_chi2

    R0 = Rotation.from_euler("xyz", [0.2, -0.1, 0.3]).as_matrix()
    t0 = np.array([10.0, -5.0, 3000.0])
    cov = np.diag([0.005**2] * 3 + [1.0] * 3)
    result = PoseResult(ok=True, R=R0, t_mm=t0, covariance=cov)
    R1 = Rotation.from_rotvec([0.01, 0.0, 0.0]).as_matrix() @ R0
    assert pose_shift_chi2(result, R1, t0 + [0.0, 0.0, 2.0]) == pytest.approx(8.0, rel=1e-6)
    assert pose_shift_chi2(result, R0, t0) == 0.0
    assert pose_shift_chi2(PoseResult(ok=True, R=R0, t_mm=t0), R1, t0) == float("inf")


@pytest.mark.parametrize(("shift_deg", "held"), [(0.0005, True), (3.0, False)])
def test_a_pixel_fit_far_from_the_centroid_pose_is_not_taken(monkeypatch, shift_deg, held):
    """The pixel fit refines the centroid pose: a fitted pose 3 deg away from it (far
    beyond the centroid pose's own 3 sigma at 3 m) is another answer, and the centroid
    pose stays with the reason; one a hair away is taken. The fit is replaced by one that
    returns the centroid pose turned by ``shift_deg`` about the camera's x axis."""
    from dataclasses import replace as dc_replace

    from scipy.spatial.transform import Rotation

    import tofpose.pipeline as pipeline_module
    from tofpose.config import PixelFitConfig

    real_fit = pipeline_module.fit_pose_to_pixels

    def shifted_fit(gray, distance_mm, camera, catalog, R, t_mm, ids, **kwargs):
        fit = real_fit(gray, distance_mm, camera, catalog, R, t_mm, ids, **kwargs)
        turn = Rotation.from_euler("x", shift_deg, degrees=True).as_matrix()
        return dc_replace(fit, ok=True, reason="", R=turn @ R, t_mm=np.asarray(t_mm))

    monkeypatch.setattr(pipeline_module, "fit_pose_to_pixels", shifted_fit)
    f = render(facing_pose(3000.0, 2, -3, 10), seed=4)
    plain = PosePipeline(CameraModel(), paper_target()).process(f.gray, f.distance_mm)
    on = PipelineConfig(pixel_fit=PixelFitConfig(enabled=True))
    fitted = PosePipeline(CameraModel(), paper_target(), on).process(f.gray, f.distance_mm)
    assert plain.ok and fitted.ok
    angle = rotation_angle_deg(fitted.R, plain.R)
    if held:
        assert fitted.pixel_fit == "ok"
        assert angle == pytest.approx(shift_deg, abs=1e-6)
    else:
        assert "sigma from the centroid pose" in fitted.pixel_fit, fitted.pixel_fit
        assert angle < 1e-9 and np.allclose(fitted.t_mm, plain.t_mm)
        assert np.allclose(fitted.covariance, plain.covariance)


def test_pixel_fit_config_refuses_a_shift_limit_that_is_not_positive():
    from tofpose.config import PixelFitConfig

    with pytest.raises(ValueError, match="max_shift_chi2"):
        PixelFitConfig(max_shift_chi2=0.0)


def test_a_pixel_fit_is_not_taken_when_the_centroid_covariance_is_singular(monkeypatch):
    """A centroid pose whose covariance cannot be inverted gives the fit nothing to be
    checked against: the centroid pose stays, and the reason says why (not "inf
    sigma")."""
    from tofpose.config import PixelFitConfig

    monkeypatch.setattr(
        PosePipeline, "_reported_covariance", lambda self, ml, n, t: np.zeros((6, 6))
    )
    f = render(facing_pose(3000.0, 2, -3, 10), seed=4)
    on = PipelineConfig(pixel_fit=PixelFitConfig(enabled=True))
    fitted = PosePipeline(CameraModel(), paper_target(), on).process(f.gray, f.distance_mm)
    assert fitted.ok
    assert fitted.pixel_fit.startswith("the centroid pose's covariance is singular"), (
        fitted.pixel_fit
    )
    assert np.all(fitted.covariance == 0.0)  # the centroid pose's own, kept


def test_the_fallback_triplet_search_stops_by_count_not_by_the_clock(monkeypatch):
    """When annealing finds no rigid match, the triplet hypotheses over every blob stop by
    the RANSAC count or ``FALLBACK_MAX_TRIPLETS``, not by a clock: on a machine so loaded
    that every look at the clock is 10 s later (a first call's warm-up on a busy machine
    ran past the old 100 ms budget), a frame whose annealing fails still gets its pose
    from the fallback, with the true reflectors."""
    import itertools

    import tofpose.pipeline as pipeline_module
    from tofpose.stages.matching.matching import MatchResult

    cat = paper_target()
    frame = render(facing_pose(3000.0, 4, -6, 10))
    pipe = PosePipeline(CameraModel(), cat)

    def annealing_fails(self, meas):
        return MatchResult(np.empty((0, 2), np.int64), [], np.zeros((0, 0)), 0, 30.0, "none")

    monkeypatch.setattr(PosePipeline, "_match", annealing_fails)
    clock = itertools.count(1e6, 10.0)
    monkeypatch.setattr(pipeline_module.time, "perf_counter", lambda: float(next(clock)))
    r = pipe.process(frame.gray, frame.distance_mm)
    assert r.ok, r.reason
    assert sorted(int(m.catalog_id) for m in r.matched) == sorted(int(i) for i in cat.ids)


def _other_sensor_at(range_m: float, seed: int = 0):
    """A frame of the physics study's ``other sensor`` (640 x 480, 20 MHz: 7.49 m
    unambiguous range), its drawn scene, and the pipeline set for that camera."""
    from tofpose.config import config_for_camera
    from tofpose.sim.randomise import draw_frame

    cat = paper_target()
    drawn = draw_frame("other sensor", range_m, np.random.default_rng(seed), cat)
    cam = drawn.camera
    config = config_for_camera(
        PipelineConfig(), width=cam.width, height=cam.height, count_scale=cam.count_scale
    )
    return drawn, PosePipeline(cam, cat, config)


@pytest.mark.parametrize(("range_m", "seed"), [(8.0, 0), (8.0, 1), (12.0, 2), (16.0, 3)])
def test_a_target_beyond_the_unambiguous_range_is_measured_with_its_distances_unwrapped(
    range_m, seed
):
    """A 20 MHz camera reads a target at 8 m ~0.5 m away, where its blobs are far too
    small for the catalog (at 8 m they are its size); at 12 m it reads 4.5 m, where the
    sizes pass but no catalog geometry matches; at 16 m two ranges have wrapped. The frame
    is measured again with its distances read whole unambiguous ranges further, and the
    pose is right and consistent with its covariance. The stream's next frames are read
    so from the start, the reading following the target."""
    drawn, pipe = _other_sensor_at(range_m, seed)
    assert drawn.camera.unambiguous_range_mm == pytest.approx(7494.8, abs=0.1)
    T = drawn.T_camera_target
    for k in range(3):
        f = drawn.render(np.random.default_rng(100 + k))
        assert np.nanmax(f.distance_mm) < drawn.camera.unambiguous_range_mm  # it wraps
        r = pipe.process(f.gray, f.distance_mm, 0.1 * k)
        assert r.ok, r.reason
        assert rotation_angle_deg(r.R, T.R) < 1.0 and np.linalg.norm(r.t_mm - T.t_mm) < 40.0
        assert pose_nees(r.R, r.t_mm, r.covariance, T.R, T.t_mm) < 20.06
        assert np.min([m.distance_mm for m in r.matched]) > drawn.camera.unambiguous_range_mm
        assert r.distances_read_about_mm > drawn.camera.unambiguous_range_mm
        # the first frame paid for the reading it refused, the next ones did not
        assert ("refused reading" in r.timings_ms) == (k == 0)


def _counting_process(pipe: PosePipeline) -> list[int]:
    """Counts ``pipe``'s passes over a frame (``_process`` calls)."""
    calls = [0]
    inner = pipe._process

    def counted(*args, **kwargs):
        calls[0] += 1
        return inner(*args, **kwargs)

    pipe._process = counted  # type: ignore[method-assign]
    return calls


@pytest.mark.parametrize("tracking", [False, True])
def test_an_unwrapped_reading_that_does_not_hold_leaves_the_refusal_and_the_state(tracking):
    """The same far frame with a catalog of the same discs in another layout: the sizes
    say the distances wrap, the frame is read again (more than one pass), but no reading
    matches the catalog's geometry. The refusal names the wrap and what to do (not the
    catalog's sizes), and the pipeline's state is what it is without the readings tried
    (equal digests, with tracking on the frame counter too, over a following frame)."""
    from dataclasses import replace

    from tofpose.core.catalog import Catalog, Reflector

    drawn, pipe = _other_sensor_at(8.0)
    scrambled = Catalog(
        "scrambled",
        tuple(
            Reflector(
                r.id, (r.position_mm[1], -2.0 * r.position_mm[0], r.position_mm[2]), r.diameter_mm
            )
            for r in paper_target().reflectors
        ),
    )
    config = replace(pipe.config, tracking=replace(pipe.config.tracking, enabled=tracking))
    tried = PosePipeline(drawn.camera, scrambled, config)
    untried = PosePipeline(drawn.camera, scrambled, config)
    untried._wrap_readings = lambda found, meas: []  # type: ignore[method-assign]
    untried._suggest_wraps = lambda wrong_size: []  # type: ignore[method-assign]
    passes = _counting_process(tried)
    for k in range(3):
        f = drawn.render(np.random.default_rng(k))
        before = passes[0]
        r = tried.process(f.gray, f.distance_mm, 0.1 * k)
        u = untried.process(f.gray, f.distance_mm, 0.1 * k)
        assert passes[0] - before > 1
        assert not r.ok and not u.ok
        assert "wrap at 7.49 m (20 MHz)" in r.reason or "wrap (7.49 m at 20 MHz)" in r.reason
        assert "lower modulation frequency" in r.reason and "right catalog" not in r.reason
        assert tried.state_digest() == untried.state_digest()


def test_a_camera_that_unwraps_its_own_distances_is_read_as_measured():
    """A camera that states where its distances wrap (``unwrapped_range_mm``: it unwraps
    several frequencies, or reports nothing beyond) is not read again: one pass."""
    from dataclasses import replace

    drawn, pipe = _other_sensor_at(8.0)
    cam = replace(drawn.camera, unwrapped_range_mm=drawn.camera.unambiguous_range_mm)
    pipe = PosePipeline(cam, pipe.catalog, pipe.config)
    passes = _counting_process(pipe)
    f = drawn.render(np.random.default_rng(1))
    r = pipe.process(f.gray, f.distance_mm)
    assert not r.ok and passes[0] == 1


def _after_a_frame_at_8_m(range_m: float, seed: int, tolerance_mm: float):
    """A stream of the 20 MHz camera: a frame at 8 m (read one range further), then one
    of another scene at ``range_m``, whose pose must be within 1 deg and
    ``tolerance_mm``; (pipeline, that scene, its result)."""
    far, pipe = _other_sensor_at(8.0)
    then, _ = _other_sensor_at(range_m, seed=seed)
    f = far.render(np.random.default_rng(1))
    assert pipe.process(f.gray, f.distance_mm, 0.0).ok
    g = then.render(np.random.default_rng(2))
    r = pipe.process(g.gray, g.distance_mm, 5.0)
    assert r.ok, r.reason
    T = then.T_camera_target
    assert rotation_angle_deg(r.R, T.R) < 1.0 and np.linalg.norm(r.t_mm - T.t_mm) < tolerance_mm
    return pipe, then, r


def test_a_far_target_found_again_after_a_gap_is_read_further_again():
    """Read about 8 m, then (after a gap, no reset) the target at 13 m: it reads 5.5 m,
    where its sizes pass and the reading about 8 m leaves it; the candidates' range
    plus one unambiguous range is tried, and the pose is right."""
    _, _, r = _after_a_frame_at_8_m(13.0, seed=5, tolerance_mm=65.0)
    assert r.distances_read_about_mm > 12_000.0


def test_a_stream_that_comes_back_within_the_unambiguous_range_is_read_as_measured_again():
    """Read one range further at 8 m, then the target at 3 m in the same stream: read
    about 8 m its discs come out far too large, the reading is taken back, and the pose
    is right."""
    pipe, near, r = _after_a_frame_at_8_m(3.0, seed=4, tolerance_mm=20.0)
    assert max(m.distance_mm for m in r.matched) < 4000.0
    # near again, the reading ends: the next frame is taken as measured
    h = near.render(np.random.default_rng(3))
    r = pipe.process(h.gray, h.distance_mm, 0.2)
    assert r.ok and r.distances_read_about_mm is None


def test_a_target_within_the_unambiguous_range_is_read_as_measured():
    """The same camera at 4.5 m: no reading is tried, the pose is the measured one."""
    drawn, pipe = _other_sensor_at(4.5)
    f = drawn.render(np.random.default_rng(1))
    r = pipe.process(f.gray, f.distance_mm)
    assert r.ok, r.reason
    assert pipe._unwrap_about_mm is None
    T = drawn.T_camera_target
    assert rotation_angle_deg(r.R, T.R) < 1.0 and np.linalg.norm(r.t_mm - T.t_mm) < 30.0


@pytest.mark.parametrize(
    ("range_m", "refusal"),
    [
        # markers 1, 4 and 7 nearly on one line: the pose turned about it by 32 deg (1
        # sigma); reported, it was 25 deg off, 48 of its sigmas away
        (4.5, "attitude not determined by the matched reflectors [7, 1, 4]"),
        # markers 7 and 8 merged into one blob, matched as 8, with 5 and 6: reported,
        # the pose was 7 deg off, 10 of its sigmas away
        (8.0, "reflector 7 would overlap the blob matched as 8"),
    ],
)
def test_a_pose_the_few_markers_in_view_cannot_support_is_refused(range_m, refusal):
    """The target mostly out of view (the physics study's ``out of view`` cells at 4.5
    and 8 m): the frame whose three markers cannot support a pose is refused, naming
    why, and no ok pose of the cell is confidently wrong."""
    from scipy.spatial.transform import Rotation

    from tofpose.pipeline import MAX_ATTITUDE_SIGMA_DEG
    from tofpose.sim.randomise import ALL_FAMILIES, draw_frame

    cat = paper_target()
    rng = np.random.default_rng([0, ALL_FAMILIES.index("out of view"), int(range_m * 10)])
    refused, worst_d2 = [], 0.0
    pipe = PosePipeline(CameraModel(), cat)
    for _ in range(24):
        d = draw_frame("out of view", range_m, rng, cat)
        f = d.render(rng)
        pipe.reset()
        r = pipe.process(f.gray, f.distance_mm)
        if not r.ok:
            refused += [r.reason] if refusal in r.reason else []
            continue
        T = d.T_camera_target
        e = np.r_[Rotation.from_matrix(r.R @ T.R.T).as_rotvec(), r.t_mm - T.t_mm]
        worst_d2 = max(worst_d2, float(e @ np.linalg.solve(r.covariance, e)))
        sigma = np.degrees(np.sqrt(np.linalg.eigvalsh(r.covariance[:3, :3]).max()))
        assert sigma <= MAX_ATTITUDE_SIGMA_DEG
    assert len(refused) >= 1, refused
    assert worst_d2 < 20.06  # chi2_6 at 3 sigma


def test_a_refused_tracked_frame_falls_back_to_acquisition_and_is_kept_once(monkeypatch):
    """A tracked pose refused after tracking (``undetermined_attitude``, here made to
    refuse every tracked pose) falls back to the acquisition pass, and the frame is in
    the persistence history once, as a pipeline that never tracked keeps it: the
    tracker had committed it already."""
    import tofpose.pipeline as pipeline_module
    from tofpose.config import TrackingConfig

    f = render(facing_pose(3000.0, 5.0, -3.0, 2.0))
    tracking = PosePipeline(
        CameraModel(), paper_target(), PipelineConfig(tracking=TrackingConfig(enabled=True))
    )
    plain = PosePipeline(CameraModel(), paper_target())
    first = tracking.process(f.gray, f.distance_mm)
    assert first.ok and first.mode == "acquisition"
    real = pipeline_module.undetermined_attitude
    monkeypatch.setattr(
        pipeline_module,
        "undetermined_attitude",
        lambda r: "refused in this test" if r.mode == "tracking" else real(r),
    )
    second = tracking.process(f.gray, f.distance_mm)
    assert second.ok and second.mode == "acquisition"
    for _ in range(2):
        assert plain.process(f.gray, f.distance_mm).ok
    kept = [e.content_digest() for e in tracking._persistence.snapshot()]
    assert kept == [e.content_digest() for e in plain._persistence.snapshot()]
    assert len(kept) == 2
