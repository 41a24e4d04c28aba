"""The persistence kernels against NumPy."""

from __future__ import annotations

import numpy as np

from tofpose.stages.persistence.kernels.persistence import (
    column_medians,
    consistent,
    counter_medians,
    gather_stack,
    mean_in_boxes,
    medians_and_counts_at,
    pixel_mask,
    ranges_consistent,
)


def test_column_medians_equal_nanmedian():
    rng = np.random.default_rng(0)
    for k in (1, 2, 3, 4, 5):
        stack = rng.normal(2000, 5, (k, 300)).astype(np.float32)
        stack[rng.random((k, 300)) < 0.2] = np.nan
        want = np.full(300, np.nan, np.float32)
        some = ~np.all(np.isnan(stack), axis=0)
        want[some] = np.nanmedian(stack[:, some], axis=0)
        np.testing.assert_array_equal(column_medians(stack), want)
    # five frames without NaNs go through the sorting network only; with ties
    full = np.round(rng.normal(2000, 2, (5, 1000))).astype(np.float32)
    np.testing.assert_array_equal(column_medians(full), np.median(full, axis=0))


def test_medians_and_counts_at_the_pixels_equal_the_stacked_ones():
    rng = np.random.default_rng(3)
    for k_frames in (2, 3, 5, 6):  # tuples shorter than five frames compile too
        frames = tuple(rng.normal(700, 3, (20, 30)).astype(np.float32) for _ in range(k_frames))
        for f in frames:
            f[rng.random(f.shape) < 0.15] = np.nan
        masks = tuple(rng.random(600) < 0.6 for _ in range(k_frames - 1))
        flat = np.sort(rng.choice(600, 250, replace=False)).astype(np.int64)
        for n_older in range(k_frames):
            out = np.full((20, 30), -1.0, np.float32)
            counts = medians_and_counts_at(frames, masks, n_older, flat, out)
            want = np.full(250, np.nan, np.float32)
            stack = np.array([f.ravel()[flat] for f in frames[: 1 + n_older]])
            some = ~np.all(np.isnan(stack), axis=0)
            want[some] = np.nanmedian(stack[:, some], axis=0)
            np.testing.assert_array_equal(out.ravel()[flat], want)
            untouched = np.setdiff1d(np.arange(600), flat)
            assert (out.ravel()[untouched] == -1).all()
            want_counts = 1 + sum(m[flat].astype(int) for m in masks[:n_older])
            np.testing.assert_array_equal(counts, want_counts)


def test_consistency_gate():
    a = np.array([[10.0, 10.0], [50.0, 40.0], [90.0, 20.0]])
    assert consistent(a, a + 0.1, 0.35)
    assert not consistent(a, a + 1.0, 0.35)  # moved a pixel
    assert consistent(a[:2], a, 0.35)  # a blob more in the older frame
    assert not consistent(a, np.empty((0, 2)), 0.35)
    # a part split from a merged pair has no centroid yet: it takes no part
    with_split = np.vstack((a, [[np.nan, np.nan]]))
    assert consistent(with_split, with_split + 0.1, 0.35)
    assert not consistent(with_split, with_split + 1.0, 0.35)


def test_means_counts_and_stacks_use_only_the_counted_frames():
    rng = np.random.default_rng(1)
    frames = [rng.uniform(0, 100, (20, 30)).astype(np.float32) for _ in range(4)]
    boxes = np.array([[5, 5, 4, 3]], np.int64)
    out = mean_in_boxes(frames[0], (frames[1], frames[2], frames[0]), 2, boxes, frames[0].copy())
    sl = np.s_[3:10, 3:11]
    np.testing.assert_array_equal(out[sl], (frames[0][sl] + (frames[1][sl] + frames[2][sl])) / 3)
    np.testing.assert_array_equal(out[0, :], frames[0][0, :])  # outside the box: this frame
    masks = [rng.random(600) < 0.5 for _ in range(3)]
    flat = np.arange(0, 600, 7, dtype=np.int64)
    starts = np.array([0, 40, len(flat)], np.int64)
    got = counter_medians((*masks, masks[0]), 3, flat, starts)
    count = sum(m[flat].astype(int) for m in masks)
    np.testing.assert_array_equal(got, [np.median(count[:40]), np.median(count[40:])])
    stack = gather_stack((frames[3], frames[1], frames[3]), 2, flat[:20])
    np.testing.assert_array_equal(
        stack, [frames[3].ravel()[flat[:20]], frames[1].ravel()[flat[:20]]]
    )


def test_the_counting_median_is_numpys_median():
    from tofpose.stages.persistence.kernels.persistence import median_of_counts

    rng = np.random.default_rng(4)
    for m in (1, 2, 3, 4, 7, 10, 51):
        for _ in range(20):
            v = rng.integers(0, 6, m)
            assert median_of_counts(np.bincount(v, minlength=6), m) == np.median(v)


def test_the_pixel_mask_holds_exactly_the_listed_pixels():
    flat = np.array([0, 5, 6, 7, 599, 5], np.int64)  # a repeat is harmless
    want = np.zeros(600, bool)
    want[flat] = True
    np.testing.assert_array_equal(pixel_mask(flat, 600), want)
    assert not pixel_mask(np.empty(0, np.int64), 600).any()


def _blob_ranges(rng, n_blobs, n_pix, shift_mm, sigma_mm=4.0, base_mm=3000.0):
    """Two distance frames (flat, float32) of ``n_blobs`` blobs of ``n_pix`` pixels with
    Gaussian noise; the second frame's blob j is ``shift_mm[j]`` nearer."""
    size = n_blobs * n_pix
    a = (base_mm + rng.normal(0, sigma_mm, size)).astype(np.float32)
    b = (base_mm + rng.normal(0, sigma_mm, size)).astype(np.float32)
    b -= np.repeat(np.asarray(shift_mm, np.float32), n_pix)
    return a, b, np.arange(size, dtype=np.int64), np.arange(0, size + 1, n_pix, dtype=np.int64)


def test_ranges_consistent_keeps_static_frames_and_cuts_moving_markers():
    """Static: consistent in nearly every pair (the test is at 0.999); the markers
    moving by 4 standard errors of their median difference (a target turning a
    fraction of a degree a frame at 3 m): cut; one blob alone far off (a blob's heavy
    tail): not cut; too few pixels or none valid: nothing to test, consistent."""
    rng = np.random.default_rng(4)
    z = 3.09
    static = [ranges_consistent(*_blob_ranges(rng, 8, 40, np.zeros(8)), z) for _ in range(500)]
    assert np.mean(static) >= 0.99
    se = 1.2533 * 4.0 * np.sqrt(2.0) / np.sqrt(40)  # the median difference's standard error
    moving = [
        ranges_consistent(*_blob_ranges(rng, 8, 40, 4 * se * np.linspace(-1, 1, 8)), z)
        for _ in range(200)
    ]
    assert np.mean(moving) <= 0.05
    one_off = np.zeros(8)
    one_off[3] = 30 * se
    assert (
        np.mean([ranges_consistent(*_blob_ranges(rng, 8, 40, one_off), z) for _ in range(200)])
        >= 0.95
    )
    a, b, flat, starts = _blob_ranges(rng, 8, 4, np.full(8, 50.0))  # 4 pixels a blob
    assert ranges_consistent(a, b, flat, starts, z)
    b[:] = np.nan
    assert ranges_consistent(a, b, flat, starts, z)
