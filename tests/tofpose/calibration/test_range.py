"""The range-correction fit recovers the simulator's programmed range errors from a
calibration set of frames of the known target at known poses."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import facing_pose
from tofpose.calibration.range import (
    RangeCorrection,
    fit_range_correction,
)
from tofpose.core.camera import CameraModel
from tofpose.core.catalog import paper_target
from tofpose.sim.calibration_run import EXPOSURE_FRACTIONS, calibration_frames
from tofpose.sim.render import SensorModel, render_frame
from tofpose.sim.scene import FIRST_DISC, TargetScene
from tofpose.sim.systematic import SystematicErrors

CAM = CameraModel()


def _calibration_set(errors: SystematicErrors, n_per_pose: int = 3, seed: int = 1):
    """Frames at 1.2-8 m (more than a period of the 4th harmonic, U / 4 = 6.2 m) with small
    attitudes and lateral offsets, as a rail and turntable run gives them, each pose at
    three integration times (1, 1/3, 1/10 of auto exposure): the reflectors' amplitude
    then spans a decade at the same distance, which separates the amplitude-related
    error from the others (the black plate is too dim and noisy to help)."""
    poses = [
        facing_pose(z, pitch_deg=p, yaw_deg=y, offset_mm=(ox, oy))
        for z in np.linspace(1200.0, 8000.0, 25)
        for p, y, ox, oy in ((0, 0, 0, 0), (4, -5, 150, -80), (-3, 6, -200, 60))
    ]
    fractions = tuple(EXPOSURE_FRACTIONS[k % 3] for k in range(n_per_pose))
    return calibration_frames(
        CAM,
        paper_target(),
        errors,
        poses,
        np.random.default_rng(seed),
        exposure_fractions=fractions,
    )


def test_the_fit_recovers_the_cyclic_amplitude_and_pixel_errors():
    e = SystematicErrors().only("wiggle", "amplitude", "pixel")
    u = SensorModel().unambiguous_range_mm
    fit = fit_range_correction(_calibration_set(e), u)
    c = fit.correction
    amps = [np.hypot(s, co) for s, co in c.harmonics_mm]
    np.testing.assert_allclose(amps, e.wiggle_amplitudes_mm, rtol=0.1, atol=0.3)
    phases = [np.arctan2(co, s) for s, co in c.harmonics_mm]
    np.testing.assert_allclose(phases, e.wiggle_phases_rad, atol=0.2)
    assert c.amplitude_mm_per_decade == pytest.approx(e.amplitude_mm_per_decade, rel=0.15)
    # it records the distances it used: the reflectors' pixels of a run whose target
    # origin stood at 1.2-8 m (its markers stand in front of the origin, and the dimmest
    # pixels of the far poses fall below the amplitude cut)
    near, far = c.calibrated_span_mm
    assert 900 < near < 1200 and 7000 < far < 8100, c.calibrated_span_mm
    assert c.covers(3000.0) and not c.covers(700.0) and not c.covers(9000.0)
    # The per-pixel map follows the programmed fixed pattern where the reflectors were
    # seen often and brightly enough to fix it (up to the mean, held by the constant).
    truth = e.pixel_offsets_mm(240, 320)
    seen = c.pixel_offsets_mm != 0
    assert seen.sum() == fit.pixels_with_offset > 1500
    r = np.corrcoef(c.pixel_offsets_mm[seen], truth[seen])[0, 1]
    assert r > 0.75, r
    # On a new noiseless frame the correction removes most of the systematic error on
    # the reflectors' pixels.
    T = facing_pose(3000.0, yaw_deg=3.0)
    f = render_frame(CAM, TargetScene(), T, SensorModel(noise=False, systematic=e), None)
    disc = (f.surface_id >= FIRST_DISC) & np.isfinite(f.distance_mm)
    idx = np.flatnonzero(disc)
    before = f.distance_mm.ravel()[idx] - f.true_distance_mm.ravel()[idx]
    after = before - c.error_mm(f.distance_mm.ravel()[idx], f.gray.ravel()[idx], idx)
    rms = lambda x: float(np.sqrt(np.mean(x**2)))  # noqa: E731
    # what stays is mostly the random per-pixel part where the run did not pin it
    assert rms(after) < 0.35 * rms(before), (rms(before), rms(after))


def test_a_correction_survives_its_json_form():
    c = RangeCorrection(
        24_982.0,
        3.5,
        ((1.0, -2.0), (0.5, 0.25)),
        -6.0,
        pixel_offsets_mm=np.arange(12.0).reshape(3, 4) / 7,
        calibrated_span_mm=(900.0, 6000.0),
    )
    back = RangeCorrection.from_dict(c.to_dict())
    assert back.calibrated_span_mm == (900.0, 6000.0)
    d, a, i = np.array([1000.0, 5000.0]), np.array([50.0, 3000.0]), np.array([0, 11])
    np.testing.assert_allclose(back.error_mm(d, a, i), c.error_mm(d, a, i), atol=0.01)
    with pytest.raises(ValueError, match="lacks 'offset_mm'"):
        RangeCorrection.from_dict({"unambiguous_range_mm": 1.0})
    for bad in ([5000.0, 900.0], [900.0], "900-6000"):
        with pytest.raises(ValueError, match="calibrated_span_mm"):
            RangeCorrection.from_dict({**c.to_dict(), "calibrated_span_mm": bad})
    # a file written before spans were recorded covers every range
    legacy = {k: v for k, v in c.to_dict().items() if k != "calibrated_span_mm"}
    assert RangeCorrection.from_dict(legacy).covers(100_000.0)


def test_fitting_nothing_is_refused_with_a_reason():
    empty = np.full((240, 320), np.nan)
    with pytest.raises(ValueError, match="no pixel with a known true distance"):
        fit_range_correction([(empty, empty, empty)], 24_982.0)
