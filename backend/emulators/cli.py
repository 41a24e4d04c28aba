"""``tofpose emulate camera|table|lab``: run device emulators until interrupted."""

from __future__ import annotations

import sys
import threading

from backend.drivers.sim import make_sim_world
from backend.emulators.lab import EmulatedLab
from backend.emulators.rate_table import RateTableEmulator
from backend.emulators.tofcam660 import COMMAND_PORT, DATA_PORT, TofCam660Emulator


def run(opts: dict) -> int:
    """Start what ``opts["device"]`` names, print where it listens, serve until Ctrl-C."""
    device = opts["device"]
    world = make_sim_world(
        target_distance_mm=opts["target_distance_mm"],
        start_rail_mm=opts["start_rail_mm"],
        seed=opts["seed"],
    )
    emu: TofCam660Emulator | RateTableEmulator | EmulatedLab
    try:
        if device == "camera":
            emu = TofCam660Emulator(world, opts["address"])
            lines = [_camera_line(opts["address"])]
        elif device == "table":
            emu = RateTableEmulator(world, opts["host"], opts["port"])
            lines = [_table_line(*emu.address)]
        else:
            lab = EmulatedLab(
                camera_address=opts["camera_address"],
                table_host=opts["host"],
                table_port=opts["table_port"],
                world=world,
            )
            lines = [_camera_line(opts["camera_address"]), _table_line(*lab.table.address)]
            emu = lab
    except OSError as exc:
        print(f"tofpose emulate {device}: cannot listen: {exc}", file=sys.stderr)
        return 2
    emu.start()
    print("\n".join(["tofpose emulator (simulated lab), Ctrl-C to stop:", *lines]), flush=True)
    try:
        threading.Event().wait()
    except KeyboardInterrupt:
        pass
    finally:
        emu.close()
    return 0


def _camera_line(address: str) -> str:
    return (
        f"  TOFcam-660     {address}  (TCP {COMMAND_PORT}, images over UDP to port "
        f"{DATA_PORT});  tofpose serve --camera tofcam660:{address}"
    )


def _table_line(host: str, port: int) -> str:
    return (
        f"  rate table     TCPIP::{host}::{port}::SOCKET  (SCPI);  "
        f"tofpose serve --motion scpi:{host}:{port}"
    )
