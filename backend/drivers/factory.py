"""Build the configured drivers from settings."""

from __future__ import annotations

from dataclasses import dataclass

from backend.drivers.base import CameraDriver, CameraSettings, MotionDriver, MotionError
from backend.drivers.reference import EncoderReferencedCamera
from backend.drivers.replay import ReplayCamera
from backend.drivers.sim import SimCamera, SimMotion, SimWorld, make_sim_world
from backend.settings import Settings, visa_resource
from tofpose.core.catalog import Catalog
from tofpose.sim.bench import LabGeometry


@dataclass
class Devices:
    """The drivers the app owns. ``world`` is set when a simulated lab backs them."""

    camera: CameraDriver
    motion: MotionDriver | None
    world: SimWorld | None = None
    catalog_hint: Catalog | None = None  # a replayed recording's own catalog

    @property
    def lab_geometry(self) -> LabGeometry | None:
        """The lab's nominal geometry that turns encoder readings into a reference pose:
        the simulated lab's, or the one an encoder-referenced real camera uses; None
        without a motion system."""
        if self.motion is None:
            return None
        if self.world is not None:
            return self.world.bench.geometry
        return getattr(self.camera, "geometry", None)

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
    initial = CameraSettings(frame_rate_hz=settings.frame_rate_hz)
    if settings.camera == "sim":
        assert world is not None  # made above for a simulated camera or motion
        camera: CameraDriver = SimCamera(world, initial)
    elif settings.camera.startswith("tofcam660:"):
        from backend.drivers.tofcam660 import TofCam660Driver  # the optional vendor client

        camera = TofCam660Driver(
            settings.camera.removeprefix("tofcam660:"), settings=initial, connect_now=False
        )
    else:
        camera = ReplayCamera(settings.camera.removeprefix("replay:"), settings.replay_rate_hz)
        hint = camera.catalog
    motion: MotionDriver | None = None
    if settings.motion == "sim":
        assert world is not None
        motion = SimMotion(world)
    elif settings.motion.startswith("scpi:"):
        from backend.drivers.scpi import ScpiRateTable  # the optional PyVISA

        try:
            motion = ScpiRateTable(str(visa_resource(settings.motion)))
        except MotionError:
            camera.close()
            raise
    if motion is not None and not isinstance(camera, (SimCamera, ReplayCamera)):
        # a real camera knows no truth: the lab reference comes from the encoders
        geometry = LabGeometry(target_distance_mm=settings.lab_target_distance_mm)
        camera = EncoderReferencedCamera(camera, motion, geometry)
    return Devices(camera, motion, world, hint)
