"""The live 3-D scene: a viser server inside the backend process, fed by the live hub.

Nodes (names are part of the contract: tests and docs use them), in the lab frame in
metres (``scene_model``):

- ``/turntable``: the gimbal's axes at the encoder positions (a frame per axis set);
  ``/rail``: the rail the turntable rides on.
- ``/camera``: the camera's pose in the lab; children ``/camera/frustum``,
  ``/camera/cloud`` (the back-projected distance image, downsampled to
  ``max_cloud_points``) and ``/camera/reflectors`` (the measured reflector points,
  coloured matched / unmatched).
- ``/estimate`` and ``/truth``: the target model at the estimated pose and at the lab's
  reference (when the source knows it; else at the exact pose, when that is known:
  ``_shown_truth``): ``.../plate`` and ``.../reflector_<id>``, each
  reflector coloured matched / unmatched / out of view (``scene_model.STATE_COLOURS``).
- GUI: a "Pause scene" checkbox (freezes the scene; the pipeline keeps running) and a
  status line.

One thread takes the newest sample from a one-deep hub subscription (older ones are
dropped, never queued) and updates the nodes at most ``max_rate_hz`` times a second.
"""

from __future__ import annotations

import logging
import threading
import time

import numpy as np

from backend.drivers.base import CameraFrame
from backend.services.acquisition import AcquisitionService, LiveSample
from backend.services.hub import LiveHub
from backend.services.scene_model import (
    MATCHED,
    STATE_COLOURS,
    UNMATCHED,
    distance_cloud,
    lab_camera_pose,
    reflector_states,
)
from tofpose.catalog import Catalog
from tofpose.geometry import RigidTransform, quaternion_wxyz_from_rotation

log = logging.getLogger("tofpose.scene")
TRUTH_COLOUR = (70, 120, 230)
PLATE_COLOUR = (200, 200, 205)


def _shown_truth(frame: CameraFrame) -> RigidTransform | None:
    """The pose ``/truth`` shows (``T_camera_target``): the lab's reference (encoders +
    nominal geometry, or a recording's ``/lab_truth``), as it always has on the
    simulator; the exact pose only when the frame has no lab reference (a replayed
    recording with ``/truth`` alone); None when it has neither."""
    if frame.T_camera_target_lab is not None:
        return frame.T_camera_target_lab
    return frame.T_camera_target_exact


def _place(handle, T: RigidTransform) -> None:
    """Set a viser node's pose from a transform in millimetres."""
    handle.wxyz = quaternion_wxyz_from_rotation(T.R)
    handle.position = np.asarray(T.t_mm, float) / 1000.0


class LiveScene:
    """Owns a ``viser.ViserServer`` and keeps its scene in step with the live results."""

    def __init__(
        self,
        hub: LiveHub,
        acquisition: AcquisitionService,
        *,
        host: str,
        port: int,
        max_rate_hz: float = 10.0,
        max_cloud_points: int = 12_000,
        rail_length_mm: float | None = None,
    ) -> None:
        import viser  # imported here: the pipeline and the CLI do not need it

        self._hub = hub
        self._acq = acquisition
        self._camera = acquisition.camera.model
        self._min_period_s = 1.0 / max_rate_hz
        self._max_cloud_points = max_cloud_points
        self.server = viser.ViserServer(host=host, port=port, label="tofpose", verbose=False)
        self.updates = 0
        self.last_frame_index: int | None = None
        self._catalog_name: str | None = None
        self._stop = threading.Event()
        self._build_static(rail_length_mm)
        self._sub = hub.subscribe(maxsize=1)
        self._thread = threading.Thread(target=self._run, name="tofpose-scene", daemon=True)
        self._thread.start()

    # -- lifecycle ------------------------------------------------------------------------
    @property
    def port(self) -> int:
        return self.server.get_port()

    @property
    def paused(self) -> bool:
        return bool(self._pause.value)

    def set_paused(self, paused: bool) -> None:
        self._pause.value = paused

    def close(self) -> None:
        self._stop.set()
        self._hub.unsubscribe(self._sub)
        self._thread.join(timeout=2.0)
        self.server.stop()

    # -- scene construction ---------------------------------------------------------------
    def _build_static(self, rail_length_mm: float | None) -> None:
        s = self.server.scene
        s.set_up_direction("-y")  # the lab's y axis points down
        s.configure_environment_map(hdri=None)
        s.add_light_ambient("/light/ambient", intensity=1.2)
        s.add_light_directional("/light/key", intensity=1.5, wxyz=(0.92, -0.38, 0.0, 0.0))
        self.server.initial_camera.up = (0.0, -1.0, 0.0)
        self._aimed = False
        s.add_frame("/lab", axes_length=0.25, axes_radius=0.008)
        if rail_length_mm:
            end = (0.0, 0.0, rail_length_mm / 1000.0)
            s.add_line_segments("/rail", np.array([[(0.0, 0.0, 0.0), end]]), colors=(90, 90, 90))
        self.turntable = s.add_frame("/turntable", axes_length=0.4, axes_radius=0.012)
        self.camera_node = s.add_frame("/camera", show_axes=False)
        m = self._camera
        fov_v = 2.0 * np.arctan(m.height / 2.0 / m.fy)
        self.frustum = s.add_camera_frustum(
            "/camera/frustum", fov=float(fov_v), aspect=m.width / m.height, scale=0.35,
            color=(30, 30, 30),
        )  # fmt: skip
        self.cloud = s.add_point_cloud(
            "/camera/cloud", np.zeros((1, 3), np.float32), (150, 150, 150), point_size=0.007
        )
        self.measured = s.add_point_cloud(
            "/camera/reflectors", np.zeros((1, 3), np.float32), (0, 0, 0), point_size=0.05,
            point_shape="circle", visible=False,
        )  # fmt: skip
        self._pause = self.server.gui.add_checkbox("Pause scene", initial_value=False)
        self.status = self.server.gui.add_markdown("waiting for the first frame")
        self.estimate = self.truth = None
        self.estimate_reflectors: dict[int, object] = {}
        self.truth_reflectors: dict[int, object] = {}

    def _build_target(self, catalog: Catalog) -> None:
        """(Re)build the two target models for the active catalog."""
        s = self.server.scene
        for node in (self.estimate, self.truth):
            if node is not None:
                node.remove()
        self.estimate = s.add_frame("/estimate", axes_length=0.15, axes_radius=0.006)
        self.truth = s.add_frame("/truth", axes_length=0.15, axes_radius=0.006, visible=False)
        w, h = catalog.plate_size_mm
        dims = (w / 1000.0, h / 1000.0, 0.01)
        s.add_box("/estimate/plate", PLATE_COLOUR, dims, position=(0.0, 0.0, -0.005))
        s.add_box("/truth/plate", TRUTH_COLOUR, dims, wireframe=True, position=(0, 0, -0.005))
        self.estimate_reflectors, self.truth_reflectors = {}, {}
        for r in catalog.reflectors:
            pos = np.asarray(r.position_mm, float) / 1000.0
            radius = r.diameter_mm / 2000.0
            self.estimate_reflectors[r.id] = s.add_icosphere(
                f"/estimate/reflector_{r.id}", radius, STATE_COLOURS[UNMATCHED], position=pos
            )
            self.truth_reflectors[r.id] = s.add_icosphere(
                f"/truth/reflector_{r.id}", radius, TRUTH_COLOUR, position=pos, wireframe=True
            )
        s.add_label("/estimate/label", "estimate", position=(-w / 2000.0, h / 2000.0, 0.0))
        s.add_label("/truth/label", "truth", position=(w / 2000.0, -h / 2000.0, 0.0))

    # -- live updates ----------------------------------------------------------------------
    def _run(self) -> None:
        last = 0.0
        while not self._stop.is_set():
            sample = self._sub.get(timeout_s=0.2)
            if sample is None or self.paused:
                continue
            wait = self._min_period_s - (time.monotonic() - last)
            if wait > 0 and self._stop.wait(wait):
                return
            newer = self._sub.get(timeout_s=0)  # whatever arrived while we waited
            sample = newer or sample
            try:
                self.update(sample)
            except Exception:  # a scene glitch must never take the server down
                log.exception("3-D scene update failed")
            last = time.monotonic()

    def update(self, sample: LiveSample) -> None:
        """Move every live node to what ``sample`` shows (called by the scene thread;
        tests call it directly)."""
        catalog = self._acq.catalog
        if catalog.name != self._catalog_name or self.estimate is None:
            self._build_target(catalog)
            self._catalog_name = catalog.name
        res, frame = sample.result, sample.frame
        T_lab_cam = lab_camera_pose(frame.meta.get("encoders"))
        T_shown = _shown_truth(frame)  # the lab reference; the exact pose only without one
        if not self._aimed:
            self._aim_view(T_lab_cam, res, T_shown)
        with self.server.atomic():
            _place(self.turntable, T_lab_cam)
            _place(self.camera_node, T_lab_cam)
            T_est = RigidTransform(res.R, res.t_mm) if res.ok else None
            states = reflector_states(catalog, res, self._camera, T_est or T_shown)
            for r, state in zip(catalog.reflectors, states, strict=True):
                self.estimate_reflectors[r.id].color = STATE_COLOURS[state]
            self.estimate.visible = T_est is not None
            if T_est is not None:
                _place(self.estimate, T_lab_cam.compose(T_est))
            self.truth.visible = T_shown is not None
            if T_shown is not None:
                _place(self.truth, T_lab_cam.compose(T_shown))
            if sample.has_images:
                cloud = distance_cloud(
                    self._camera, frame.gray, frame.distance_mm, self._max_cloud_points
                )
                if len(cloud.points_m):
                    self.cloud.points = cloud.points_m
                    self.cloud.colors = cloud.colours
            self._update_measured(res)
            self.status.content = self._status_text(res, frame.index)
        self.updates += 1
        self.last_frame_index = frame.index

    def _aim_view(self, T_lab_cam: RigidTransform, res, T_shown) -> None:
        """Point the initial view (new browser tabs) at the camera and the target: from
        above and to the side of the camera, at the middle of the line of sight."""
        if res.ok:
            range_m = float(np.linalg.norm(res.t_mm)) / 1000.0
        elif T_shown is not None:
            range_m = float(np.linalg.norm(T_shown.t_mm)) / 1000.0
        else:
            return  # wait for a frame that says where the target is
        cam = T_lab_cam.t_mm / 1000.0
        ahead = T_lab_cam.R[:, 2]
        self.server.initial_camera.look_at = cam + ahead * range_m / 2.0
        self.server.initial_camera.position = cam + T_lab_cam.R @ np.array(
            [-1.1 * range_m, -0.6 * range_m, -0.15 * range_m]
        )
        self._aimed = True

    def _update_measured(self, res) -> None:
        pts = [np.asarray(m.point_mm, float) for m in res.matched]
        cols = [STATE_COLOURS[MATCHED]] * len(pts)
        for u, v, d in res.unmatched:
            if np.isfinite(d):
                pts.append(self._camera.back_project(np.array([[u, v]]), np.array([d]))[0])
                cols.append(STATE_COLOURS[UNMATCHED])
        self.measured.visible = bool(pts)
        if pts:
            self.measured.points = (np.asarray(pts) / 1000.0).astype(np.float32)
            self.measured.colors = np.asarray(cols, np.uint8)

    @staticmethod
    def _status_text(res, frame_index: int) -> str:
        if not res.ok:
            return f"frame {frame_index}: **no pose**: {res.reason}"
        x, y, z = res.t_mm
        p, yw, r = res.euler_deg
        return (
            f"frame {frame_index}: {res.n_matched} matched, residual "
            f"{res.residual_mm:.2f} mm  \nx {x:.1f} mm, y {y:.1f} mm, z {z:.1f} mm  \n"
            f"pitch {p:.2f} deg, yaw {yw:.2f} deg, roll {r:.2f} deg"
        )
