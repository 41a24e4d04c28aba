"""Each systematic range error, programmed alone, is recovered from noiseless rendered
frames: the difference between what the camera reads and the true phasor distance."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from tests.conftest import facing_pose
from tofpose.core.camera import CameraModel
from tofpose.sim.render import SensorModel, render_frame
from tofpose.sim.scene import FIRST_DISC, PLATE, TargetScene
from tofpose.sim.systematic import SystematicErrors

DEFAULTS = SystematicErrors()


def _frame(errors: SystematicErrors, distance_mm: float = 2000.0, time_s: float = 0.0, **kw):
    sensor = SensorModel(noise=False, systematic=errors, supersampling=1)
    return render_frame(
        CameraModel(), TargetScene(), facing_pose(distance_mm, **kw), sensor, None, time_s=time_s
    )


def _error(f) -> np.ndarray:
    return f.distance_mm.astype(float) - f.true_distance_mm


def test_the_ideal_sensor_has_no_systematic_error():
    f = _frame(SystematicErrors.none())
    assert np.nanmax(np.abs(_error(f))) < 1e-3


def test_the_cyclic_error_is_recovered_by_a_harmonic_fit_over_range():
    e = DEFAULTS.only("wiggle")
    u = SensorModel().unambiguous_range_mm
    d_all, err_all = [], []
    for z in np.linspace(1500.0, 1500.0 + u / 4, 9):  # one full period of the 4th harmonic
        f = _frame(e, z)
        plate = (f.surface_id == PLATE) & np.isfinite(f.distance_mm)
        d_all.append(f.true_distance_mm[plate])
        err_all.append(_error(f)[plate])
    d, err = np.concatenate(d_all), np.concatenate(err_all)
    phi = 2 * np.pi * d / u
    A = np.column_stack([np.sin(4 * phi), np.cos(4 * phi), np.sin(8 * phi), np.cos(8 * phi)])
    coef, *_ = np.linalg.lstsq(A, err, rcond=None)
    amps = np.hypot(coef[0::2], coef[1::2])
    np.testing.assert_allclose(amps, e.wiggle_amplitudes_mm, rtol=0.01)
    phases = np.arctan2(coef[1::2], coef[0::2])
    np.testing.assert_allclose(phases, e.wiggle_phases_rad, atol=0.01)


def test_the_amplitude_error_is_recovered_as_a_slope_per_decade():
    e = DEFAULTS.only("amplitude")
    f = _frame(e)
    ok = np.isfinite(f.distance_mm) & (f.amplitude > 1.0)
    x = np.log10(f.amplitude[ok] / e.amplitude_reference_counts)
    slope, _ = np.polyfit(x, _error(f)[ok], 1)
    assert slope == pytest.approx(e.amplitude_mm_per_decade, rel=1e-3)
    # retro-reflector pixels (bright) read differently from the plate (dim)
    disc = (f.surface_id >= FIRST_DISC) & ok
    plate = (f.surface_id == PLATE) & ok
    assert np.median(_error(f)[disc]) < np.median(_error(f)[plate]) - 5.0


def test_the_per_pixel_offsets_are_the_cameras_fixed_pattern():
    e = DEFAULTS.only("pixel")
    a, b = _frame(e, 2000.0), _frame(e, 3000.0, yaw_deg=5.0)
    both = np.isfinite(a.distance_mm) & np.isfinite(b.distance_mm)
    np.testing.assert_allclose(_error(a)[both], _error(b)[both], atol=1e-3)  # same pattern
    expected = e.pixel_offsets_mm(240, 320)
    np.testing.assert_allclose(_error(a)[both], expected[both], atol=1e-3)
    v, u = np.mgrid[0:240, 0:320]
    r2 = ((u - 159.5) ** 2 + (v - 119.5) ** 2) / (159.5**2 + 119.5**2)
    slope, _ = np.polyfit(r2.ravel(), expected.ravel(), 1)  # the smooth radial part
    assert slope == pytest.approx(e.pixel_offset_corner_mm, abs=0.1)
    resid = expected - slope * r2
    assert np.std(resid) == pytest.approx(e.pixel_offset_sigma_mm, rel=0.02)


@pytest.mark.parametrize("time_s", [0.0, 900.0, 9000.0])
def test_the_drift_follows_the_warm_up(time_s):
    e = DEFAULTS.only("drift")
    err = _error(_frame(e, time_s=time_s))
    expected = e.drift_mm_per_kelvin * e.warmup_kelvin * (1 - np.exp(-time_s / e.warmup_tau_s))
    assert np.nanmax(np.abs(err - expected)) < 1e-3


def test_lens_scatter_pulls_the_plate_next_to_a_reflector_towards_its_range():
    e = DEFAULTS.only("scatter")
    f = _frame(e)
    err = _error(f)
    disc = f.surface_id >= FIRST_DISC
    plate = (f.surface_id == PLATE) & np.isfinite(f.distance_mm)
    # plate pixels by their distance (px) to the nearest reflector pixel
    import cv2

    dist_px = cv2.distanceTransform((~disc).astype(np.uint8), cv2.DIST_L2, 5)
    near = plate & (dist_px > 1) & (dist_px < 6)
    far = plate & (dist_px > 40)
    # the reflectors stand 100-150 mm proud of the plate: their light makes the plate
    # nearby read short, by millimetres; far from them it hardly matters
    assert np.median(err[near]) < -2.0
    assert abs(np.median(err[far])) < 0.5 * abs(np.median(err[near]))


def test_the_zero_offset_adds_the_same_distance_to_every_pixel():
    e = replace(SystematicErrors.none(), offset_mm=-17.5)
    err = _error(_frame(e))
    assert np.isfinite(err).sum() > 1000
    assert np.nanmax(np.abs(err + 17.5)) < 1e-3
    assert DEFAULTS.only("offset") == SystematicErrors.none()  # off by default


def test_only_names_the_terms_it_knows():
    with pytest.raises(ValueError, match="unknown error terms"):
        DEFAULTS.only("wobble")
