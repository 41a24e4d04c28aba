"""Interop with the robotics tools labs already use (docs/interop.md).

- ``topics``: the channel names, schemas and units (the contract of an exported file).
- ``foxglove_messages``: our frames, poses and overlays as Foxglove well-known messages
  (``foxglove-sdk``'s typed messages) and as JSON payloads for what no schema carries.
- ``channels``: one set of channels on a ``foxglove.Context``, logged per frame; the MCAP
  export and the live Foxglove server both write through it.
- ``mcap_export`` / ``mcap_import``: HDF5 recording <-> MCAP file.
- ``mcap_profiles``: the export in either profile (``foxglove`` or ``ros2``).
- ``ros2_export`` (``--profile ros2``): HDF5 recording -> MCAP of ROS 2 messages, with
  ``ros2_topics`` (its contract), ``ros2_messages`` (the conversions),
  ``ros2_covariance`` (ROS's covariance order and units) and ``ros2_schemas`` (ROS 2's
  ``.msg`` definitions, shipped in ``ros2_msgs/``).
- ``ros2_import`` (``tofpose import ros2``): ROS 2 bag (MCAP or sqlite3, read by
  ``rosbags``) -> HDF5 recording, with ``ros2_images`` (Image and CameraInfo messages to
  arrays and camera).
- ``k4a_import`` (``tofpose import k4a``): Azure Kinect recording (Matroska, decoded by
  PyAV) -> HDF5 recording, with ``k4a_calibration`` (its ``calibration.json`` to the
  depth camera of the recording's mode).
- ``distortion_fit``: a rational lens model (k4..k6) as the nearest five coefficients
  that ``CameraModel`` holds.

Encoding is the SDK's (protobuf for the well-known schemas, JSON for ours) and decoding
the ``mcap`` reader's with ``mcap-protobuf-support``; the ROS 2 profile's CDR is
``mcap-ros2-support``'s (the ROS 2 import decodes with ``rosbags``): no encoder or
decoder of our own.
"""

from typing import Literal, get_args

#: the MCAP profiles a recording exports to: Foxglove's well-known schemas (the default)
#: or ROS 2's messages
McapProfile = Literal["foxglove", "ros2"]
MCAP_PROFILES: tuple[str, ...] = get_args(McapProfile)
DEFAULT_MCAP_PROFILE: McapProfile = "foxglove"
#: the file name suffix of each profile's export (``rec.h5`` -> ``rec.mcap``,
#: ``rec.ros2.mcap``): the server keeps one export of each beside a recording
MCAP_SUFFIXES: dict[str, str] = {"foxglove": ".mcap", "ros2": ".ros2.mcap"}
