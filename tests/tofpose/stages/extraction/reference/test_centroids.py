"""The reference statement of Eqs. 19-20 against known truth."""

from __future__ import annotations

import numpy as np

from tofpose.stages.extraction.reference.centroids import blob_centroid, blob_range, surround_level


def test_a_uniform_square_on_a_flat_surround_is_centred_exactly():
    """A sharp 5 x 5 square (a plateau: coverage weights) and a 2 x 2 one (no plateau:
    intensity weights) on a level of 40: centroids at their centres, the surround's
    level read from the ring."""
    g = np.full((40, 40), 40.0, np.float32)
    g[10:15, 10:15] = 900.0
    g[30:32, 20:22] = 500.0
    w = g.shape[1]
    for rows, cols, centre in (
        ((10, 15), (10, 15), (12.0, 12.0)),
        ((30, 32), (20, 22), (20.5, 30.5)),
    ):
        r, c = np.mgrid[rows[0] : rows[1], cols[0] : cols[1]]
        pixels = (r * w + c).ravel()
        bbox = (cols[0], rows[0], cols[1] - cols[0], rows[1] - rows[0])
        level = surround_level(g, bbox)
        assert level == 40.0
        np.testing.assert_allclose(blob_centroid(g, pixels, bbox, level), centre, atol=1e-12)


def test_the_range_is_the_median_projection_on_the_centroid_line_of_sight():
    """Pixels of a plane facing the camera at 3 m read ranges 3000 / cos(angle); their
    projections on the centre's line of sight are the plane's distance along it."""
    h, w = 20, 20
    v, u = np.mgrid[0:h, 0:w].astype(float)
    rays = np.dstack(((u - 10.0) / 300.0, (v - 10.0) / 300.0, np.ones((h, w))))
    bearings = rays / np.linalg.norm(rays, axis=2, keepdims=True)
    distance = 3000.0 / bearings[..., 2]
    pixels = np.array([10 * w + 10, 10 * w + 11, 11 * w + 10, 11 * w + 11])
    centre = bearings[10, 10]
    want = np.median(distance.ravel()[pixels] * (bearings.reshape(-1, 3)[pixels] @ centre))
    assert blob_range(distance, pixels, bearings, centre) == want
    assert abs(blob_range(distance, pixels[:1], bearings, centre) - 3000.0) < 1e-9
