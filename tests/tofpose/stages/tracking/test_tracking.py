"""Tracking mode: windows around predicted reflectors, fallback to acquisition, never a
stale pose. Frames come from the simulator with a known truth."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import facing_pose, render
from tofpose import CameraModel, PipelineConfig, PosePipeline, paper_target
from tofpose.config import TrackingConfig
from tofpose.core.catalog import Catalog
from tofpose.core.geometry import rotation_angle_deg
from tofpose.sim.scene import Clutter, TargetScene
from tofpose.stages.tracking.tracking import Window, find_in_window, predict_windows

TRACKING = PipelineConfig(tracking=TrackingConfig(enabled=True))


def test_windows_sit_on_the_predicted_reflectors_and_skip_merging_ones():
    cam, cat = CameraModel(), paper_target()
    T = facing_pose(3000.0, 2, -3, 10)
    ws = predict_windows(
        cam, cat.positions_mm, cat.diameters_mm, T.R, T.t_mm, margin_px=4.0, min_diameter_px=1.0
    )
    uv = cam.project(T.apply(cat.positions_mm))
    assert len(ws) == 8
    for w in ws:
        np.testing.assert_allclose(w.centre_uv, uv[w.catalog_index])
        assert w.u0 <= uv[w.catalog_index, 0] < w.u1 and w.v0 <= uv[w.catalog_index, 1] < w.v1
        assert w.u1 - w.u0 >= w.diameter_px + 8
    far = facing_pose(8000.0)
    ids = {
        int(cat.ids[w.catalog_index])
        for w in predict_windows(
            cam,
            cat.positions_mm,
            cat.diameters_mm,
            far.R,
            far.t_mm,
            margin_px=4.0,
            min_diameter_px=1.0,
        )
    }
    assert 7 not in ids and 8 not in ids and len(ids) == 6  # 7 and 8 merge at 8 m


def test_find_in_window_takes_the_disc_and_says_why_not():
    gray = np.zeros((60, 60), np.float32)
    yy, xx = np.mgrid[:60, :60]
    gray[(xx - 30.3) ** 2 + (yy - 20.6) ** 2 <= 9] = 1000.0  # a 6 px disc
    w = Window(0, np.array([29.0, 21.0]), 6.0, 22, 38, 13, 29)
    b = find_in_window(gray, w, 500.0, 0.0)
    assert not isinstance(b, str)
    np.testing.assert_allclose(b.centroid_uv, [30.3, 20.6], atol=0.2)
    assert find_in_window(np.zeros_like(gray), w, 500.0, 0.0) == "not found in its window"
    shifted = Window(0, np.array([36.0, 21.0]), 6.0, 29, 44, 13, 29)  # disc at its edge
    assert "edge" in find_in_window(gray, shifted, 500.0, 0.0)


@pytest.mark.parametrize(
    ("z", "offset"), [(700.0, (-110.0, -55.0)), (3000.0, (0.0, -30.0)), (5712.0, (2.0, -10.0))]
)
def test_tracking_gives_the_acquisition_pose_within_its_sigma(z, offset):
    """The same static stream with tracking off and on: after the first (acquisition)
    frame tracking takes over, and each pose differs from acquisition's by less than its
    own reported 1-sigma (position norm and attitude). Not closer: beyond ~4.5 m tracking
    leaves out markers 7 and 8, which merge (acquisition splits them apart), and it
    thresholds at the last acquisition's level, so the two see slightly different data.
    Measured: at most 0.1 mm / 0.04 deg at 0.7-3 m; 0.23 deg (0.7 sigma) at 5.7 m."""
    cam, cat = CameraModel(), paper_target()
    T = facing_pose(z, 2, -3, 10, offset_mm=offset)
    frames = [render(T, seed=s) for s in range(12)]
    acq, trk = PosePipeline(cam, cat), PosePipeline(cam, cat, TRACKING)
    modes = []
    for f in frames:
        a, b = acq.process(f.gray, f.distance_mm), trk.process(f.gray, f.distance_mm)
        assert a.ok and b.ok
        modes.append(b.mode)
        if b.mode == "tracking":
            sd = np.sqrt(np.diag(b.covariance))
            assert np.linalg.norm(a.t_mm - b.t_mm) < np.linalg.norm(sd[3:])
            assert np.radians(rotation_angle_deg(a.R, b.R)) < np.linalg.norm(sd[:3])
            assert np.linalg.norm(b.t_mm - T.t_mm) < 3.0 * np.linalg.norm(sd[3:]) + 0.5
    assert modes[0] == "acquisition" and modes[1:].count("tracking") == 11


def test_tracking_recovers_after_the_target_jumps_and_is_never_stale():
    cam, cat = CameraModel(), paper_target()
    a, b = facing_pose(2500.0, 0, 0, 0), facing_pose(2500.0, 4, -6, 30, offset_mm=(350, -120))
    seq = [a] * 4 + [b] * 4 + [a] * 2
    pipe = PosePipeline(cam, cat, TRACKING)
    modes = []
    for n, T in enumerate(seq):
        f = render(T, seed=n)
        r = pipe.process(f.gray, f.distance_mm, n / 30)
        assert r.ok, r.reason
        assert rotation_angle_deg(r.R, T.R) < 0.3 and np.linalg.norm(r.t_mm - T.t_mm) < 3.0
        modes.append(r.mode)
    # the frame after each jump is measured afresh, the ones after it tracked again
    assert modes == [
        "acquisition",
        "tracking",
        "tracking",
        "tracking",
        "acquisition",
        "tracking",
        "tracking",
        "tracking",
        "acquisition",
        "tracking",
    ]


def test_a_slewing_target_is_tracked_frame_by_frame():
    """Roll slewing 0.5 deg per frame (as the acquisition test): tracking follows each
    frame, never lags."""
    cam, cat = CameraModel(), paper_target()
    pipe = PosePipeline(cam, cat, TRACKING)
    tracked = 0
    for n in range(10):
        T = facing_pose(1800.0, 0, 0, 0.5 * n)
        r = pipe.process(*(lambda f: (f.gray, f.distance_mm))(render(T, seed=n)))
        assert r.ok and rotation_angle_deg(r.R, T.R) < 0.15
        tracked += r.mode == "tracking"
    assert tracked >= 8


def test_acquisition_again_every_reacquire_every_frames():
    cam, cat = CameraModel(), paper_target()
    cfg = PipelineConfig(tracking=TrackingConfig(enabled=True, reacquire_every=4))
    pipe = PosePipeline(cam, cat, cfg)
    T = facing_pose(2000.0, 1, 2, 3)
    modes = [
        pipe.process(*(lambda f: (f.gray, f.distance_mm))(render(T, seed=s))).mode for s in range(9)
    ]
    assert modes == ["acquisition", "tracking", "tracking", "tracking"] * 2 + ["acquisition"]


def test_a_covered_marker_while_tracking_falls_back_and_the_pose_stays_right():
    """Marker 6 is covered from frame 3 on: it is still predicted in view, its window is
    empty, so each of those frames falls back to acquisition (7 markers); the poses stay
    right."""
    cam, cat = CameraModel(), paper_target()
    covered = TargetScene(Catalog(cat.name, tuple(r for r in cat.reflectors if r.id != 6)))
    T = facing_pose(3000.0, 2, -3, 5)
    pipe = PosePipeline(cam, cat, TRACKING)
    for n in range(6):
        f = render(T, seed=n, scene=covered if n >= 3 else None)
        r = pipe.process(f.gray, f.distance_mm)
        assert r.ok and np.linalg.norm(r.t_mm - T.t_mm) < 2.0
        if n >= 3:
            assert r.mode == "acquisition" and 6 not in [m.catalog_id for m in r.matched]


def test_a_reflection_appearing_beside_a_marker_never_bends_a_tracked_pose():
    """From frame 2 a bright 80 mm reflection sits 60 mm in front of marker 6 (inside its
    window): the tracked fit would bend by ~6 deg; the residual test refuses it, the
    acquisition pass drops the reflection as an outlier, and the pose stays right."""
    cam, cat = CameraModel(), paper_target()
    glint = TargetScene(clutter=(Clutter((120.0, 60.0, 210.0), 80.0, 1.0),))
    T = facing_pose(3000.0, 2, -3, 12)
    pipe = PosePipeline(cam, cat, TRACKING)
    for n in range(5):
        f = render(T, seed=n, scene=glint if n >= 2 else None)
        r = pipe.process(f.gray, f.distance_mm)
        assert r.ok
        assert np.linalg.norm(r.t_mm - T.t_mm) < 2.0 and rotation_angle_deg(r.R, T.R) < 0.3
