"""Build the configured drivers from settings."""

from __future__ import annotations

from dataclasses import dataclass

from backend.drivers.base import CameraDriver, CameraSettings, MotionDriver
from backend.drivers.replay import ReplayCamera
from backend.drivers.sim import SimCamera, SimMotion, SimWorld, make_sim_world
from backend.settings import Settings
from tofpose.catalog import Catalog


@dataclass
class Devices:
    """The drivers the app owns. ``world`` is set when a simulated lab backs them."""

    camera: CameraDriver
    motion: MotionDriver | None
    world: SimWorld | None = None
    catalog_hint: Catalog | None = None  # a replayed recording's own catalog

    def close(self) -> None:
        self.camera.close()
        if self.motion is not None:
            self.motion.close()


def build_devices(settings: Settings, catalog: Catalog | None = None) -> Devices:
    """Drivers for ``settings.camera`` / ``settings.motion``.

    Raises ``RecordingError`` for an unusable replay file.
    """
    world = None
    if settings.camera == "sim" or settings.motion == "sim":
        world = make_sim_world(
            target_distance_mm=settings.sim_target_distance_mm,
            start_rail_mm=settings.sim_start_rail_mm,
            catalog=catalog,
            seed=settings.sim_seed,
            time_scale=settings.sim_time_scale,
        )
    hint = None
    if settings.camera == "sim":
        initial = CameraSettings(frame_rate_hz=settings.frame_rate_hz)
        camera: CameraDriver = SimCamera(world, initial)
    else:
        camera = ReplayCamera(settings.camera.removeprefix("replay:"), settings.replay_rate_hz)
        hint = camera.catalog
    motion = SimMotion(world) if settings.motion == "sim" else None
    return Devices(camera, motion, world, hint)
