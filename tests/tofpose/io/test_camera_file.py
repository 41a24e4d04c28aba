"""``--camera``: a shipped profile's name or a camera JSON file."""

import json

import pytest

from tofpose.core.camera import CameraModel
from tofpose.core.camera_profiles import load_profile, profile_text
from tofpose.io.camera_file import camera_from_arg, load_camera, read_camera_text


def test_a_profile_name_or_a_camera_json_path(tmp_path):
    assert camera_from_arg("hololens2-ahat") == load_profile("hololens2-ahat")
    path = tmp_path / "cam.json"
    path.write_text(CameraModel(fx=300.0, name="mine").to_json())
    assert camera_from_arg(str(path)) == CameraModel(fx=300.0, name="mine")
    # a profile with the calibrations' additions still reads as one
    doc = {**json.loads(profile_text("tofcam660")), "range_correction": None}
    path.write_text(json.dumps(doc))
    assert load_camera(path.read_text())[0] == CameraModel()


def test_neither_a_file_nor_a_profile_lists_the_profiles(tmp_path):
    with pytest.raises(
        SystemExit,
        match="neither a camera JSON file nor a camera profile "
        r"\(azure-kinect-nfov, hololens2-ahat, tofcam660\)",
    ):
        read_camera_text("kinect")
    with pytest.raises(SystemExit, match="cannot read camera .*missing.json"):
        read_camera_text(str(tmp_path / "missing.json"))


@pytest.mark.parametrize("key", ["distance_kind", "fx", "count_scale"])
def test_a_profile_file_missing_a_field_names_it(tmp_path, key):
    doc = json.loads(profile_text("azure-kinect-nfov"))
    del doc[key]
    path = tmp_path / "my-kinect.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(SystemExit, match=f"camera profile azure-kinect-nfov is missing {key}$"):
        camera_from_arg(str(path))


def test_a_camera_file_that_is_not_a_camera_is_named(tmp_path):
    path = tmp_path / "cam.json"
    for text, message in (("{", "not valid JSON"), ("[]", "must be an object")):
        path.write_text(text)
        with pytest.raises(SystemExit, match=message):
            camera_from_arg(str(path))


def test_a_catalog_argument_is_a_built_in_name_or_a_json_file(tmp_path):
    from tofpose.core.catalog import paper_target
    from tofpose.io.camera_file import catalog_from_arg

    assert catalog_from_arg("paper-target") == paper_target()
    path = tmp_path / "cat.json"
    path.write_text(paper_target().to_json())
    assert catalog_from_arg(str(path)) == paper_target()
    with pytest.raises(SystemExit, match="cannot read catalog"):
        catalog_from_arg(str(tmp_path / "missing.json"))
    path.write_text('{"name": "x", "reflectors": []}')
    with pytest.raises(ValueError, match="at least 3 reflectors"):
        catalog_from_arg(str(path))
