"""The shipped camera profiles: what each states, and the errors of a bad one."""

import json
import math

import pytest

from tofpose.core.camera import CameraModel
from tofpose.core.camera_profiles import (
    REQUIRED_KEYS,
    load_profile,
    parse_profile,
    profile_names,
    profile_text,
)
from tofpose.core.tof import unambiguous_range_mm


def test_three_profiles_ship_and_the_tofcam660_is_todays_default_camera():
    assert profile_names() == ("azure-kinect-nfov", "hololens2-ahat", "tofcam660")
    assert load_profile("tofcam660") == CameraModel()
    assert load_profile("tofcam660").unambiguous_range_mm == pytest.approx(
        unambiguous_range_mm(6.0)
    )


def test_azure_kinect_nfov_is_its_published_mode():
    cam = load_profile("azure-kinect-nfov")
    assert (cam.width, cam.height) == (640, 576)
    hfov = 2 * math.degrees(math.atan(cam.width / 2 / cam.fx))
    vfov = 2 * math.degrees(math.atan(cam.height / 2 / cam.fy))
    assert (hfov, vfov) == (pytest.approx(75.0, abs=0.01), pytest.approx(65.0, abs=0.01))
    assert cam.distance_kind == "z" and cam.depth_unit_mm == 1.0 and cam.depth_invalid_code == 0
    assert cam.full_scale_counts == 65535.0  # 16-bit IR
    assert cam.unambiguous_range_mm == 3860.0  # the mode's operating range


def test_hololens2_ahat_wraps_at_one_metre_and_reads_radial():
    cam = load_profile("hololens2-ahat")
    assert (cam.width, cam.height) == (512, 512)
    assert cam.unwrapped_range_mm is None  # one frequency: c / (2 f)
    assert cam.unambiguous_range_mm == pytest.approx(1000.0, abs=1e-6)
    assert cam.distance_kind == "radial" and cam.depth_max_valid_code == 4089


@pytest.mark.parametrize("name", ["tofcam660", "azure-kinect-nfov", "hololens2-ahat"])
def test_each_profile_is_a_camera_json_that_round_trips(name):
    cam = load_profile(name)
    assert CameraModel.from_json(profile_text(name)) == cam  # any camera JSON reader reads it
    assert CameraModel.from_json(cam.to_json()) == cam
    doc = json.loads(profile_text(name))
    assert doc["profile"] == name and doc["source"]


def test_an_unknown_profile_name_lists_the_valid_ones():
    with pytest.raises(
        ValueError,
        match="unknown camera profile 'kinect'; choose one of "
        "azure-kinect-nfov, hololens2-ahat, tofcam660",
    ):
        load_profile("kinect")


def _doc(**changes):
    doc = json.loads(profile_text("azure-kinect-nfov"))
    doc.update(changes)
    return doc


@pytest.mark.parametrize(
    "key",
    ["fx", "full_scale_counts", "count_scale", "distance_kind", "depth_invalid_code", "source"],
)
def test_a_profile_missing_a_field_names_it(key):
    doc = _doc()
    del doc[key]
    with pytest.raises(ValueError, match=f"camera profile x is missing {key}$"):
        parse_profile(json.dumps(doc), where="camera profile x")


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"distance_knd": "z"}, "unknown keys distance_knd"),
        ({"distance_kind": "depth"}, "distance_kind must be one of radial, z, got 'depth'"),
        ({"fx": "wide"}, "camera fx must be float, got 'wide'"),
        ({"count_scale": 0}, "count_scale must be positive"),
        ({"unwrapped_range_mm": -1.0}, "unwrapped_range_mm must be positive"),
        ({"depth_unit_mm": 0}, "depth_unit_mm must be positive"),
        ({"dist": [0, 0]}, "5 coefficients"),
    ],
)
def test_a_bad_profile_field_is_named(changes, message):
    with pytest.raises(ValueError, match=message):
        parse_profile(json.dumps(_doc(**changes)))


def test_a_profile_that_is_not_json_or_not_an_object_is_named():
    with pytest.raises(ValueError, match="camera profile is not valid JSON"):
        parse_profile("{")
    with pytest.raises(ValueError, match="must be a JSON object"):
        parse_profile("[1]")
    assert len(REQUIRED_KEYS) == len(set(REQUIRED_KEYS))
