"""The simulated lab bench: turntable + rail carrying the camera, the fixed target.

Lab frame L: at all axes zero the camera frame coincides with L (x right, y down, z
towards the target); the rail translates the turntable along +z. Kinematic chain:

    T_lab_camera = Trans(0, 0, rail) . Ry(yaw) . Rx(pitch) . Rz(roll) . T_inner_camera

``T_inner_camera`` is the installation transform. The world renders with the *true*
installation and target placement (nominal composed with an unknown error, §6.4-6.5);
the lab's ground truth uses encoder readings and the *nominal* values, as a real lab
would.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from tofpose.core.camera import CameraModel
from tofpose.core.geometry import RigidTransform
from tofpose.lab.kinematics import axes_transform
from tofpose.sim.render import RenderedFrame, SensorModel, reference_full_scale, render_frame
from tofpose.sim.scene import TargetScene
from tofpose.sim.turntable import Turntable

# Target facing the camera: target z (out of the plate) points at the camera, target y up.
R_FACING = np.diag([1.0, -1.0, -1.0])


@dataclass
class LabGeometry:
    """Nominal geometry and its unknown errors.

    target_distance_mm : distance from the turntable centre (rail 0) to the target origin.
    T_inner_camera : nominal installation of the camera on the inner axis.
    T_lab_target : nominal target placement (default: facing the camera at distance).
    mount_error, placement_error : true = nominal . error (unknown to the lab).
    """

    target_distance_mm: float = 2000.0
    target_offset_mm: tuple[float, float] = (0.0, 0.0)
    T_inner_camera: RigidTransform = field(default_factory=RigidTransform.identity)
    mount_error: RigidTransform = field(default_factory=RigidTransform.identity)
    placement_error: RigidTransform = field(default_factory=RigidTransform.identity)

    @property
    def T_lab_target(self) -> RigidTransform:
        ox, oy = self.target_offset_mm
        return RigidTransform(R_FACING, np.array([ox, oy, self.target_distance_mm]))

    def T_camera_target(self, positions: dict[str, float], *, true: bool) -> RigidTransform:
        mount = self.T_inner_camera
        target = self.T_lab_target
        if true:
            mount = mount.compose(self.mount_error)
            target = target.compose(self.placement_error)
        T_lab_camera = axes_transform(positions).compose(mount)
        return T_lab_camera.inverse().compose(target)


@dataclass
class BenchFrame:
    """One simulated capture with its truths."""

    time_s: float
    frame: RenderedFrame
    T_true: RigidTransform  # what the world rendered
    T_lab_truth: RigidTransform  # what the lab computes from encoders + nominal geometry
    encoders: dict[str, float]


@dataclass
class SimulatedBench:
    """Camera + scene + sensor + turntable + geometry, driven by explicit time."""

    camera: CameraModel = field(default_factory=CameraModel)
    scene: TargetScene = field(default_factory=TargetScene)
    sensor: SensorModel = field(default_factory=SensorModel)
    geometry: LabGeometry = field(default_factory=LabGeometry)
    turntable: Turntable = field(default_factory=Turntable)
    seed: int = 0

    def __post_init__(self) -> None:
        self.rng = np.random.default_rng(self.seed)

    def poses_at(self, time_s: float) -> tuple[RigidTransform, RigidTransform, dict[str, float]]:
        """(T_true the world renders, T_lab_truth from encoders, encoder readings) at a time."""
        true_pos = self.turntable.true_position(time_s)
        enc = self.turntable.encoder_position(time_s)
        T_true = self.geometry.T_camera_target(true_pos, true=True)
        return T_true, self.geometry.T_camera_target(enc, true=False), enc

    def subframe_poses(self, time_s: float, T_true: RigidTransform) -> list | None:
        """True poses at the four phase sub-frames of the frame stamped ``time_s``, or
        None when the table does not move over them (or the sensor's motion artefacts are
        off): a slewing table gives motion artefacts (``render.combine_subframes``).

        A frame's stamp is the middle of its acquisition: the sub-frames are taken at
        ``time_s + (k - 1.5) * period`` (k = 0..3), so ``T_true`` (the pose at
        ``time_s``, the truth a pose is judged against) is the pose the four samples
        average about. Before 2026-12 the stamp was the first sub-frame's start, and a
        pose measured on a slewing table read 1.5 sub-frame periods late against its
        truth: on the 5 deg / 4 s yaw sine at 2 m, NEES/6 against the truth at the first
        sub-frame's start and at the middle 1.7 and 0.5 with the centroid-error priors
        before 2026-12, 5.3 and 1.4 with the size-scaled ones (one run of 100 poses)."""
        if not self.sensor.motion_artefacts:
            return None
        period = self.sensor.subframe_period_s(
            float(np.linalg.norm(T_true.t_mm)), full_scale_counts=reference_full_scale(self.camera)
        )
        positions = [self.turntable.true_position(time_s + (k - 1.5) * period) for k in range(4)]
        if all(p == positions[0] for p in positions[1:]):
            return None
        return [self.geometry.T_camera_target(p, true=True) for p in positions]

    def capture(self, time_s: float) -> BenchFrame:
        T_true, T_lab, enc = self.poses_at(time_s)
        subframes = self.subframe_poses(time_s, T_true)
        frame = render_frame(
            self.camera,
            self.scene,
            T_true,
            self.sensor,
            self.rng,
            time_s=time_s,
            subframe_poses=subframes,
        )
        return BenchFrame(time_s, frame, T_true, T_lab, enc)
