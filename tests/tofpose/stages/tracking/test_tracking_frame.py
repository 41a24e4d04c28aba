"""The compiled tracking frame (``tofpose.stages.tracking.tracking_frame``): its windows against the
window rule, and its poses against the reference statement of the §5 fit on their own
measurements, with and without lens distortion, persistence settings and a range
correction; tracked frames and fallbacks to acquisition alike."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tests.conftest import facing_pose, render
from tofpose import CameraModel, PipelineConfig, PosePipeline, paper_target
from tofpose.calibration.range import RangeCorrection
from tofpose.config import PersistenceConfig, TrackingConfig
from tofpose.core.catalog import Catalog
from tofpose.core.records import camera_record, catalog_record
from tofpose.sim.render import SensorModel
from tofpose.sim.scene import Clutter, TargetScene
from tofpose.stages.tracking.kernels.tracking import camera_windows
from tofpose.stages.tracking.tracking import Window, predict_windows

TRACKING = PipelineConfig(tracking=TrackingConfig(enabled=True, reacquire_every=6))


#: a lens with distortion (the simulator renders without; these tests compare two code
#: paths on the same frames, not poses against the truth)
LENS = CameraModel(dist=(-0.02, 0.008, 0.0004, -0.0003, 0.0))


def _windows_numpy(cam, xyz, diameters, T, margin_px, min_diameter_px):
    """The window rule of ``predict_windows`` stated in NumPy with ``CameraModel.project``
    (OpenCV's projection under distortion): (catalog index, centre, diameter, u0, u1,
    v0, v1) of the reflectors in view, large enough and clear of their neighbours."""
    centres = T.apply(xyz)
    uv = cam.project(centres)
    d_px = cam.fx * diameters / centres[:, 2]
    gap = np.linalg.norm(uv[:, None] - uv[None], axis=-1) - 0.5 * (d_px[:, None] + d_px[None])
    np.fill_diagonal(gap, np.inf)
    half = 0.5 * d_px + margin_px
    u0, u1 = np.floor(uv[:, 0] - half).astype(int), np.ceil(uv[:, 0] + half).astype(int) + 1
    v0, v1 = np.floor(uv[:, 1] - half).astype(int), np.ceil(uv[:, 1] + half).astype(int) + 1
    use = (d_px >= min_diameter_px) & (gap.min(axis=1) >= 2.0)
    use &= (u0 >= 0) & (v0 >= 0) & (u1 <= cam.width) & (v1 <= cam.height)
    return [Window(i, uv[i], d_px[i], u0[i], u1[i], v0[i], v1[i]) for i in np.flatnonzero(use)]


@pytest.mark.parametrize("cam", [CameraModel(), LENS], ids=["pinhole", "distorted"])
@pytest.mark.parametrize(
    ("z", "offset"), [(700.0, (60.0, -40.0)), (3000.0, (-120.0, 40.0)), (8000.0, (-120.0, 40.0))]
)
def test_camera_windows_are_the_window_rule(cam, z, offset):
    cat = paper_target()
    T = facing_pose(z, 3, -4, 20, offset_mm=offset)
    want = _windows_numpy(cam, cat.positions_mm, cat.diameters_mm, T, 4.0, 1.0)
    got = predict_windows(
        cam, cat.positions_mm, cat.diameters_mm, T.R, T.t_mm, margin_px=4.0, min_diameter_px=1.0
    )
    assert [(w.catalog_index, w.u0, w.u1, w.v0, w.v1) for w in got] == [
        (w.catalog_index, w.u0, w.u1, w.v0, w.v1) for w in want
    ]
    idx, bounds, centres, diam = camera_windows(
        catalog_record(cat), T.R, T.t_mm, camera_record(cam), 4.0, 1.0
    )
    assert idx.tolist() == [w.catalog_index for w in want] and len(want) >= 3
    assert bounds.tolist() == [[w.u0, w.u1, w.v0, w.v1] for w in want]
    np.testing.assert_allclose(centres, [w.centre_uv for w in want], atol=1e-9)
    np.testing.assert_allclose(diam, [w.diameter_px for w in want], rtol=1e-12)
    behind = facing_pose(-500.0)
    nothing = camera_windows(
        catalog_record(cat), behind.R, behind.t_mm, camera_record(cam), 4.0, 1.0
    )
    assert len(nothing.catalog_index) == 0


def _stream():
    """A static run, a slew, a jump, a covered marker and a reflection in a window: every
    way tracking continues or falls back."""
    cat = paper_target()
    covered = TargetScene(Catalog(cat.name, tuple(r for r in cat.reflectors if r.id != 6)))
    glint = TargetScene(clutter=(Clutter((120.0, 60.0, 210.0), 80.0, 1.0),))
    for _ in range(6):
        yield facing_pose(2500.0, 2, -3, 10), None
    for n in range(5):
        yield facing_pose(2500.0, 2, -3, 10 + 0.5 * n), None
    yield facing_pose(2600.0, 2, 4, 14), None  # a jump
    for n in range(3):
        yield facing_pose(2600.0, 2, 4, 14), covered if n else None
    for n in range(4):
        yield facing_pose(2600.0, 2, 4, 14), glint if n >= 2 else None
    for _ in range(6):
        yield facing_pose(5712.0, 2, -3, 10, offset_mm=(2.0, -10.0)), None


#: a calibrated range correction with every term of the model (offsets of a few mm, as
#: a real camera's calibration gives)
CORRECTION = RangeCorrection(
    SensorModel().unambiguous_range_mm,
    offset_mm=3.0,
    harmonics_mm=((2.0, -1.5), (0.5, 0.3)),
    amplitude_mm_per_decade=1.5,
    pixel_offsets_mm=np.random.default_rng(7).normal(0.0, 2.0, CameraModel().shape),
)


@pytest.mark.parametrize(
    ("cam", "persistence", "correction"),
    [
        (CameraModel(), PersistenceConfig(), None),
        (CameraModel(), PersistenceConfig(1, 1), None),
        (CameraModel(), PersistenceConfig(3, 3), None),
        (LENS, PersistenceConfig(), None),
        (CameraModel(), PersistenceConfig(), CORRECTION),
    ],
    ids=["K=5", "K=1", "K=3,C=3", "distorted", "range-corrected"],
)
def test_each_tracked_pose_is_the_reference_fit_of_its_own_measurements(
    cam, persistence, correction
):
    """Every tracked pose is the maximum-likelihood pose (``tofpose.stages.pose.reference.pose.
    ml_refine``, SciPy's least squares) of the reflectors it reports (bearings, ranges,
    sigmas), to a thousandth of its sigma; the frame-level sigma estimate and the range
    offset are off here, so that the fit's sigmas are the reported ones."""
    from tofpose.stages.pose.records import Reflectors
    from tofpose.stages.pose.reference.pose import ml_refine

    cat = paper_target()
    cfg = replace(
        TRACKING, persistence=persistence, adapt_range_sigma=False, estimate_range_offset=False
    )
    pipe = PosePipeline(cam, cat, cfg, range_correction=correction)
    xyz = dict(zip(cat.ids, cat.positions_mm, strict=True))
    modes = []
    for k, (T, scene) in enumerate(_stream()):
        f = render(T, seed=k, scene=scene)
        r = pipe.process(f.gray, f.distance_mm)
        modes.append(r.mode)
        if not (r.ok and r.mode == "tracking"):
            continue
        assert "tracking" in r.timings_ms  # one compiled call
        x = np.array([xyz[m.catalog_id] for m in r.matched])
        rho = np.array([m.distance_mm for m in r.matched])
        e = np.array([m.point_mm for m in r.matched]) / rho[:, None]
        sr = np.array([m.range_sigma_mm for m in r.matched])
        sb = np.array([m.centroid_sigma_px for m in r.matched]) / cam.fx
        R, t, cov, _ = ml_refine(Reflectors(x=x, e=e, rho=rho, sr=sr, sb=sb), r.R, r.t_mm)
        sigma = np.sqrt(np.diag(cov))
        d_rot = Rotation.from_matrix(R @ r.R.T).as_rotvec()
        assert np.all(np.abs(d_rot) < 1e-3 * sigma[:3]), (d_rot, sigma[:3])
        assert np.all(np.abs(t - r.t_mm) < 1e-3 * sigma[3:]), (t - r.t_mm, sigma[3:])
        np.testing.assert_allclose(np.linalg.norm(e, axis=1), 1.0, atol=1e-12)
    # the stream exercised tracked frames, and without the range correction fallbacks to
    # acquisition after them (with it, 4 frames are tracked, at the stream's end, between
    # two of the stream's scheduled acquisitions: the fit cannot absorb its made-up errors
    # here without the frame's sigma estimate)
    assert modes.count("tracking") >= (4 if correction is not None else 10)
    pairs = zip(modes[:-1], modes[1:], strict=True)
    assert correction is not None or any(p == "tracking" and m == "acquisition" for p, m in pairs)


def test_range_offsets_of_another_image_size_are_refused():
    small = replace(CORRECTION, pixel_offsets_mm=np.zeros((120, 160)))
    with pytest.raises(ValueError, match="120 x 160 px .* 240 x 320"):
        PosePipeline(CameraModel(), paper_target(), TRACKING, range_correction=small)
