"""One simulated lab behind both device emulators: the TOFcam-660 emulator and the
rate-table emulator share one ``SimWorld``, so that moving the emulated table changes
what the emulated camera sees, as on the real bench (``tofpose emulate lab``)."""

from __future__ import annotations

from backend.drivers.sim import SimWorld, make_sim_world
from backend.emulators.rate_table import RateTableEmulator
from backend.emulators.tofcam660 import COMMAND_PORT, DATA_PORT, TofCam660Emulator


class EmulatedLab:
    """Both emulators over one world; ``start()``/``close()`` or a ``with`` block."""

    def __init__(
        self,
        *,
        camera_address: str = "127.0.0.2",
        table_host: str = "127.0.0.1",
        table_port: int = 5025,
        world: SimWorld | None = None,
        camera_command_port: int = COMMAND_PORT,
        camera_data_port: int = DATA_PORT,
        seed: int = 0,
    ) -> None:
        self.world = world or make_sim_world(seed=seed)
        self.table = RateTableEmulator(self.world, table_host, table_port)
        try:
            self.camera = TofCam660Emulator(
                self.world,
                camera_address,
                command_port=camera_command_port,
                data_port=camera_data_port,
            )
        except OSError:
            self.table.close()
            raise

    def start(self) -> EmulatedLab:
        self.table.start()
        self.camera.start()
        return self

    def close(self) -> None:
        self.camera.close()
        self.table.close()

    def __enter__(self) -> EmulatedLab:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()
