"""Recordings on demand over HTTP, on the simulated lab: a recording holds exactly the
frames the live hub delivered (count, frame numbers, device times) with the live poses,
covariances and relative states, wall-clock stamps and encoders; it downloads as HDF5
(``tofpose.io.recording``) and as MCAP (``mcap``'s reader); start is refused without free
space (507), while too many run (409), with a bad body (422 naming the field) and for a
read key (403); downloads and deletion wait for the stop (409); a server that stops
closes its recordings."""

from __future__ import annotations

import json
import shutil
import time
from collections import namedtuple

import h5py
import numpy as np
import pytest

from backend.services.recordings import StopReason
from tests.backend.conftest import AUTH, make_settings, running_app, wait_for
from tests.tofpose.io.interop.test_mcap_export import read_back
from tests.tofpose.io.interop.test_ros2_export import read_back as read_back_ros2
from tofpose.io.interop import ros2_topics, topics
from tofpose.io.recording import open_recording

Usage = namedtuple("Usage", "total used free")


@pytest.fixture(scope="module")
def app_client(tmp_path_factory):
    data = tmp_path_factory.mktemp("recordings") / "data"
    with running_app(make_settings(data, recording_min_free_mb=100)) as c:
        yield c


def _bearer(key: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {key}"}


def _start(c, **body) -> dict:
    r = c.post("/api/recordings", json={"name": "test", **body}, headers=AUTH)
    assert r.status_code == 201, r.text
    return r.json()


def _stop(c, rid: int) -> dict:
    r = c.post(f"/api/recordings/{rid}/stop", headers=AUTH)
    assert r.status_code == 200, r.text
    return r.json()


def _frames(c, rid: int) -> int:
    return c.get(f"/api/recordings/{rid}").json()["frames"]


def test_a_recording_holds_every_frame_the_hub_delivered_with_the_live_results(
    app_client, tmp_path
):
    c = app_client
    hub = c.app.state.tofpose.hub
    watch = hub.subscribe(maxsize=100_000)  # the test's own view of what the hub delivers
    try:
        rec = _start(c, name="before the test")
        assert (rec["state"], rec["frames"], rec["stop_reason"]) == ("recording", 0, None)
        wait_for(lambda: _frames(c, rec["id"]) >= 20, 60.0, "20 recorded frames")
        done = _stop(c, rec["id"])
    finally:
        hub.unsubscribe(watch)
    delivered = []
    while (s := watch.get(0)) is not None:
        delivered.append(s)
    assert watch.dropped == 0
    assert (done["state"], done["stop_reason"]) == ("stopped", "requested")
    assert done["dropped_frames"] == 0
    assert done["stop_detail"] == "stopped on request" and done["size_bytes"] > 0

    r = c.get(f"/api/recordings/{rec['id']}/recording.h5")
    assert r.status_code == 200 and r.headers["content-type"] == "application/x-hdf5"
    assert 'filename="before-the-test-' in r.headers["content-disposition"]
    path = tmp_path / "rec.h5"
    path.write_bytes(r.content)
    assert len(r.content) == done["size_bytes"]
    with h5py.File(path, "r") as f:
        index = f["frames/index"][...]
        n = len(index)
        assert n == done["frames"] >= 20
        # the recorded frames are a run of the delivered ones, without a gap
        by_index = {s.frame.index: s for s in delivered}
        first = [s.frame.index for s in delivered].index(index[0])
        run = delivered[first : first + n]
        np.testing.assert_array_equal(index, [s.frame.index for s in run])
        np.testing.assert_array_equal(f["frames/time_s"][...], [s.frame.time_s for s in run])
        ok = f["pose/ok"][...]
        np.testing.assert_array_equal(ok, [s.result.ok for s in run])
        assert ok.sum() >= 15  # the simulated lab: poses on nearly every frame
        poses = [s.result for s in run if s.result.ok]
        np.testing.assert_array_equal(f["pose/R_camera_target"][ok], [p.R for p in poses])
        np.testing.assert_array_equal(f["pose/t_camera_target_mm"][ok], [p.t_mm for p in poses])
        np.testing.assert_array_equal(f["pose/covariance"][ok], [p.covariance for p in poses])
        valid = f["relative_state/valid"][...]
        states = [s.state for s in run if s.state is not None]
        np.testing.assert_array_equal(valid, [s.state is not None for s in run])
        np.testing.assert_array_equal(
            f["relative_state/velocity_mm_s"][valid], [s.velocity_mm_s for s in states]
        )
        # the simulated camera reads the encoders at each frame; rail, pitch, roll, yaw
        axes = [a.decode() if isinstance(a, bytes) else a for a in f["motion"].attrs["axes"]]
        np.testing.assert_array_equal(
            f["motion/positions"][...],
            [[by_index[i].frame.meta["encoders"][a] for a in axes] for i in index],
        )
        assert np.isfinite(f["motion/targets"][...]).all()
        # wall-clock stamps: UTC ns, within a minute of now, in order
        wall = f["frames/wall_time_ns"][...]
        assert (np.abs(wall / 1e9 - time.time()) < 60).all() and (np.diff(wall) > 0).all()
    with open_recording(path) as rec_file:  # the project's reader takes it as any recording
        assert rec_file.n_frames == n and rec_file.reference_R is not None

    r = c.get(f"/api/recordings/{rec['id']}/recording.mcap")
    assert r.status_code == 200 and r.headers["content-type"] == "application/x-mcap"
    (tmp_path / "rec.mcap").write_bytes(r.content)
    messages, _, _ = read_back(tmp_path / "rec.mcap")
    assert len(messages[topics.GRAY]) == n
    assert len(messages[topics.REFERENCE]) == n
    # the messages carry the wall clock of each frame's capture, not the device's clock
    assert [t for t, _ in messages[topics.GRAY]] == wall.tolist()

    # as ROS 2 messages (?profile=ros2): an independent ROS 2 reader decodes every message
    r = c.get(f"/api/recordings/{rec['id']}/recording.mcap", params={"profile": "ros2"})
    assert r.status_code == 200 and r.headers["content-type"] == "application/x-mcap"
    assert 'filename="before-the-test-' in r.headers["content-disposition"]
    assert '.ros2.mcap"' in r.headers["content-disposition"]
    (tmp_path / "rec.ros2.mcap").write_bytes(r.content)
    ros2 = read_back_ros2(tmp_path / "rec.ros2.mcap")
    assert len(ros2[ros2_topics.AMPLITUDE]) == len(ros2[ros2_topics.TF]) == n
    assert [t for t, _ in ros2[ros2_topics.AMPLITUDE]] == wall.tolist()
    with open_recording(path) as rec_file:
        gray, dist_mm, _ = rec_file.frame(n - 1)
    _, amplitude = ros2[ros2_topics.AMPLITUDE][n - 1]
    np.testing.assert_array_equal(amplitude.data.view("<u2").reshape(gray.shape), gray)
    _, distance = ros2[ros2_topics.DISTANCE][n - 1]
    dist_m = distance.data.view("<f4").reshape(gray.shape)
    np.testing.assert_allclose(dist_m, dist_mm / 1000.0, rtol=2**-24, atol=0)
    labs = [t for _, m in ros2[ros2_topics.TF] for t in m.transforms]
    assert [t.child_frame_id for t in labs].count("tofpose_target_reference") == n


def test_an_unknown_mcap_profile_is_refused_naming_the_parameter_and_the_choices(app_client):
    c = app_client
    rid = _start(c, name="profile")["id"]
    _stop(c, rid)
    r = c.get(f"/api/recordings/{rid}/recording.mcap", params={"profile": "ros1"})
    assert r.status_code == 422
    (detail,) = r.json()["detail"]
    assert detail["loc"] == ["query", "profile"]
    assert "'foxglove'" in detail["msg"] and "'ros2'" in detail["msg"]


def test_start_is_refused_with_507_below_the_free_space_floor(app_client, monkeypatch):
    c = app_client
    before = c.get("/api/recordings").json()["recordings"]
    monkeypatch.setattr(shutil, "disk_usage", lambda _p: Usage(10**12, 10**12, 42 * 10**6))
    r = c.post("/api/recordings", json={"name": "no room"}, headers=AUTH)
    assert r.status_code == 507
    assert "42 MB free" in r.json()["detail"] and "100 MB" in r.json()["detail"]
    listing = c.get("/api/recordings").json()
    assert listing["recordings"] == before
    assert (listing["free_mb"], listing["min_free_mb"]) == (42.0, 100.0)


@pytest.mark.parametrize(
    ("body", "field"),
    [
        ({}, "name"),
        ({"name": ""}, "name"),
        ({"name": "a\nb"}, "name"),
        ({"name": "x" * 201}, "name"),
        ({"name": 5}, "name"),
        ({"name": "x", "duration_s": 0}, "duration_s"),
        ({"name": "x", "duration_s": -3}, "duration_s"),
        ({"name": "x", "duration_s": "10"}, "duration_s"),
        ({"name": "x", "duration_s": 1e9}, "duration_s"),
        ({"name": "x", "seconds": 10}, "seconds"),
    ],
)
def test_a_bad_body_gets_422_naming_the_field(app_client, body, field):
    r = app_client.post("/api/recordings", json=body, headers=AUTH)
    assert r.status_code == 422, r.text
    assert [e["loc"] for e in r.json()["detail"]] == [["body", field]]


def test_each_scope_may_do_what_it_should(app_client):
    c = app_client
    keys = {}
    for scope in ("read", "operate"):
        r = c.post("/api/keys", json={"name": f"rec-{scope}", "scope": scope}, headers=AUTH)
        keys[scope] = _bearer(r.json()["key"])
    r = c.post("/api/recordings", json={"name": "nope"}, headers=keys["read"])
    assert r.status_code == 403 and "'operate'" in r.json()["detail"]
    assert c.post("/api/recordings", json={"name": "nope"}).status_code == 401
    r = c.post(
        "/api/recordings", json={"name": "operator's", "duration_s": 60}, headers=keys["operate"]
    )
    assert r.status_code == 201
    rid = r.json()["id"]
    assert c.post(f"/api/recordings/{rid}/stop", headers=keys["read"]).status_code == 403
    assert c.get(f"/api/recordings/{rid}", headers=keys["read"]).status_code == 200
    r = c.post(f"/api/recordings/{rid}/stop", headers=keys["operate"])
    assert r.status_code == 200 and r.json()["state"] == "stopped"
    r = c.delete(f"/api/recordings/{rid}", headers=keys["operate"])
    assert r.status_code == 403 and "'admin'" in r.json()["detail"]
    assert c.delete(f"/api/recordings/{rid}", headers=AUTH).status_code == 204
    assert c.get(f"/api/recordings/{rid}").status_code == 404


def test_downloads_and_deletion_wait_for_the_stop_and_unknown_ids_are_404(app_client):
    c = app_client
    rid = _start(c, name="busy")["id"]
    try:
        for suffix in ("h5", "mcap"):
            r = c.get(f"/api/recordings/{rid}/recording.{suffix}")
            assert r.status_code == 409 and "is recording" in r.json()["detail"]
        assert c.delete(f"/api/recordings/{rid}", headers=AUTH).status_code == 409
        # a second may run beside it, a third not
        other = _start(c, name="beside")["id"]
        r = c.post("/api/recordings", json={"name": "third"}, headers=AUTH)
        assert r.status_code == 409 and "at most 2 at once" in r.json()["detail"]
        _stop(c, other)
    finally:
        first = _stop(c, rid)
    assert _stop(c, rid) == first  # stopping twice changes nothing
    for path in ("/api/recordings/999999", "/api/recordings/999999/recording.h5"):
        assert c.get(path).status_code == 404
    assert c.post("/api/recordings/999999/stop", headers=AUTH).status_code == 404


def test_a_duration_stops_it_and_the_list_shows_the_disk(app_client):
    c = app_client
    rid = _start(c, name="timed", duration_s=1.0)["id"]
    done = wait_for(
        lambda: (r := c.get(f"/api/recordings/{rid}").json())["state"] == "stopped" and r,
        30.0,
        "the recording's end",
    )
    assert done["stop_reason"] == StopReason.DURATION and done["frames"] > 0
    assert done["elapsed_s"] >= 1.0
    listing = c.get("/api/recordings").json()
    assert listing["recordings"][0]["id"] == rid  # newest first
    assert listing["max_active"] == 2 and listing["used_mb"] > 0 and listing["free_mb"] > 100


def test_a_new_modulation_frequency_is_refused_while_a_recording_records(app_client):
    """A recording holds one camera model: the frequency stays until it is stopped (409
    naming it, the camera unchanged); other settings change as before; after the stop
    the frequency changes too."""
    c = app_client
    before = c.get("/api/camera/settings").json()
    rid = _start(c, name="held")["id"]
    try:
        r = c.put("/api/camera/settings", json={"modulation_frequency_mhz": 12}, headers=AUTH)
        assert r.status_code == 409, r.text
        detail = r.json()["detail"]
        assert f"recording {rid} ('held')" in detail and "stop it" in detail
        # the settings say so before anyone tries: the same sentence, nothing else held
        held = c.get("/api/camera/settings").json()
        assert held == {**before, "frequency_held": detail}
        assert before["frequency_held"] is None and before["locked"] is None
        r = c.put("/api/camera/settings", json={"integration_time_us": 300}, headers=AUTH)
        assert r.status_code == 200, r.text
        same = {"modulation_frequency_mhz": before["modulation_frequency_mhz"]}
        r = c.put("/api/camera/settings", json=same, headers=AUTH)  # no change: no refusal
        assert r.status_code == 200, r.text
    finally:
        _stop(c, rid)
    assert c.get("/api/camera/settings").json()["frequency_held"] is None
    r = c.put("/api/camera/settings", json={"modulation_frequency_mhz": 12}, headers=AUTH)
    assert r.status_code == 200 and r.json()["modulation_frequency_mhz"] == 12
    restore = {
        k: before[k] for k in ("integration_time_us", "modulation_frequency_mhz", "auto_exposure")
    }
    assert c.put("/api/camera/settings", json=restore, headers=AUTH).status_code == 200


def test_a_server_that_stops_closes_its_recordings(tmp_path):
    data = tmp_path / "data"
    with running_app(make_settings(data, recording_min_free_mb=100)) as c:
        rid = _start(c, name="at shutdown")["id"]
        wait_for(lambda: _frames(c, rid) >= 3, 60.0, "3 recorded frames")
    index = json.loads((data / "recordings" / "index.json").read_text())
    entry = next(e for e in index["recordings"] if e["id"] == rid)
    assert (entry["state"], entry["stop_reason"]) == ("stopped", "shutdown")
    with open_recording(data / "recordings" / entry["file"]) as rec:
        assert rec.n_frames == entry["frames"] >= 3


def test_the_frequency_is_compared_as_the_camera_would_take_it():
    """A camera with a fixed list of frequencies (the TOFcam-660) takes the nearest:
    11.9 MHz at 12 is no change (not refused while recording, not applied); a camera
    without a list takes the value asked."""
    from backend.api.routes.camera import _nearest_frequency_mhz
    from backend.drivers.base import CameraLimits
    from backend.drivers.tofcam660 import MODULATION_MHZ
    from backend.services.campaigns.camera_plan import DEFAULT_LIMITS

    listed = CameraLimits(
        integration_time_us=(1.0, 4000.0), modulation_frequencies_mhz=MODULATION_MHZ
    )
    assert _nearest_frequency_mhz(listed, 11.9) == 12.0
    assert _nearest_frequency_mhz(listed, 7.0) == 6.0
    assert _nearest_frequency_mhz(DEFAULT_LIMITS, 11.9) == 11.9  # no list: the API's defaults
