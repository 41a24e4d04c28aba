"""The compiled window search against OpenCV's labelling on the same windows (the
reference, ``tofpose.stages.tracking.reference.tracking``)."""

from __future__ import annotations

import numpy as np

from tofpose.stages.tracking.kernels.tracking import (
    AT_EDGE,
    FOUND,
    NO_SIZE,
    NOT_FOUND,
    search_windows,
)
from tofpose.stages.tracking.reference import tracking as reference


def _reference(gray, bounds, centres, diameters, threshold):
    """The reference's window search (``reference.tracking.search_windows``: OpenCV's
    8-connected labelling) on the same windows, background 10 counts."""
    return reference.search_windows(gray, bounds, centres, diameters, threshold, 10.0)


def test_search_windows_takes_the_component_opencv_takes():
    rng = np.random.default_rng(0)
    gray = rng.uniform(0, 50, (120, 160)).astype(np.float32)
    v, u = np.mgrid[0:120, 0:160]
    for cu, cv, r in ((40, 40, 5.0), (100, 60, 3.0), (52, 43, 1.5)):  # a glint near disc 1
        gray[(u - cu) ** 2 + (v - cv) ** 2 <= r * r] = 800.0
    bounds = np.array([[28, 53, 28, 53], [90, 111, 50, 71], [0, 10, 0, 10], [37, 44, 30, 50]])
    centres = np.array([[40.0, 40.0], [100.0, 60.0], [5.0, 5.0], [40.0, 40.0]])
    diam = np.array([10.0, 6.0, 4.0, 10.0])
    status, bbox, peak, cen, starts, flat = search_windows(
        gray, bounds, centres, diam, np.float32(400.0), 10.0
    )
    assert status.tolist() == [FOUND, FOUND, NOT_FOUND, AT_EDGE]
    want = _reference(gray, bounds, centres, diam, np.float32(400.0))
    np.testing.assert_array_equal(status, want[0])
    np.testing.assert_array_equal(starts, want[4])
    for j in (0, 1):
        want_px = want[5][want[4][j] : want[4][j + 1]]
        np.testing.assert_array_equal(bbox[j], want[1][j])
        np.testing.assert_array_equal(flat[starts[j] : starts[j + 1]], want_px)
        np.testing.assert_allclose(cen[j], want[3][j], atol=1e-9)
        assert peak[j] == want[2][j] == 800.0
    tiny = search_windows(gray, bounds[:1], centres[:1], np.array([40.0]), np.float32(400.0), 10.0)
    assert tiny[0][0] == NO_SIZE  # a 40 px disc predicted, only a 10 px one there


def test_search_windows_on_random_speckle_and_merging_shapes_equals_opencv():
    """Components that only join further down (U, comb and diagonal shapes: the run
    union-find must merge them) among random speckle: the same pick, box and pixels as
    OpenCV's 8-connected labelling."""
    rng = np.random.default_rng(7)
    checked = 0
    for _ in range(150):
        gray = rng.uniform(0, 50, (90, 120)).astype(np.float32)
        gray[rng.random(gray.shape) < 0.08] = 900.0  # speckle
        v, u = np.mgrid[0:90, 0:120]
        cu, cv = rng.uniform(30, 90), rng.uniform(25, 65)
        shape = rng.integers(0, 3)
        if shape == 0:  # a U: two prongs joined at the bottom
            gray[int(cv) - 8 : int(cv) + 6, int(cu) - 6 : int(cu) - 3] = 900.0
            gray[int(cv) - 8 : int(cv) + 6, int(cu) + 3 : int(cu) + 6] = 900.0
            gray[int(cv) + 6 : int(cv) + 8, int(cu) - 6 : int(cu) + 6] = 900.0
        elif shape == 1:  # a diagonal staircase (8-connected only)
            for k in range(-7, 8):
                gray[int(cv) + k, int(cu) + k] = 900.0
        else:  # a comb: teeth joined by a bar at the bottom
            for k in range(-6, 7, 3):
                gray[int(cv) - 6 : int(cv) + 6, int(cu) + k] = 900.0
            gray[int(cv) + 6, int(cu) - 6 : int(cu) + 7] = 900.0
        gray[(u - cu) ** 2 + (v - cv) ** 2 <= 4.0] = 900.0  # a small disc in the middle
        u0, v0 = int(cu) - 16, int(cv) - 16
        bounds = np.array([[u0, u0 + 33, v0, v0 + 33]])
        diam = np.array([rng.uniform(4.0, 14.0)])
        centre = np.array([[cu + rng.normal(0, 2), cv + rng.normal(0, 2)]])
        status, bbox, _, _, starts, flat = search_windows(
            gray, bounds, centre, diam, np.float32(400.0), 10.0
        )
        want = _reference(gray, bounds, centre, diam, np.float32(400.0))
        assert status[0] == want[0][0]
        if status[0] != FOUND:
            assert status[0] in (NO_SIZE, AT_EDGE)
            continue
        np.testing.assert_array_equal(bbox[0], want[1][0])
        np.testing.assert_array_equal(flat[starts[0] : starts[1]], want[5])
        checked += 1
    assert checked > 50


def test_windows_share_a_pixel_exactly_when_their_lists_intersect():
    from tofpose.stages.tracking.kernels.tracking import any_shared

    rng = np.random.default_rng(7)
    w = 40
    for _ in range(300):
        lists = []
        for _ in range(rng.integers(2, 5)):  # random blobs in random boxes, some overlapping
            x, y = rng.integers(0, 30, 2)
            bw, bh = rng.integers(1, 10, 2)
            rows, cols = np.mgrid[y : y + bh, x : x + bw]
            keep = rng.random(rows.size) < 0.5
            keep[0] = True
            lists.append(np.sort((rows.ravel() * w + cols.ravel())[keep]))
        flat = np.concatenate(lists).astype(np.int64)
        starts = np.cumsum([0] + [len(v) for v in lists]).astype(np.int64)
        bbox = np.array(
            [[(v % w).min(), (v // w).min(), np.ptp(v % w) + 1, np.ptp(v // w) + 1] for v in lists],
            np.int64,
        )
        want = reference.any_shared(flat, starts, bbox)
        assert any_shared(flat, starts, bbox) == want
