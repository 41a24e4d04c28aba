import numpy as np
import pytest

from tests.conftest import facing_pose, render
from tofpose.config import ExtractionConfig
from tofpose.core.camera import CameraModel
from tofpose.core.catalog import paper_target
from tofpose.stages.extraction.extraction import (
    FrameError,
    active_pixel_mask,
    check_frame,
    disc_image_centre_offset_px,
    find_candidate_blobs,
    frame_levels,
    measure_blobs,
)


def _blobs(frame, cfg=None, camera=None):
    camera = camera or CameraModel()
    cfg = cfg or ExtractionConfig()
    g, d = check_frame(camera, frame.gray, frame.distance_mm)
    stats = frame_levels(g, cfg)
    blobs = find_candidate_blobs(g, d, camera, paper_target().diameters_mm, cfg, stats).accepted
    return measure_blobs(blobs, g, d, camera, stats.background)


@pytest.mark.parametrize(
    ("distance_mm", "angles"),
    [(1000.0, (0, 0, 0)), (1500.0, (6, -5, 15)), (2000.0, (20, -4, 10)), (3000.0, (-10, 12, -30))],
)
def test_centroids_match_projected_centres_on_noiseless_frames(distance_mm, angles):
    """Sub-0.1 px after removing the perspective (ellipse-centre) bias; ranges to 0.5 %."""
    cam, cat = CameraModel(), paper_target()
    T = facing_pose(distance_mm, *angles, offset_mm=(30.0, -40.0))
    blobs = _blobs(render(T, noise=False))
    centres = T.apply(cat.positions_mm)
    uv_true = cam.project(centres)
    assert len(blobs) >= 5
    worst_raw, worst = 0.0, 0.0
    for b in blobs:
        k = int(np.argmin(np.linalg.norm(uv_true - b.centroid_uv, axis=1)))
        off = disc_image_centre_offset_px(cam, centres[k], T.R[:, 2], cat.diameters_mm[k] / 2)
        worst_raw = max(worst_raw, np.linalg.norm(b.centroid_uv - uv_true[k]))
        worst = max(worst, np.linalg.norm(b.centroid_uv - off - uv_true[k]))
        assert b.distance_mm == pytest.approx(np.linalg.norm(centres[k]), rel=5e-3, abs=1.0)
    assert worst < 0.1, f"worst corrected centroid error {worst:.3f} px (raw {worst_raw:.3f})"


def test_perspective_offset_vanishes_for_fronto_parallel_disc():
    cam = CameraModel()
    off = disc_image_centre_offset_px(
        cam, np.array([300.0, -200.0, 1500.0]), np.array([0, 0, -1.0]), 40.0
    )
    np.testing.assert_allclose(off, 0.0, atol=1e-9)
    tilted = disc_image_centre_offset_px(
        cam, np.array([0.0, 0.0, 800.0]), np.array([0, -0.5, -0.866]), 40.0
    )
    assert np.linalg.norm(tilted) > 0.05


def test_active_set_is_capped_dimmest_first():
    rng = np.random.default_rng(0)
    g = rng.uniform(0, 1000, (240, 320)).astype(np.float32)
    stats = frame_levels(g, ExtractionConfig(raw_threshold_abs=100.0))
    mask, applied = active_pixel_mask(g, stats, n_max=500)
    assert applied.n_active == mask.sum() == 500 and stats.n_active == 0
    assert applied.raw_threshold > stats.raw_threshold
    assert g[mask.astype(bool)].min() >= np.sort(g.ravel())[-500]


def test_size_gate_follows_range():
    """The same physical 80 mm marker is accepted at 1 m and 6 m; a disc twice too big is not."""
    for z in (1000.0, 6000.0):
        assert any(b.area_px > 0 for b in _blobs(render(facing_pose(z), noise=False)))
    from tofpose.core.catalog import Catalog, Reflector
    from tofpose.sim.scene import TargetScene

    big = Catalog(
        "big",
        tuple(
            Reflector(i, (x, y, 100.0), 200.0)
            for i, x, y in ((1, -200, 0), (2, 0, 100), (3, 200, -50))
        ),
    )
    frame = render(facing_pose(2000.0), noise=False, scene=TargetScene(catalog=big))
    assert _blobs(frame) == []


@pytest.mark.parametrize(
    ("gray", "dist", "msg"),
    [
        (np.zeros((240, 300), np.uint16), np.zeros((240, 320), np.float32), "gray image has shape"),
        (
            np.zeros((240, 320), np.uint16),
            np.zeros((24, 32), np.float32),
            "distance image has shape",
        ),
        (np.zeros((240, 320), bool), np.zeros((240, 320), np.float32), "integer counts"),
        (np.zeros((240, 320), np.uint16), np.zeros((240, 320), np.int32), "float mm"),
    ],
)
def test_check_frame_names_the_problem(gray, dist, msg):
    with pytest.raises(FrameError, match=msg):
        check_frame(CameraModel(), gray, dist)


def test_check_frame_turns_inf_and_negative_into_nan():
    d = np.full((240, 320), 1000.0, np.float32)
    d[0, 0], d[0, 1], d[0, 2] = np.inf, -5.0, np.nan
    _, out = check_frame(CameraModel(), np.zeros((240, 320), np.uint16), d)
    assert np.isnan(out[0, :3]).all() and np.isfinite(out[1:]).all()


@pytest.mark.parametrize("gray_dtype", [np.uint16, np.uint8, np.int32, np.float32, np.float64])
@pytest.mark.parametrize("distance_dtype", [np.float32, np.float64])
def test_check_frame_converts_every_input_dtype_as_numpy_does(gray_dtype, distance_dtype):
    """Counts become float32 (non-finite float counts 0), distances float32 with every
    non-finite or non-positive value NaN, whichever path converts them (uint16 counts
    with float distances take one compiled pass)."""
    rng = np.random.default_rng(4)
    gray = rng.integers(0, 250, (240, 320)).astype(gray_dtype)
    d = rng.normal(1500.0, 400.0, (240, 320)).astype(distance_dtype)
    d.flat[:6] = [np.inf, -np.inf, np.nan, 0.0, -3.0, 1e-3]
    if np.dtype(gray_dtype).kind == "f":
        gray.flat[:2] = [np.nan, np.inf]
    g, out = check_frame(CameraModel(), gray, d)
    want_g = np.nan_to_num(gray.astype(np.float32), nan=0.0, posinf=0.0, neginf=0.0)
    want_d = d.astype(np.float32)
    want_d[~(np.isfinite(want_d) & (want_d > 0))] = np.nan
    assert g.dtype == out.dtype == np.float32
    np.testing.assert_array_equal(g, want_g)
    np.testing.assert_array_equal(out, want_d)
    before = (g[0, 10], out[0, 10])
    gray[0, 10], d[0, 10] = 7, -1.0  # copies: the caller's buffers may be reused
    assert (g[0, 10], out[0, 10]) == before


def _found(frame, cfg=None):
    camera, cfg = CameraModel(), cfg or ExtractionConfig()
    g, d = check_frame(camera, frame.gray, frame.distance_mm)
    stats = frame_levels(g, cfg)
    return find_candidate_blobs(g, d, camera, paper_target().diameters_mm, cfg, stats), g, stats


@pytest.mark.parametrize(
    ("diameter_mm", "distance_mm", "reason"),
    [(200.0, 2000.0, "oversize"), (10.0, 1000.0, "penalty"), (6.0, 1000.0, "size")],
)
def test_blobs_refused_by_a_gate_are_reported_with_that_gate(diameter_mm, distance_mm, reason):
    """Discs far larger (smaller) than the catalog's are refused by the size window as
    oversize (too small), at their place in the image."""
    from tofpose.core.catalog import Catalog, Reflector
    from tofpose.sim.scene import TargetScene

    pos = ((1, -200, 0), (2, 0, 100), (3, 200, -50))
    cat = Catalog("other", tuple(Reflector(i, (x, y, 100.0), diameter_mm) for i, x, y in pos))
    pose = facing_pose(distance_mm)
    frame = render(pose, noise=False, scene=TargetScene(catalog=cat))
    found, _, _ = _found(frame)
    assert found.accepted == []
    assert [r.reason for r in found.rejected] == [reason] * 3, found.rejected
    centres = CameraModel().project(cat.positions_mm @ pose.R.T + pose.t_mm)
    got = np.array(sorted((r.u_px, r.v_px) for r in found.rejected))
    np.testing.assert_allclose(got, np.array(sorted(map(tuple, centres))), atol=1.5)


def test_a_marker_cut_by_the_border_is_rejected_as_such_and_the_active_set_is_a_threshold():
    pose = facing_pose(1500.0)
    # Slide the target right until marker 8 (x = 420 mm) straddles the image's right edge.
    cam = CameraModel()
    edge_x_mm = (cam.width - 1 - cam.cx) * (1500.0 - 150.0) / cam.fx
    pose.t_mm[0] = edge_x_mm - 420.0
    frame = render(pose, noise=False)
    found, g, stats = _found(frame)
    border = [r for r in found.rejected if r.reason == "border"]
    assert len(border) == 1 and border[0].u_px > cam.width - 20
    assert len(found.accepted) == 7
    # The active pixel set is exactly the pixels at or above the applied threshold.
    assert np.array_equal(found.active_mask.astype(bool), g >= stats.raw_threshold)


def test_blob_with_values_is_dataclasses_replace():
    """The per-frame copy with changed fields gives what ``dataclasses.replace`` gives,
    leaves the original as it was, and refuses a field Blob does not have."""
    from dataclasses import fields, replace

    from tofpose.stages.extraction.extraction import Blob

    b = Blob(
        pixels=np.arange(5),
        area_px=5,
        bbox=(1, 2, 3, 4),
        peak_counts=900.0,
        ellipse=((1.0, 2.0), (3.0, 2.5), 10.0),
        source="ellipse",
    )
    changes = {"centroid_uv": np.array([3.5, 4.5]), "distance_mm": 1234.5}
    got, want = b.with_values(**changes), replace(b, **changes)
    assert type(got) is Blob and got is not b
    for f in fields(Blob):
        a, w = getattr(got, f.name), getattr(want, f.name)
        same = np.array_equal(a, w, equal_nan=True) if isinstance(w, np.ndarray) else a == w
        assert same or (a != a and w != w), f.name  # NaN floats are the same NaN
    assert np.isnan(b.distance_mm) and np.isnan(b.centroid_uv).all()  # unchanged
    with pytest.raises(TypeError, match="distance"):
        b.with_values(distance=3.0)
    with pytest.raises(AttributeError):  # still frozen
        got.distance_mm = 1.0


def test_a_frame_is_saturated_at_the_cameras_own_full_scale():
    """Saturation is counted at ``CameraModel.full_scale_counts``, not at 12 bits: a
    frame at 4095 everywhere is saturated for the TOFcam-660 (full scale 4095), not for
    a 16-bit camera, which saturates at 65535; the pipeline refuses the first alone."""
    from tofpose import CameraModel, PosePipeline, paper_target
    from tofpose.config import ExtractionConfig
    from tofpose.stages.extraction.extraction import frame_levels

    gray = np.full((240, 320), 4095.0, np.float32)
    distance = np.full((240, 320), 3000.0, np.float32)
    assert frame_levels(gray, ExtractionConfig()).saturated_fraction == 1.0
    wide = frame_levels(gray, ExtractionConfig(), saturated_counts=65535.0)
    assert wide.saturated_fraction == 0.0
    twelve_bit = PosePipeline(CameraModel(), paper_target()).process(gray, distance)
    assert twelve_bit.reason.startswith("frame saturated")
    sixteen_bit = CameraModel(full_scale_counts=65535.0)
    result = PosePipeline(sixteen_bit, paper_target()).process(gray, distance)
    assert not result.ok and not result.reason.startswith("frame saturated")
