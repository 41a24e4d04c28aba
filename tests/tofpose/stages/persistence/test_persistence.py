from dataclasses import replace

import numpy as np

from tofpose.config import PersistenceConfig
from tofpose.core.camera import CameraModel
from tofpose.stages.extraction.extraction import Blob
from tofpose.stages.persistence.persistence import Persistence
from tofpose.stages.persistence.reference.persistence import History

H, W = 40, 60
CAM = CameraModel(
    width=W, height=H, fx=60.0, fy=60.0, cx=29.5, cy=19.5, dist=(-0.05, 0.01, 0.0, 0.0, 0.0)
)


def _frame(cx, cy, level=1000.0, rng=None, r=4):
    v, u = np.mgrid[0:H, 0:W]
    inside = (u - cx) ** 2 + (v - cy) ** 2 <= r * r
    g = np.where(inside, level, 10.0).astype(np.float32)
    d = np.where(inside, 2000.0, np.nan).astype(np.float32)
    if rng is not None:
        d = d + rng.normal(0, 5, d.shape).astype(np.float32)
    idx = np.flatnonzero(inside)
    b = Blob(
        pixels=idx,
        area_px=len(idx),
        bbox=(cx - r, cy - r, 2 * r + 1, 2 * r + 1),
        centroid_uv=np.array([cx, cy], float),
    )
    return [b], g, d


def test_static_scene_uses_k_frames_and_median_distance():
    p = Persistence(PersistenceConfig(k_frames=5, c_min=2))
    rng = np.random.default_rng(0)
    for n in range(1, 8):
        blobs, g, d = _frame(20, 20, rng=rng)
        kept, mean_g, med_d, info = p.measure(blobs, g, d, CAM, 10.0)
        assert info.frames_used == min(n, 5)
        assert not info.motion
        assert len(kept) == 1
    # The temporal median over 5 frames has less noise than one frame.
    pix = kept[0].pixels
    assert np.std(med_d.reshape(-1)[pix]) < 0.75 * np.std(d.reshape(-1)[pix])


def test_motion_cuts_history_so_nothing_stale_is_averaged():
    p = Persistence(PersistenceConfig(k_frames=5, c_min=2, motion_tolerance_px=0.35))
    for _ in range(4):
        p.measure(*_frame(20, 20), CAM, 10.0)
    blobs, g, d = _frame(26, 20)  # the scene jumped 6 px
    kept, mean_g, _, info = p.measure(blobs, g, d, CAM, 10.0)
    assert info.motion and info.frames_used == 1
    assert mean_g is g  # only the current frame
    assert len(kept) == 1  # a fresh scene is measured, not refused


def test_transient_blob_is_dropped_by_counter_image():
    p = Persistence(PersistenceConfig(k_frames=5, c_min=2))
    for _ in range(3):
        p.measure(*_frame(20, 20), CAM, 10.0)
    blobs, g, d = _frame(20, 20)
    extra, g2, _ = _frame(45, 30, r=3)
    g = np.maximum(g, g2)
    kept, _, _, info = p.measure(blobs + extra, g, d, CAM, 10.0)
    assert len(kept) == 1 and info.dropped_blobs == 1


def test_the_compiled_combination_is_the_reference_statement():
    """``Persistence.measure`` (one compiled call) against ``tofpose.reference.
    persistence.History`` over a stream with a static run, a transient blob the counter
    drops, a blob without a centroid (as a split part has) and a jump that cuts the
    history: the same frames combined, the same blobs kept, and I-bar and D-bar equal
    where the compiled call defines them (inside the boxes grown by 2 px, at the kept
    blobs' pixels; elsewhere its scratch frames hold what earlier frames left)."""
    rng = np.random.default_rng(3)
    stream = [_frame(20, 20, rng=rng) for _ in range(4)]
    blobs, g, d = _frame(20, 20, rng=rng)
    extra, g2, d2 = _frame(45, 30, r=3, rng=rng)
    stream.append((blobs + extra, np.maximum(g, g2), np.fmin(d, d2)))
    blobs, g, d = _frame(20, 20, rng=rng)
    stream.append(([replace(blobs[0], centroid_uv=np.full(2, np.nan))], g, d))
    stream += [_frame(27, 22, rng=rng) for _ in range(3)]
    cfg = PersistenceConfig(k_frames=4, c_min=2)
    compiled, reference = (
        Persistence(cfg),
        History(cfg.k_frames, cfg.c_min, cfg.motion_tolerance_px),
    )
    seen_drop = seen_motion = seen_combined = False
    for blobs, g, d in stream:
        got, got_g, got_d, info = compiled.measure(blobs, g, d, CAM, 10.0)
        want = reference.combine(
            [b.pixels for b in blobs], np.array([b.centroid_uv for b in blobs]), g, d
        )
        assert (info.frames_used, info.motion) == (want.frames_used, want.motion)
        assert [b.pixels.tolist() for b in got] == [
            b.pixels.tolist() for b, k in zip(blobs, want.keep, strict=True) if k
        ]
        for x, y, bw, bh in (b.bbox for b in blobs):
            box = np.s_[max(y - 2, 0) : y + bh + 2, max(x - 2, 0) : x + bw + 2]
            np.testing.assert_array_equal(got_g[box], want.mean_gray[box])
        for b in got:
            np.testing.assert_array_equal(
                got_d.ravel()[b.pixels], want.median_distance.ravel()[b.pixels]
            )
        seen_drop |= info.dropped_blobs > 0
        seen_motion |= info.motion
        seen_combined |= info.frames_used == cfg.k_frames
    assert seen_drop and seen_motion and seen_combined


def test_a_target_turning_in_place_is_not_averaged_into_a_stale_pose():
    """A 5 deg, 4 s sine slew about the target's own vertical axis at 3 m, rendered at
    10 Hz: the markers' images hardly move (the centroid gate passes) but their ranges
    change by millimetres a frame. Frames combined over that lag the ranges: with the
    centroid gate alone the poses' mean NEES/6 read 39 (0.69 deg RMS attitude error, a
    covariance claiming 0.1 deg). The range gate (``kernels.persistence.
    ranges_consistent``) cuts the history; the static scene before it still combines
    five frames."""
    import math

    from scipy.spatial.transform import Rotation

    from bench._foreign_metrics import pose_error
    from tests.conftest import facing_pose, render
    from tofpose import CameraModel, PosePipeline, paper_target
    from tofpose.core.geometry import RigidTransform

    pipe = PosePipeline(CameraModel(), paper_target())
    t0 = facing_pose(3000.0, 2, -3, 5)
    used_static, d2, att = [], [], []
    for k in range(8):
        r = pipe.process(*_rendered(render, t0, k), 0.1 * k)
        used_static.append(r.frames_used)
    assert used_static[-4:] == [5, 5, 5, 5]
    amp = math.radians(5.0)
    for k in range(50):
        tt = 0.1 * k
        R = Rotation.from_rotvec([0.0, amp * math.sin(2 * math.pi * tt / 4.0), 0.0]).as_matrix()
        T = RigidTransform(R @ t0.R, t0.t_mm)
        r = pipe.process(*_rendered(render, T, 100 + k), 0.8 + tt)
        assert r.ok, r.reason
        e = pose_error(r.R, r.t_mm, T.R, T.t_mm)
        d2.append(e @ np.linalg.solve(r.covariance, e))
        att.append(math.degrees(np.linalg.norm(e[:3])))
    assert np.mean(d2) / 6 < 3.0, np.mean(d2) / 6
    assert np.sqrt(np.mean(np.square(att))) < 0.25


def _rendered(render, T, seed):
    frame = render(T, seed=seed)
    return frame.gray, frame.distance_mm


def test_the_state_digest_says_when_two_pipelines_will_agree(camera, catalog):
    from tests.conftest import facing_pose, render
    from tofpose.pipeline import PosePipeline

    frames = [render(facing_pose(2500.0, yaw_deg=3.0), seed=s) for s in range(6)]
    a, b = PosePipeline(camera, catalog), PosePipeline(camera, catalog)
    assert a.state_digest() == b.state_digest()
    for f in frames[:4]:
        a.process(f.gray, f.distance_mm)
    for f in frames[2:4]:  # b sees only the last two: its history is shorter
        b.process(f.gray, f.distance_mm)
    assert a.state_digest() != b.state_digest()
    b.reset()  # the same four frames from a reset: the same state ...
    for f in frames[:4]:
        b.process(f.gray, f.distance_mm)
    assert a.state_digest() == b.state_digest()
    ra, rb = (p.process(frames[4].gray, frames[4].distance_mm) for p in (a, b))
    np.testing.assert_array_equal(ra.t_mm, rb.t_mm)  # ... and the same next result
    # the lens blur the tracker keeps (it sets the next frames' centroid-error priors)
    # is part of the state
    before = b.state_digest()
    b._track = replace(b._track, psf_sigma_px=b._track.psf_sigma_px + 0.5)
    assert b.state_digest() != before


def test_history_kept_between_frames_is_the_history_built_afresh():
    """``history`` keeps its newest-first tuples from frame to frame (updated by
    ``commit``): after every commit (with and without motion), ``reset`` and ``restore``
    they hold the same arrays, in the same order, as a Persistence given the same
    entries and asked for the first time, padded with this frame's arrays."""
    rng = np.random.default_rng(2)
    p = Persistence(PersistenceConfig(k_frames=4))

    def fresh(gray, distance):
        q = Persistence(p.config)
        q.restore(p.snapshot())
        return q.history(gray, distance)

    def same(a, b):
        assert a.n_frames == b.n_frames
        for name in ("gray", "distance", "mask", "centroids"):
            got, want = getattr(a, name), getattr(b, name)
            assert len(got) == len(want) == 3, name
            for g, w in zip(got[: a.n_frames], want[: a.n_frames], strict=True):
                assert g is w, name  # the entries' own arrays, newest first
            for g, w in zip(got[a.n_frames :], want[a.n_frames :], strict=True):
                np.testing.assert_array_equal(g, w)  # the padding

    steps = [(False, 0)] * 5 + [(True, 1), (False, 0), (True, 0), (False, 0), (False, 0)]
    for k, (motion, n_used) in enumerate(steps):
        blobs, g, d = _frame(20 + k % 3, 18, rng=rng)
        h = p.history(g, d)
        same(h, fresh(g, d))
        p.commit(np.array([blobs[0].centroid_uv]), blobs[0].pixels, g, d, n_used, motion)
        assert p.history(g, d).n_frames == min(len(p.snapshot()), 3)
        if k == 6:
            saved = p.snapshot()
        if k == 7:
            p.restore(saved)
            assert p.history(g, d).n_frames == len(saved)
    same(p.history(g, d), fresh(g, d))
    p.reset()
    assert p.history(g, d).n_frames == 0
    same(p.history(g, d), fresh(g, d))
