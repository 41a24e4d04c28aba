"""``ros2_schemas``: complete ``ros2msg`` definitions from the shipped ROS 2 .msg files."""

from __future__ import annotations

import pytest

from tofpose.io.interop.ros2_schemas import SEPARATOR, definition, field_types, msg_text
from tofpose.io.interop.ros2_topics import TYPES


def _dependencies(text: str) -> list[str]:
    return [line[5:] for line in text.splitlines() if line.startswith("MSG: ")]


def test_a_definition_lists_every_dependency_once_after_rosbag2s_delimiter():
    text = definition("sensor_msgs/msg/CameraInfo")
    assert text.startswith(msg_text("sensor_msgs/msg/CameraInfo").rstrip("\n"))
    assert _dependencies(text) == [
        "std_msgs/msg/Header",
        "builtin_interfaces/msg/Time",
        "sensor_msgs/msg/RegionOfInterest",
    ]
    assert text.count(SEPARATOR + "\nMSG: ") == 3 and len(SEPARATOR) == 80


def test_nested_and_array_fields_are_followed():
    deps = _dependencies(definition("tf2_msgs/msg/TFMessage"))
    assert deps == [
        "geometry_msgs/msg/TransformStamped",
        "std_msgs/msg/Header",
        "builtin_interfaces/msg/Time",
        "geometry_msgs/msg/Transform",
        "geometry_msgs/msg/Vector3",
        "geometry_msgs/msg/Quaternion",
    ]


def test_every_exported_type_has_a_complete_definition():
    for type_name in set(TYPES.values()):
        text = definition(type_name)
        for dep in _dependencies(text):
            assert msg_text(dep) in text


def test_field_types_qualify_names_and_skip_primitives_and_constants():
    text = (
        "Header header # c\nuint8 A=1\nfloat64[9] k\nPose[] poses\nstd_msgs/Empty e\nstring<=8 s\n"
    )
    assert field_types(text, "geometry_msgs") == [
        "geometry_msgs/msg/Header",
        "geometry_msgs/msg/Pose",
        "std_msgs/msg/Empty",
    ]


@pytest.mark.parametrize(
    ("name", "message"),
    [
        (
            "sensor_msgs/msg/PointCloud2",
            "no ROS 2 message definition ships for sensor_msgs/msg/PointCloud2",
        ),
        ("sensor_msgs/Image", "not of the form package/msg/Type"),
        ("Image", "not of the form package/msg/Type"),
    ],
)
def test_an_unknown_or_malformed_type_is_refused_naming_it(name, message):
    with pytest.raises(ValueError, match=message):
        definition(name)
