"""Domain randomisation: the physics and the pose of one simulated frame, drawn at random
from what real targets, lenses and sensors do (``docs/simulator.md``'s knobs).

Physics families (each frame draws its own values):

* ``ideal``: the simulator's defaults (black anodised plate, wall 2 m behind);
* ``grey plate``: plate reflectance 0.25-0.6 (MLI-covered mock-ups), no wall;
* ``lens blur``: PSF core sigma 0.3-1.5 px, halo 0-10 % of the energy at 4x;
* ``gains``: each reflector's return 0.7-1.3 of a new one's, fall-off exponent 2-6;
* ``systematic``: an uncalibrated camera (``draw_systematic_errors``): cyclic error of
  0-15 mm (4th harmonic) and 0-5 mm (8th), random phases; amplitude-related error of
  -10 to +2 mm per decade; per-pixel offsets of 0-10 mm at the corners and 0-4 mm per
  pixel, a fresh pattern; a zero offset of -15 to +15 mm; lens scatter 0-0.8 %;
* ``background``: a real scene around the target (``tofpose.sim.background.
  synthetic_room``: walls, floor, furniture, a person, shiny fittings, and in 30 % of
  frames an arm in front of the target covering part of it), 1-10 klx ambient; drawn by
  ``draw_background`` once the pose is known;
* ``all``: every knob above but the background drawn at once, ambient 1-10 klx, wall or
  none;

and five more (``EXTRA_FAMILIES``) that are drawn whole by ``draw_frame``, since they
need the pose or a camera of their own:

* ``saturating``: the defaults with a fixed exposure set for the plate, so that a
  reflector facing the camera at the target's range reads 2-5x full scale
  (``fixed_exposure``): the markers' cores are clipped with no distance, only their rims
  are measured;
* ``glints``: the defaults plus 15 specular glints (``tofpose.sim.glints``): Gaussian
  spots of sigma 0.5-1.6 px and peaks of 400-2500 reference counts, each within 250 mm
  of the target's range and in and around its image (up to 1.5x its half extent from
  its centre), none hidden by the target;
* ``other sensor``: the defaults on a second sensor profile (``other_sensor_camera``:
  640 x 480 px, twice the focal length in px so the same field of view, 20 MHz
  modulation, count scale 4); the pipeline is set for it by
  ``tofpose.config.config_for_camera``;
* ``bright plate``: a light-painted plate (reflectance 0.6-0.95, no wall) with weaker
  reflectors: each reflector's return 0.7-1.3 of the others' and the retro-reflector
  gain log-uniform over ``BRIGHT_PLATE_RETRO_GAIN`` (4-40 times a white diffuser, where
  the default is 40: lower grades of retro-reflective sheeting return a tenth of
  prismatic sheeting's). A face-on marker then reads retro gain x its gain /
  reflectance times the plate, about 3-90x (where the defaults give ~400x), and the
  exposure the markers set lifts the plate well above the noise.
* ``out of view``: the defaults with the target's centre near an edge of the image
  (``draw_edge_pose``: 0.85-1.2 of the half field of view off the axis towards one
  side, so that part of the target, often all but three of its markers, is out of the
  frame).

Used by the physics robustness study (``bench/physics.py``, all twelve) and by Monte-Carlo
accuracy studies (``tofpose.study``: ``FAMILIES``, drawn by ``draw_physics``,
``draw_pose`` and ``draw_background``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from tofpose.core.camera import CameraModel
from tofpose.core.catalog import Catalog
from tofpose.core.geometry import RigidTransform, rotation_from_euler_deg
from tofpose.sim.background import synthetic_room
from tofpose.sim.bench import R_FACING
from tofpose.sim.glints import Glints, draw_glints, render_glints
from tofpose.sim.render import (
    RenderedFrame,
    SensorModel,
    reference_full_scale,
    render_frame,
    sensor_for_camera,
)
from tofpose.sim.scene import TargetScene
from tofpose.sim.systematic import SystematicErrors

#: the families ``draw_physics`` draws (a study's and the API's)
FAMILIES = ("ideal", "grey plate", "lens blur", "gains", "systematic", "background", "all")
#: the families only ``draw_frame`` draws (they need the pose, their own camera, or a
#: sensor knob a study's families keep: appended so that the study's draws stay)
EXTRA_FAMILIES = ("saturating", "glints", "other sensor", "bright plate", "out of view")
ALL_FAMILIES = FAMILIES + EXTRA_FAMILIES
ARM_PROBABILITY = 0.3  # share of background frames with an arm in front of the target
#: ``saturating``: a face-on reflector at the target's range reads this many full scales
OVEREXPOSURE = (2.0, 5.0)
N_GLINTS = 15  # ``glints``: glints per frame
#: ``bright plate``: the retro-reflector gain's range (log-uniform), and the plate's
#: reflectance
BRIGHT_PLATE_RETRO_GAIN = (4.0, 40.0)
BRIGHT_PLATE_REFLECTANCE = (0.6, 0.95)
#: ``out of view``: the target centre's distance off the axis towards one edge, in half
#: fields of view (beyond 1 it lies outside the image)
EDGE_OFFSET = (0.85, 1.2)


def other_sensor_camera() -> CameraModel:
    """The ``other sensor`` family's camera: 640 x 480 px with twice the EPC660's focal
    length in px (fx = fy = 650: the same field of view), 20 MHz modulation (7.49 m
    unambiguous range, no unwrapping), gray counts 4x the EPC660's (full scale
    4 x 4095)."""
    ref = CameraModel()
    return CameraModel(
        width=2 * ref.width,
        height=2 * ref.height,
        fx=2.0 * ref.fx,
        fy=2.0 * ref.fy,
        cx=319.5,
        cy=239.5,
        name="640x480 20 MHz (robustness study)",
        full_scale_counts=4.0 * ref.full_scale_counts,
        modulation_frequency_hz=20.0e6,
        count_scale=4.0,
    )


def camera_for(family: str) -> CameraModel:
    """The camera a family's frames are taken with: ``other_sensor_camera`` for ``other
    sensor``, the EPC660 (``CameraModel()``) for the others. ``ValueError`` naming an
    unknown family."""
    if family not in ALL_FAMILIES:
        raise ValueError(f"unknown physics family {family!r} (one of {', '.join(ALL_FAMILIES)})")
    return other_sensor_camera() if family == "other sensor" else CameraModel()


@dataclass(frozen=True)
class DrawnFrame:
    """Everything one frame of a family is rendered from (``draw_frame``).

    camera : the family's camera (``camera_for``); scene, sensor : its physics (the
    sensor at the camera's modulation frequency); T_camera_target : the true pose;
    glints : the frame's glints (family ``glints``), else None.
    """

    family: str
    camera: CameraModel
    scene: TargetScene
    sensor: SensorModel
    T_camera_target: RigidTransform
    glints: Glints | None = None

    def render(self, rng: np.random.Generator) -> RenderedFrame:
        """The frame (``render_frame``, then ``render_glints`` when it has glints)."""
        f = render_frame(self.camera, self.scene, self.T_camera_target, self.sensor, rng)
        if self.glints is None:
            return f
        return render_glints(f, self.glints, self.camera, self.sensor, rng)


def draw_frame(
    family: str,
    range_m: float,
    rng: np.random.Generator,
    catalog: Catalog,
    *,
    max_attitude_deg: float = 20.0,
    offset_fraction: float = 0.5,
    ambient_lux: float | None = None,
) -> DrawnFrame:
    """One frame of any family of ``ALL_FAMILIES`` at ``range_m``: ``draw_physics`` (the
    defaults for ``EXTRA_FAMILIES``), ``draw_pose``, ``draw_background``, then what the
    extra families draw once the pose is known: ``saturating`` its overexposure
    (``OVEREXPOSURE``, ``fixed_exposure``), ``glints`` its glints (``draw_glints``).
    A family of ``FAMILIES`` draws from ``rng`` exactly what those three calls draw."""
    camera = camera_for(family)
    base = family if family in FAMILIES else "ideal"
    scene, sensor = draw_physics(base, rng, catalog, ambient_lux)
    sensor = sensor_for_camera(sensor, camera)
    if family == "out of view":
        T = draw_edge_pose(range_m, rng, camera, max_attitude_deg)
    else:
        T = draw_pose(range_m, rng, camera, max_attitude_deg, offset_fraction)
    scene = draw_background(family, scene, rng, camera, T)
    glints = None
    if family == "saturating":
        overexposure = float(rng.uniform(*OVEREXPOSURE))
        range_mm = float(np.linalg.norm(T.t_mm))
        sensor = fixed_exposure(sensor, camera, range_mm, overexposure)
    if family == "glints":
        glints = draw_glints(rng, camera, scene, T, n=N_GLINTS)
    if family == "bright plate":
        scene, sensor = bright_plate(scene, sensor, rng, len(catalog))
    return DrawnFrame(family, camera, scene, sensor, T, glints)


def bright_plate(
    scene: TargetScene, sensor: SensorModel, rng: np.random.Generator, n_reflectors: int
) -> tuple[TargetScene, SensorModel]:
    """``scene`` and ``sensor`` as the ``bright plate`` family draws them: the plate's
    reflectance over ``BRIGHT_PLATE_REFLECTANCE``, no wall, each of the
    ``n_reflectors`` reflectors' gain 0.7-1.3, the retro-reflector gain log-uniform
    over ``BRIGHT_PLATE_RETRO_GAIN``."""
    lo, hi = np.log(BRIGHT_PLATE_RETRO_GAIN)
    scene = replace(
        scene,
        plate_reflectance=float(rng.uniform(*BRIGHT_PLATE_REFLECTANCE)),
        wall_distance_mm=None,
        reflector_gains=tuple(rng.uniform(0.7, 1.3, n_reflectors).tolist()),
    )
    return scene, replace(sensor, retro_gain=float(np.exp(rng.uniform(lo, hi))))


def fixed_exposure(
    sensor: SensorModel, camera: CameraModel, distance_mm: float, overexposure: float
) -> SensorModel:
    """``sensor`` with its exposure fixed (no auto exposure) so that a reflector facing
    the camera at ``distance_mm`` reads ``overexposure`` times ``camera``'s full scale:
    the auto exposure's rule (``SensorModel.exposure_for``) aimed at ``overexposure``
    instead of ``auto_exposure_fill``. A manual setting, not held to the auto exposure's
    ``integration_limits_us``: at 8 m on the EPC660 it is 26-66 ms for 2-5x."""
    if not overexposure > 0:
        raise ValueError(f"overexposure must be positive, got {overexposure}")
    aimed = replace(
        sensor,
        auto_exposure=True,
        auto_exposure_fill=overexposure,
        integration_limits_us=(sensor.integration_limits_us[0], math.inf),
    )
    t_us = aimed.exposure_for(distance_mm, full_scale_counts=reference_full_scale(camera))
    return replace(sensor, auto_exposure=False, integration_time_us=t_us)


def draw_physics(
    family: str, rng: np.random.Generator, catalog: Catalog, ambient_lux: float | None = None
) -> tuple[TargetScene, SensorModel]:
    """(TargetScene, SensorModel) of one frame of ``family`` (module docstring).
    ``ambient_lux``: the ambient light, when the caller sets it (a study's grid axis);
    None keeps the sensor's default, except for ``all``, which draws 1-10 klx.
    ``ValueError`` naming the family when it is not one of ``FAMILIES`` (one of
    ``EXTRA_FAMILIES``: ``draw_frame`` draws it)."""
    if family in EXTRA_FAMILIES:
        raise ValueError(f"physics family {family!r} needs its pose or camera: use draw_frame")
    if family not in FAMILIES:
        raise ValueError(f"unknown physics family {family!r} (one of {', '.join(ALL_FAMILIES)})")
    scene: dict = {"catalog": catalog}
    sensor: dict = {}
    if family in ("grey plate", "all"):
        scene["plate_reflectance"] = float(rng.uniform(0.25, 0.6))
        scene["wall_distance_mm"] = None
    if family in ("lens blur", "all"):
        sensor["blur_sigma_px"] = float(rng.uniform(0.3, 1.5))
        sensor["psf_halo_fraction"] = float(rng.uniform(0.0, 0.1))
    if family in ("gains", "all"):
        scene["reflector_gains"] = tuple(rng.uniform(0.7, 1.3, len(catalog)).tolist())
        scene["retro_falloff_exponent"] = float(rng.uniform(2.0, 6.0))
    if family == "background":
        scene["wall_distance_mm"] = None  # the room has its own
        if ambient_lux is None:
            sensor["ambient_lux"] = float(rng.uniform(1000.0, 10000.0))
    if family in ("systematic", "all"):
        sensor["systematic"] = draw_systematic_errors(rng)
    if ambient_lux is not None:
        sensor["ambient_lux"] = float(ambient_lux)
    if family == "all":
        if ambient_lux is None:
            sensor["ambient_lux"] = float(rng.uniform(1000.0, 10000.0))
        if rng.random() < 0.5:
            scene["wall_distance_mm"] = 2000.0
    return TargetScene(**scene), SensorModel(**sensor)


def draw_background(
    family: str,
    scene: TargetScene,
    rng: np.random.Generator,
    camera: CameraModel,
    T_camera_target: RigidTransform,
) -> TargetScene:
    """``scene`` with the real scene of family ``background`` around the target at
    ``T_camera_target`` (``synthetic_room``; the arm reaches across the target's line of
    sight); other families' scenes are returned as they are, and draw nothing from
    ``rng``."""
    if family != "background":
        return scene
    t = np.asarray(T_camera_target.t_mm, float)
    room = synthetic_room(camera, rng, float(np.linalg.norm(t)), t, arm_probability=ARM_PROBABILITY)
    return replace(scene, background=room)


def draw_systematic_errors(rng: np.random.Generator) -> SystematicErrors:
    """The range errors of one uncalibrated camera, each term within the span published
    ToF calibration studies report (``docs/simulator.md``): the cyclic error's 4th
    harmonic 0-15 mm and 8th 0-5 mm at random phases, -10 to +2 mm per decade of
    amplitude, per-pixel offsets of 0-10 mm at the corners plus 0-4 mm per pixel (a fresh
    pattern per camera), a zero offset of -15 to +15 mm (no drift over time: the frame is
    taken warm), lens scatter of 0-0.8 % of the light. The frame's range error common to
    a target's reflectors is then up to ~40 mm, a few to 20 mm typically."""
    return SystematicErrors(
        wiggle_amplitudes_mm=(float(rng.uniform(0.0, 15.0)), float(rng.uniform(0.0, 5.0))),
        wiggle_phases_rad=tuple(rng.uniform(0.0, 2.0 * np.pi, 2).tolist()),
        amplitude_mm_per_decade=float(rng.uniform(-10.0, 2.0)),
        pixel_offset_sigma_mm=float(rng.uniform(0.0, 4.0)),
        pixel_offset_corner_mm=float(rng.uniform(0.0, 10.0)),
        pixel_offset_seed=int(rng.integers(0, 2**31 - 1)),
        drift_mm_per_kelvin=0.0,
        scatter_fraction=float(rng.uniform(0.0, 0.008)),
        offset_mm=float(rng.uniform(-15.0, 15.0)),
    )


def draw_edge_pose(
    range_m: float,
    rng: np.random.Generator,
    camera: CameraModel,
    max_attitude_deg: float = 20.0,
) -> RigidTransform:
    """T_camera_target of an ``out of view`` frame: the target centre at ``range_m``,
    ``EDGE_OFFSET`` half fields of view off the axis towards one of the four edges (drawn
    at random) and up to half of it along that edge, attitude as ``draw_pose``'s."""
    p, y, r = rng.uniform(-max_attitude_deg, max_attitude_deg, 3)
    R = rotation_from_euler_deg(p, y, r) @ R_FACING
    half = np.array([(camera.width / 2) / camera.fx, (camera.height / 2) / camera.fy])
    side = int(rng.integers(4))
    across = rng.uniform(*EDGE_OFFSET) * (1.0 if side % 2 == 0 else -1.0)
    along = rng.uniform(-0.5, 0.5)
    uv = np.array([across, along]) if side < 2 else np.array([along, across])
    direction = np.array([*(uv * half), 1.0])
    t = range_m * 1000.0 * direction / np.linalg.norm(direction)
    return RigidTransform(R, t)


def draw_pose(
    range_m: float,
    rng: np.random.Generator,
    camera: CameraModel,
    max_attitude_deg: float = 20.0,
    offset_fraction: float = 0.5,
) -> RigidTransform:
    """T_camera_target of one frame: the target centre at ``range_m``, up to
    ``offset_fraction`` of the half field of view off the optical axis (uniform in the
    image plane), attitude uniform within +-``max_attitude_deg`` per axis (pitch, yaw,
    roll) from facing the camera."""
    p, y, r = rng.uniform(-max_attitude_deg, max_attitude_deg, 3)
    R = rotation_from_euler_deg(p, y, r) @ R_FACING
    half_u = offset_fraction * (camera.width / 2) / camera.fx
    half_v = offset_fraction * (camera.height / 2) / camera.fy
    direction = np.array([rng.uniform(-half_u, half_u), rng.uniform(-half_v, half_v), 1.0])
    t = range_m * 1000.0 * direction / np.linalg.norm(direction)
    return RigidTransform(R, t)
