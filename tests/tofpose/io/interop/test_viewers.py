"""The viewers' side of the exports (docs/interop.md): the turntable channels of an MCAP
export, the shipped Foxglove layout held to the topics and fields an export writes,
the Rerun blueprint read by Rerun's own loader, and ``tofpose export rrd`` read back."""

from __future__ import annotations

import json
import re
import shutil

import h5py
import numpy as np
import pytest

from tests.tofpose.io.interop.test_mcap_export import read_back
from tofpose.cli import main
from tofpose.core.geometry import facing_euler_deg
from tofpose.io.interop import topics
from tofpose.io.interop.motion_track import read_motion_track
from tofpose.io.interop.viewers import FOXGLOVE_LAYOUT, RERUN_BLUEPRINT
from tofpose.io.recording import open_recording
from tofpose.pipeline import PosePipeline

AXES = {"yaw": "deg", "pitch": "deg", "roll": "deg", "rail": "mm"}
WALL_START_NS = 1_765_000_000_000_000_000  # December 2025


@pytest.fixture(scope="module")
def turntable_recording(recording, tmp_path_factory):
    """The simulated recording with what the server's recordings add: a wall clock per
    frame and ``/motion`` (encoders, set-points with an axis left alone, set-point
    numbers), seeded values."""
    path = tmp_path_factory.mktemp("motion") / "table.h5"
    shutil.copyfile(recording, path)
    rng = np.random.default_rng(7)
    with h5py.File(path, "a") as f:
        n = f["frames/time_s"].shape[0]
        f["frames/wall_time_ns"] = WALL_START_NS + np.cumsum(rng.integers(5e7, 2e8, n))
        g = f.create_group("motion")
        g.attrs["axes"], g.attrs["units"] = list(AXES), list(AXES.values())
        g["positions"] = rng.normal(0.0, 5.0, (n, 4))
        targets = np.round(rng.normal(0.0, 5.0, (n, 4)))
        targets[n // 2 :, 1] = np.nan  # pitch left where it is
        g["targets"] = targets
        g["setpoint_index"] = (np.arange(n) // 3).astype(np.int32)
    return path


@pytest.fixture(scope="module")
def turntable_export(turntable_recording):
    out = turntable_recording.with_suffix(".mcap")
    assert main(["export", "mcap", str(turntable_recording), "--out", str(out)]) == 0
    return out, read_back(out)


def test_encoder_and_set_point_messages_are_the_recordings_at_its_wall_clock(
    turntable_recording, turntable_export
):
    _, (messages, channels, _) = turntable_export
    with h5py.File(turntable_recording, "r") as f:
        wall_ns = f["frames/wall_time_ns"][...]
        positions, targets = f["motion/positions"][...], f["motion/targets"][...]
        index = f["motion/setpoint_index"][...]
    assert channels[topics.ENCODERS][:2] == ("tofpose.Encoders", "jsonschema")
    assert channels[topics.SETPOINT][:2] == ("tofpose.SetPoint", "jsonschema")
    fields = [f"{a}_{u}" for a, u in AXES.items()]
    for k, ((t_enc, enc), (t_sp, sp)) in enumerate(
        zip(messages[topics.ENCODERS], messages[topics.SETPOINT], strict=True)
    ):
        assert t_enc == t_sp == wall_ns[k]
        assert enc == {"index": k, **dict(zip(fields, positions[k].tolist(), strict=True))}
        expected = [None if np.isnan(v) else v for v in targets[k].tolist()]
        assert sp == {
            "index": k,
            **dict(zip(fields, expected, strict=True)),
            "setpoint_index": int(index[k]),
        }
    assert len(messages[topics.ENCODERS]) == len(wall_ns)
    assert messages[topics.SETPOINT][-1][1]["pitch_deg"] is None


def test_a_recording_with_a_malformed_motion_group_is_refused_naming_it(
    turntable_recording, tmp_path
):
    bad = tmp_path / "bad.h5"
    shutil.copyfile(turntable_recording, bad)
    with h5py.File(bad, "a") as f:
        del f["motion/targets"]
        f["motion/targets"] = np.zeros((2, 4))
    with open_recording(bad) as rec, pytest.raises(ValueError, match=r"/motion/targets .*\(2, 4\)"):
        read_motion_track(rec.path, rec.n_frames)
    out = tmp_path / "bad.mcap"
    assert main(["export", "mcap", str(bad), "--out", str(out)]) == 2  # an error, no traceback
    assert not out.exists() and not out.with_name("bad.mcap.partial").exists()


# -- the Foxglove layout ------------------------------------------------------------------
def _layout_references(layout: dict) -> tuple[set[str], list[str], set[str]]:
    """(topics a panel subscribes to, message paths the plots draw, frame ids named)."""
    subscribed, paths, frames = set(), [], set()
    for panel_id, config in layout["configById"].items():
        kind = panel_id.split("!")[0]
        if kind in ("3D", "Image"):
            subscribed |= set(config.get("topics", {}))
            mode = config.get("imageMode", {})
            subscribed |= {mode[k] for k in ("imageTopic", "calibrationTopic") if k in mode}
            subscribed |= {a["topic"] for a in mode.get("annotations", [])}
            frames |= {k.removeprefix("frame:") for k in config.get("transforms", {})}
            frames |= {config[k] for k in ("followTf",) if k in config}
            frames |= {layer["frameId"] for layer in config.get("layers", {}).values()}
        elif kind == "Plot":
            paths += [p["value"] for p in config["paths"]]
        elif kind == "RawMessages":
            paths.append(config["topicPath"])
    return subscribed, paths, frames


def _resolve(message, field_path: str):
    """The value at ``.a.b[2]`` in a decoded message (dict or protobuf); None where the
    message has null on the way (an estimate without a pose)."""
    value = message
    for name, index in re.findall(r"\.(\w+)|\[(\d+)\]", field_path):
        if value is None:
            return None
        if name:
            value = value[name] if isinstance(value, dict) else getattr(value, name)
        else:
            value = value[int(index)]
    return value


def _panels(tree) -> set[str]:
    if isinstance(tree, str):
        return {tree}
    return _panels(tree["first"]) | _panels(tree["second"])


def test_the_foxglove_layout_names_only_what_the_export_writes(turntable_export):
    """Renaming a topic, a JSON field or a frame id breaks this test until the layout
    follows."""
    _, (messages, channels, _) = turntable_export
    layout = json.loads(FOXGLOVE_LAYOUT.read_text())
    assert _panels(layout["layout"]) == set(layout["configById"])
    subscribed, paths, frames = _layout_references(layout)
    for path in paths:
        topic, _, fields = path.partition(".")
        subscribed.add(topic)
        if fields:
            values = [_resolve(m, "." + fields) for _, m in messages[topic]]
            assert any(isinstance(v, float) for v in values), path  # a number to plot
    assert subscribed <= set(channels), sorted(subscribed - set(channels))
    for panel in ("Image!tofpose-gray", "Image!tofpose-distance"):  # Studio's ImageModeConfig
        for a in layout["configById"][panel]["imageMode"]["annotations"]:
            assert a["schemaName"] == channels[a["topic"]][0] and a["settings"]["visible"]
    assert {topics.ENCODERS, topics.SETPOINT, topics.TARGET_ORIGIN, topics.ANNOTATIONS} <= (
        subscribed
    )
    ids = {topics.CAMERA_FRAME_ID, topics.TARGET_FRAME_ID, topics.TRUTH_FRAME_ID}
    assert frames <= ids | {topics.REFERENCE_FRAME_ID}
    layout_3d = layout["configById"]["3D!tofpose-scene"]["topics"][topics.TARGET_ORIGIN]
    assert layout_3d["decayTime"] > 0  # the origin's history is the trail


def test_export_mcap_writes_the_layouts_beside_the_file(turntable_export):
    out, _ = turntable_export
    written = out.with_name(out.stem + ".foxglove-layout.json")
    assert written.read_text() == FOXGLOVE_LAYOUT.read_text()
    rerun_chunk = pytest.importorskip(
        "rerun.chunk", reason="rerun-sdk is not installed: the export writes no blueprint"
    )
    reader = rerun_chunk.RrdReader(out.with_suffix(".rbl"))
    # bound to the application id Rerun's viewer gives the MCAP file: its name
    assert [b.application_id for b in reader.blueprints()] == [out.stem]


# -- Rerun --------------------------------------------------------------------------------
def _store_columns(reader, store) -> dict[str, dict[str, list]]:
    """{entity path: {column: values in row order}} of one store of an .rrd / .rbl."""
    out: dict[str, dict[str, list]] = {}
    for chunk in reader.stream(store=store):
        rb = chunk.to_record_batch()
        cols = out.setdefault(str(chunk.entity_path), {})
        for name in rb.schema.names:
            if ":" in name:
                cols.setdefault(name, []).extend(rb.column(name).to_pylist())
    return out


@pytest.fixture(scope="module")
def rrd_export(turntable_recording):
    pytest.importorskip("rerun", reason="rerun-sdk is not installed: no tofpose export rrd")
    from rerun.chunk import RrdReader

    out = turntable_recording.with_suffix(".rrd")
    assert main(["export", "rrd", str(turntable_recording), "--out", str(out)]) == 0
    reader = RrdReader(out)
    (recording,) = reader.recordings()
    (blueprint,) = reader.blueprints()
    return _store_columns(reader, recording), _store_columns(reader, blueprint)


def _views(blueprint_columns) -> dict[str, tuple[str, str]]:
    """{view name: (class, origin)} of a blueprint store."""
    return {
        cols["ViewBlueprint:display_name"][0][0]: (
            cols["ViewBlueprint:class_identifier"][0][0],
            cols["ViewBlueprint:space_origin"][0][0],
        )
        for cols in blueprint_columns.values()
        if "ViewBlueprint:space_origin" in cols
    }


def test_the_shipped_blueprint_loads_with_rerun_and_shows_what_the_exports_log(rrd_export):
    from rerun.chunk import RrdReader

    reader = RrdReader(RERUN_BLUEPRINT)
    assert reader.recordings() == []
    (store,) = reader.blueprints()
    assert store.application_id == "tofpose"
    columns = _store_columns(reader, store)
    views = _views(columns)
    assert sorted(c for c, _ in views.values()) == ["2D", "2D", "3D", *["TimeSeries"] * 3]
    frames = [v[0] for c in columns.values() for v in c.get("SpatialInformation:target_frame", [])]
    assert frames == [topics.CAMERA_FRAME_ID]
    logged, embedded = rrd_export
    assert sorted(_views(embedded).values()) == sorted(views.values())  # the same layout
    for _cls, origin in views.values():
        if origin != "/":  # each view's origin holds data in an export
            assert any(e == origin or e.startswith(origin + "/") for e in logged), origin


def test_export_rrd_logs_the_pose_its_trail_overlay_and_turntable_series(
    turntable_recording, rrd_export
):
    logged, _ = rrd_export
    with open_recording(turntable_recording) as rec:
        pipe = PosePipeline(rec.camera, rec.catalog)
        results = [pipe.process(*rec.frame(i)) for i in range(rec.n_frames)]
    with h5py.File(turntable_recording, "r") as f:
        positions, targets = f["motion/positions"][...], f["motion/targets"][...]
    ok = [r for r in results if r.ok]
    for k, axis in enumerate(("x_mm", "y_mm", "z_mm")):
        series = logged[f"/tofpose/series/position/estimate/{axis}"]["Scalars:scalars"]
        np.testing.assert_allclose([v[0] for v in series if v], [r.t_mm[k] for r in ok])
    pitch = logged["/tofpose/series/attitude/estimate/pitch_deg"]["Scalars:scalars"]
    np.testing.assert_allclose([v[0] for v in pitch if v], [facing_euler_deg(r.R)[0] for r in ok])
    trail = logged["/tofpose/trail"]["LineStrips3D:strips"][-1][0]
    np.testing.assert_allclose(trail, [r.t_mm / 1000.0 for r in ok], rtol=1e-6)
    circles = [s for s in logged["/tof/gray_preview/overlay"]["LineStrips2D:strips"] if s]
    assert len(circles) == len(results)
    assert sum(len(c) for c in circles) >= sum(len(r.matched) for r in results)
    yaw = logged["/tofpose/series/turntable/encoders/yaw_deg"]["Scalars:scalars"]
    np.testing.assert_allclose([v[0] for v in yaw if v], positions[:, 0])
    rail = logged["/tofpose/series/rail/encoders/rail_mm"]["Scalars:scalars"]
    np.testing.assert_allclose([v[0] for v in rail if v], positions[:, 3])
    pitch_sp = logged["/tofpose/series/turntable/setpoint/pitch_deg"]["Scalars:scalars"]
    np.testing.assert_allclose(
        [v[0] for v in pitch_sp if v], targets[:, 1][~np.isnan(targets[:, 1])]
    )
