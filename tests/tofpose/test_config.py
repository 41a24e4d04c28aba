"""``config_for_camera``: the pixel- and count-valued settings follow the camera."""

import pytest

from tofpose.config import ExtractionConfig, PipelineConfig, config_for_camera
from tofpose.core.camera import CameraModel
from tofpose.core.camera_profiles import load_profile


def _for(config, camera):
    return config_for_camera(
        config, width=camera.width, height=camera.height, count_scale=camera.count_scale
    )


def test_the_epc660_keeps_the_configuration_as_it_is():
    for config in (PipelineConfig(), PipelineConfig.paper()):
        assert _for(config, CameraModel()) is config


def test_a_larger_16_bit_frame_scales_the_cap_and_the_count_thresholds():
    config = _for(PipelineConfig(), load_profile("azure-kinect-nfov"))  # 640 x 576, x16
    assert config.extraction.n_max == 12000 * 640 * 576 // (320 * 240) == 57600
    assert config.extraction.min_contrast_counts == 25.0 * 16
    assert config.extraction.raw_threshold_abs is None
    base = ExtractionConfig()
    assert config.extraction.raw_threshold_rel == base.raw_threshold_rel  # relative: kept
    assert config.refinement == PipelineConfig().refinement
    paper = _for(PipelineConfig.paper(), load_profile("hololens2-ahat"))  # 512 x 512, x16
    assert paper.extraction.peak_abs == 155.0 * 16
    assert paper.extraction.nlog_floor_abs == pytest.approx(-185.58 * 16)
    assert paper.extraction.n_max == round(12000 * 512 * 512 / (320 * 240))


def test_a_bad_camera_size_or_scale_is_named():
    with pytest.raises(ValueError, match="0 x 240, count scale 1"):
        config_for_camera(PipelineConfig(), width=0, height=240, count_scale=1)
    with pytest.raises(ValueError, match="count scale 0"):
        config_for_camera(PipelineConfig(), width=320, height=240, count_scale=0)
