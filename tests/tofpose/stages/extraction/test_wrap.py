import numpy as np
import pytest

from tofpose.config import ExtractionConfig
from tofpose.core.tof import unambiguous_range_mm
from tofpose.stages.extraction.extraction import WrongSizeBlob, predicted_diameter_window_px
from tofpose.stages.extraction.wrap import (
    MIN_DISC_PX,
    max_reading_mm,
    readings_beyond,
    suggested_ranges_mm,
    unwrap_about,
)

U_MM = unambiguous_range_mm(20.0)  # 7494.8 mm
FX = 650.0
DIAMETERS = np.array([35.0, 80.0])
CONFIG = ExtractionConfig()
LIMIT_MM = 650.0 * 80.0 / 1.5  # max_reading_mm at 650 px for the paper target


def _refused(true_range_mm: float, read_mm: float, diameters_mm=(35.0, 80.0, 80.0, 35.0)):
    """Components of the catalog's face-on sizes at ``true_range_mm`` whose distance reads
    ``read_mm``, as the size window at ``read_mm`` refuses them."""
    low, high = predicted_diameter_window_px(FX, read_mm, DIAMETERS, CONFIG)
    out = []
    for d in diameters_mm:
        size = FX * d / true_range_mm
        assert not low <= size <= high  # the window refuses it where it reads
        out.append(WrongSizeBlob(size, low, high, read_mm))
    return out


def test_unwrap_about_adds_the_whole_unambiguous_ranges_nearest_the_range():
    d = np.array([[505.0, np.nan], [7000.0, 1200.0]], np.float32)
    out = unwrap_about(d, 8000.0, U_MM)
    assert out.dtype == np.float32
    np.testing.assert_allclose(out[0, 0], 505.0 + U_MM, rtol=1e-6)
    assert np.isnan(out[0, 1])
    assert out[1, 0] == 7000.0  # nearer 8 m as it is than with 7.49 m more
    np.testing.assert_allclose(out[1, 1], 1200.0 + U_MM, rtol=1e-6)
    # two ranges further, and never fewer than none
    np.testing.assert_allclose(unwrap_about(np.array([300.0]), 15_500.0, U_MM), 300.0 + 2 * U_MM)
    assert unwrap_about(np.array([7000.0]), 1000.0, U_MM)[0] == 7000.0


@pytest.mark.parametrize("true_range_mm", [8000.0, 8500.0])
def test_refused_components_name_the_range_their_sizes_fit(true_range_mm):
    read = true_range_mm - U_MM
    found = suggested_ranges_mm(
        _refused(true_range_mm, read), FX, DIAMETERS, CONFIG, U_MM, 3, LIMIT_MM
    )
    assert [(s.wraps, s.fitting) for s in found] == [(1, 4)]
    assert found[0].about_mm == pytest.approx(true_range_mm, rel=1e-9)


def test_every_reading_the_size_window_allows_is_offered_fewest_wraps_first():
    """At 16 m (two ranges on) the sizes are inside the window at 8.5 m and 23.5 m too
    (the window's floor is a pixel): all are offered, the nearest first (matching
    against the catalog's geometry decides)."""
    read = 16_000.0 - 2 * U_MM
    found = suggested_ranges_mm(_refused(16_000.0, read), FX, DIAMETERS, CONFIG, U_MM, 3, LIMIT_MM)
    assert [s.wraps for s in found] == [1, 2, 3]
    assert found[1].about_mm == pytest.approx(16_000.0, rel=1e-9)
    # not past where the largest disc is MIN_DISC_PX across: on the EPC660's 325 px lens
    # (17.3 m) the 23.5 m reading is not offered
    nearer = suggested_ranges_mm(_refused(16_000.0, read), FX, DIAMETERS, CONFIG, U_MM, 3, 20_000.0)
    assert [s.wraps for s in nearer] == [1, 2]


def test_a_reading_too_far_is_taken_back():
    """Read one unambiguous range too far (the target came nearer than an earlier
    reading): its 80 mm discs are too large there, and fit one range nearer."""
    refused = _refused(7000.0, 7000.0 + U_MM, diameters_mm=(80.0,) * 4)
    found = suggested_ranges_mm(refused, FX, DIAMETERS, CONFIG, U_MM, 3, LIMIT_MM)
    assert found[0].wraps == -1
    assert found[0].about_mm == pytest.approx(7000.0)


def test_no_reading_without_enough_components_or_a_wrap():
    refused = _refused(8000.0, 8000.0 - U_MM)
    assert suggested_ranges_mm(refused[:2], FX, DIAMETERS, CONFIG, U_MM, 3, LIMIT_MM) == []
    assert suggested_ranges_mm(refused, FX, DIAMETERS, CONFIG, np.inf, 3, LIMIT_MM) == []
    assert suggested_ranges_mm([], FX, DIAMETERS, CONFIG, U_MM, 3, LIMIT_MM) == []
    # sizes the catalog has at no reading: far too large wherever they are put
    low, high = predicted_diameter_window_px(FX, 500.0, DIAMETERS, CONFIG)
    huge = [WrongSizeBlob(10 * high, low, high, 500.0)] * 4
    assert suggested_ranges_mm(huge, FX, DIAMETERS, CONFIG, U_MM, 3, LIMIT_MM) == []
    # a minority that fits does not decide (a component without a distance is not
    # counted either way)
    no_distance = [WrongSizeBlob(3.0, low, high, np.nan)]
    mixed = refused[:3] + [WrongSizeBlob(10 * high, low, high, refused[0].distance_mm)] * 4
    assert suggested_ranges_mm(mixed + no_distance, FX, DIAMETERS, CONFIG, U_MM, 3, LIMIT_MM) == []


def test_readings_beyond_the_candidates_stop_where_the_discs_would_vanish():
    """Candidates that match nothing where they read: 1-3 ranges further (and nearer,
    where that is above 0: a frame read too far), as far as the catalog's largest disc
    stays MIN_DISC_PX across (650 px, 80 mm: 34.7 m)."""
    limit = max_reading_mm(FX, DIAMETERS)
    assert limit == pytest.approx(FX * 80.0 / MIN_DISC_PX)
    found = readings_beyond(np.array([2400.0, 2500.0, 2600.0]), U_MM, limit)
    assert [s.wraps for s in found] == [1, 2, 3]
    assert [s.about_mm for s in found] == pytest.approx([2500.0 + n * U_MM for n in (1, 2, 3)])
    assert [s.wraps for s in readings_beyond(np.array([2500.0]), U_MM, 20_000.0)] == [1, 2]
    # read about 8 m, the target came back to 1 m: it reads 8.5 m
    back = readings_beyond(np.array([1000.0 + U_MM]), U_MM, limit)
    assert [s.wraps for s in back] == [1, -1, 2, 3]
    assert back[1].about_mm == pytest.approx(1000.0)
    # the EPC660 at 6 MHz: its 25 m unambiguous range is past where its discs vanish
    epc_limit = max_reading_mm(325.0, DIAMETERS)
    assert readings_beyond(np.array([500.0]), unambiguous_range_mm(6.0), epc_limit) == []
    assert readings_beyond(np.array([2500.0]), np.inf, limit) == []
    assert readings_beyond(np.array([]), U_MM, limit) == []
