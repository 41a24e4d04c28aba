"""Which blobs have a pixel at the camera's full scale (``extraction.saturation``)."""

import numpy as np
import pytest

from tofpose.stages.extraction.extraction import Blob
from tofpose.stages.extraction.saturation import blobs_at_full_scale, pixels_at_full_scale

FULL_SCALE = 4095


def _gray_with(values_at: dict[int, int], shape=(4, 5)) -> np.ndarray:
    gray = np.full(shape, 100, np.uint16)
    for flat_index, value in values_at.items():
        gray.ravel()[flat_index] = value
    return gray


def test_a_blob_is_saturated_exactly_when_one_of_its_pixels_reaches_full_scale():
    # blob 0: pixels 0-2 (one at full scale); blob 1: pixels 5-7 (one a count below);
    # blob 2: empty; blob 3: pixels 10-11 (one above full scale: a 16-bit container)
    gray = _gray_with({1: FULL_SCALE, 6: FULL_SCALE - 1, 11: FULL_SCALE + 10, 15: FULL_SCALE})
    flat = np.array([0, 1, 2, 5, 6, 7, 10, 11])
    starts = np.array([0, 3, 6, 6, 8])
    got = pixels_at_full_scale(gray, flat, starts, full_scale_counts=FULL_SCALE)
    np.testing.assert_array_equal(got, [True, False, False, True])


def test_the_full_scale_is_the_cameras_not_a_12_bit_constant():
    gray = _gray_with({0: 4095, 7: 16383})
    flat, starts = np.array([0, 7]), np.array([0, 1, 2])
    twelve = pixels_at_full_scale(gray, flat, starts, full_scale_counts=4095)
    fourteen = pixels_at_full_scale(gray, flat, starts, full_scale_counts=16383)
    np.testing.assert_array_equal(twelve, [True, True])
    np.testing.assert_array_equal(fourteen, [False, True])


def test_blobs_are_read_through_their_own_pixel_lists():
    gray = _gray_with({3: FULL_SCALE})
    blobs = [
        Blob(pixels=np.array([2, 3]), area_px=2, bbox=(2, 0, 2, 1)),
        Blob(pixels=np.array([12, 13]), area_px=2, bbox=(2, 2, 2, 1)),
    ]
    got = blobs_at_full_scale(gray, blobs, full_scale_counts=FULL_SCALE)
    np.testing.assert_array_equal(got, [True, False])
    assert blobs_at_full_scale(gray, [], full_scale_counts=FULL_SCALE).shape == (0,)


@pytest.mark.parametrize(
    ("gray", "flat", "starts", "full_scale", "message"),
    [
        (np.zeros(20), [0], [0, 1], FULL_SCALE, "(H, W) image"),
        (np.zeros((4, 5)), [0], [0, 1], 0.0, "full_scale_counts must be positive"),
        (np.zeros((4, 5)), [0, 1], [0, 1], FULL_SCALE, "from 0 to the 2 pixel indices"),
        (np.zeros((4, 5)), [0, 1], [1, 2], FULL_SCALE, "from 0 to the 2 pixel indices"),
        (np.zeros((4, 5)), [0, 1], [0, 2, 1, 2], FULL_SCALE, "non-decreasing"),
        (np.zeros((4, 5)), [0, 20], [0, 2], FULL_SCALE, "lie in the (4, 5) image"),
    ],
)
def test_bad_input_names_the_problem(gray, flat, starts, full_scale, message):
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")):
        pixels_at_full_scale(gray, np.array(flat), np.array(starts), full_scale_counts=full_scale)
