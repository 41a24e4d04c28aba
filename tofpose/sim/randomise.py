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
  none.

Used by the physics robustness study (``bench/physics.py``) and by Monte-Carlo accuracy
studies (``tofpose.study``).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from tofpose.core.camera import CameraModel
from tofpose.core.catalog import Catalog
from tofpose.core.geometry import RigidTransform, rotation_from_euler_deg
from tofpose.sim.background import synthetic_room
from tofpose.sim.bench import R_FACING
from tofpose.sim.render import SensorModel
from tofpose.sim.scene import TargetScene
from tofpose.sim.systematic import SystematicErrors

FAMILIES = ("ideal", "grey plate", "lens blur", "gains", "systematic", "background", "all")
ARM_PROBABILITY = 0.3  # share of background frames with an arm in front of the target


def draw_physics(
    family: str, rng: np.random.Generator, catalog: Catalog, ambient_lux: float | None = None
) -> tuple[TargetScene, SensorModel]:
    """(TargetScene, SensorModel) of one frame of ``family`` (module docstring).
    ``ambient_lux``: the ambient light, when the caller sets it (a study's grid axis);
    None keeps the sensor's default, except for ``all``, which draws 1-10 klx.
    ``ValueError`` naming the family when it is not one of ``FAMILIES``."""
    if family not in FAMILIES:
        raise ValueError(f"unknown physics family {family!r} (one of {', '.join(FAMILIES)})")
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
