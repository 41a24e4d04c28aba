"""The viser 3-D scene in a running app, checked through viser's Python API: its nodes
exist and follow the live pose and the turntable; pausing freezes them; the API says
where it is and refuses to pause a scene that does not run."""

from __future__ import annotations

import numpy as np
import pytest

from backend.services.live.scene_model import STATE_COLOURS
from tests.backend.conftest import AUTH, make_settings, running_app, wait_for
from tofpose.core.geometry import rotation_from_quaternion_wxyz

NODES = (
    "/camera",
    "/camera/frustum",
    "/camera/cloud",
    "/camera/reflectors",
    "/turntable",
    "/estimate",
    "/estimate/plate",
    "/reference",
    "/reference/plate",
    "/reference/label",
    "/truth",
    "/truth/plate",
    "/truth/label",
    *(f"/estimate/reflector_{i}" for i in range(1, 9)),
)


@pytest.fixture
def scene_app(tmp_path):
    settings = make_settings(tmp_path / "data", viser=True, viser_port=0, sim_time_scale=5.0)
    with running_app(settings) as client:
        yield client, client.app.state.tofpose.scene


def _after(scene, n_updates: int, frame_index: int | None = None):
    def ready():
        return scene.updates >= n_updates and (
            frame_index is None or (scene.last_frame_index or 0) > frame_index
        )

    wait_for(ready, 15.0, f"{n_updates} scene updates")


def test_the_scene_has_its_nodes_and_shows_the_live_pose(scene_app):
    client, scene = scene_app
    _after(scene, 3)
    names = set(scene.server.scene._handle_from_node_name)
    assert set(NODES) <= names, sorted(set(NODES) - names)
    # At rest the estimate sits where the lab's reference puts the target (2 m ahead of
    # the camera on the rail at 13 m): within a few cm, and every reflector is matched.
    camera_z_m = scene.camera_node.position[2]
    assert camera_z_m == pytest.approx(13.0, abs=1e-3)
    np.testing.assert_allclose(scene.estimate.position, [0.0, 0.0, 15.0], atol=0.03)
    np.testing.assert_allclose(scene.reference.position, [0.0, 0.0, 15.0], atol=0.03)
    np.testing.assert_allclose(scene.truth.position, [0.0, 0.0, 15.0], atol=0.03)
    assert all(h.color == STATE_COLOURS["matched"] for h in scene.estimate_reflectors.values())
    # The back-projected image holds the plate at 2 m (and the lab's wall behind it).
    ranges_m = np.linalg.norm(np.asarray(scene.cloud.points, float), axis=1)
    assert np.count_nonzero(np.abs(ranges_m - 2.0) < 0.15) > 300


def test_the_scene_follows_the_turntable(scene_app):
    client, scene = scene_app
    _after(scene, 2)
    r = client.post("/api/motion/move", json={"yaw_deg": 8.0}, headers=AUTH)
    assert r.status_code == 202, r.text

    def turned():
        R = rotation_from_quaternion_wxyz(np.asarray(scene.camera_node.wxyz))
        yaw = np.degrees(np.arctan2(R[0, 2], R[2, 2]))
        return abs(yaw - 8.0) < 0.05

    wait_for(turned, 20.0, "the scene's camera to turn with the turntable to yaw 8 deg")
    _after(scene, scene.updates + 2)
    # The target stands in the lab: the estimate, placed through the turned camera,
    # stays where it was (a wrong composition order would swing it by 8 deg = 0.28 m).
    np.testing.assert_allclose(scene.estimate.position, [0.0, 0.0, 15.0], atol=0.05)
    np.testing.assert_allclose(scene.turntable.wxyz, scene.camera_node.wxyz, atol=1e-9)


def test_pausing_freezes_the_scene_and_the_api_reports_it(scene_app):
    client, scene = scene_app
    _after(scene, 2)
    info = client.get("/api/scene").json()
    assert info["running"] and info["port"] == scene.port and not info["paused"]
    assert client.put("/api/scene", json={"paused": True}).status_code == 401
    r = client.put("/api/scene", json={"paused": True}, headers=AUTH)
    assert r.status_code == 200 and r.json()["paused"] is True
    assert scene.paused  # the scene's own GUI checkbox shows it too
    frozen = scene.updates
    n = client.app.state.tofpose.acquisition.frames_processed
    wait_for(
        lambda: client.app.state.tofpose.acquisition.frames_processed > n + 5,
        10.0,
        "frames while paused",
    )
    assert scene.updates <= frozen + 1  # at most the update that was under way
    client.put("/api/scene", json={"paused": False}, headers=AUTH)
    _after(scene, frozen + 3)
    assert client.put("/api/scene", json={"paused": "yes"}, headers=AUTH).status_code == 422


def test_without_the_scene_the_api_says_why(client):
    info = client.get("/api/scene").json()
    assert info == {**info, "running": False, "port": None}
    assert "switched off" in info["reason"]
    r = client.put("/api/scene", json={"paused": True}, headers=AUTH)
    assert r.status_code == 409 and "not running" in r.json()["detail"]


def test_a_scene_on_a_wide_bind_with_closed_reads_is_refused_with_a_reason(tmp_path):
    s = make_settings(tmp_path, viser=True, host="0.0.0.0", open_reads=False)
    assert "no token check" in s.scene_refusal
    opened = make_settings(tmp_path, viser=True, host="0.0.0.0", open_reads=True)
    assert opened.scene_refusal is None


def test_the_reference_node_shows_the_labs_reference_and_the_truth_node_the_rendered_pose(
    scene_app,
):
    """On the simulator a frame has both: ``/reference`` sits at the lab's reference
    (encoders + nominal geometry, off by the bench's mount and placement errors) and
    ``/truth`` at the pose rendered; a frame without one hides its node."""
    from dataclasses import replace

    from backend.services.live.scene_model import lab_camera_pose

    client, scene = scene_app
    _after(scene, 2)
    assert client.put("/api/scene", json={"paused": True}, headers=AUTH).status_code == 200
    sample = client.app.state.tofpose.acquisition.latest
    f = sample.frame
    assert f.T_camera_target_lab is not None and f.T_camera_target_exact is not None
    scene.update(sample)
    T_lab_cam = lab_camera_pose(f.meta.get("encoders"))
    for node, T in (
        (scene.reference, f.T_camera_target_lab),
        (scene.truth, f.T_camera_target_exact),
    ):
        assert node.visible
        np.testing.assert_allclose(node.position, T_lab_cam.compose(T).t_mm / 1000.0, atol=1e-9)
    apart_mm = 1000.0 * np.linalg.norm(np.subtract(scene.reference.position, scene.truth.position))
    assert apart_mm > 1.0  # the nominal geometry is not what the simulator rendered
    # a real camera's frame: the lab's reference only
    scene.update(replace(sample, frame=replace(f, T_camera_target_exact=None), cache={}))
    assert scene.reference.visible and not scene.truth.visible


def test_the_scene_never_takes_the_dashboard_s_port_when_any_free_port_is_asked():
    """The main server binds its port only once the app has started, after the scene: a
    scene asked for any free port must not be handed that one (once it was, and the
    server could not bind). The port the system just gave out is the likeliest to come
    back: it is the one avoided here."""
    import socket

    from backend.services.live.scene import free_port_other_than

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        taken = s.getsockname()[1]
    picks = {free_port_other_than("127.0.0.1", taken) for _ in range(50)}
    assert taken not in picks and 0 not in picks
    for port in picks:  # each was free when given
        assert 1024 <= port <= 65535
    assert free_port_other_than("203.0.113.1", taken) == 0  # not an address of this host
