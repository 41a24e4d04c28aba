"""Rerun opens our MCAP export (docs/interop.md, ``rerun REC.mcap``): its own MCAP
importer (``rerun.chunk.McapReader``, the code behind the viewer's file loading) turns
our channels into its archetypes with the values we wrote."""

from __future__ import annotations

import json
from collections import defaultdict

import numpy as np
import pyarrow as pa
import pytest
from rerun.chunk import McapReader

from tofpose.io.interop import topics
from tofpose.io.recording import open_recording


def columns_by_entity(path) -> dict[str, dict[str, list]]:
    """{entity path: {archetype column: its non-null values in log-time order}}."""
    rows: dict[str, dict[str, list]] = defaultdict(lambda: defaultdict(list))
    for chunk in McapReader(path).stream():
        rb = chunk.to_record_batch()
        if "message_log_time" not in rb.schema.names:
            continue  # static chunks (file properties)
        times = rb.column("message_log_time").cast(pa.int64()).to_pylist()
        for name in rb.schema.names:
            if ":" in name and (not name.startswith("Mcap") or name == "McapMessage:data"):
                for t, v in zip(times, rb.column(name).to_pylist(), strict=True):
                    if v is not None:
                        rows[str(chunk.entity_path)][name].append((t, v))
    return {
        e: {c: [v for _, v in sorted(vals, key=lambda tv: tv[0])] for c, vals in cols.items()}
        for e, cols in rows.items()
    }


@pytest.fixture(scope="module")
def rerun_view(exported):
    return columns_by_entity(exported)


def test_rerun_maps_our_channels_to_its_archetypes(rerun_view):
    wanted = {
        topics.GRAY: "Image:buffer",
        topics.DISTANCE: "Image:buffer",
        topics.CALIBRATION: "Pinhole:image_from_camera",
        topics.POSE_TRANSFORM: "Transform3D:translation",
        topics.TRUTH_TRANSFORM: "Transform3D:translation",
        topics.POSE: "InstancePoses3D:translations",
        topics.REFLECTORS: "Points3D:positions",
        topics.ESTIMATE: "McapMessage:data",  # ours: kept as the raw JSON message
    }
    for topic, column in wanted.items():
        assert column in rerun_view[topic], (topic, sorted(rerun_view[topic]))


def test_the_values_rerun_reads_are_ours(recording, rerun_view):
    with open_recording(recording) as rec:
        cam = rec.camera
        gray0 = rec.frame(0)[0]
    pinhole = rerun_view[topics.CALIBRATION]["Pinhole:image_from_camera"]
    # column-major 3x3: [fx 0 0, 0 fy 0, cx cy 1]
    np.testing.assert_allclose(
        np.reshape(pinhole[0], (3, 3)).T, [[cam.fx, 0, cam.cx], [0, cam.fy, cam.cy], [0, 0, 1]]
    )
    images = rerun_view[topics.GRAY]["Image:buffer"]
    np.testing.assert_array_equal(
        np.frombuffer(bytes(images[0][0]), "<u2").reshape(cam.height, cam.width), gray0
    )
    estimates = [
        json.loads(bytes(d[0] if isinstance(d[0], list) else d))
        for d in rerun_view[topics.ESTIMATE]["McapMessage:data"]
    ]
    ok = [e for e in estimates if e["ok"]]
    translations = rerun_view[topics.POSE_TRANSFORM]["Transform3D:translation"]
    assert len(translations) == len(ok) >= 6
    for e, t in zip(ok, translations, strict=True):
        np.testing.assert_allclose(t[0], np.array(e["t_camera_target_mm"]) / 1000.0, rtol=1e-6)
