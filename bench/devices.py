"""Link loss and recovery of the real-device drivers, measured against the shipped
emulators (one simulated lab), with the server's and drivers' default time-outs and
back-offs.

For each scenario and repeat: the time from the fault until ``/api/health`` (camera) or
``/api/motion`` (rate table) shows the device degraded, and the time from the device being
back until it works again (a new ok pose; motion state ok). Scenarios: the camera's
command connection dropped (device stays up); the camera switched off for 2 s; the rate
table's controller switched off for 2 s. Medians and maxima over repeats.

Run: ``python bench/devices.py [--repeats 5]``
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench._common import all_cores, table  # noqa: E402

CAMERA_ADDRESS = "127.0.0.9"
OFF_S = 2.0


def _until(pred, timeout_s: float = 30.0, poll_s: float = 0.005) -> float:
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout_s:
        if pred():
            return time.monotonic() - t0
        time.sleep(poll_s)
    raise TimeoutError("condition not reached")


def run(repeats: int) -> dict[str, list[tuple[float, float]]]:
    from fastapi.testclient import TestClient

    from backend.app import create_app
    from backend.drivers.factory import build_devices
    from backend.emulators.lab import EmulatedLab
    from backend.emulators.rate_table import RateTableEmulator
    from backend.emulators.tofcam660 import TofCam660Emulator
    from backend.settings import Settings

    out: dict[str, list[tuple[float, float]]] = {"drop": [], "camera_off": [], "table_off": []}
    with (
        tempfile.TemporaryDirectory() as tmp,
        EmulatedLab(camera_address=CAMERA_ADDRESS, table_port=0) as lab,
    ):
        host, port = lab.table.address
        settings = Settings(
            data_dir=Path(tmp),
            api_token="bench-token-0123456789",
            viser=False,
            camera=f"tofcam660:{CAMERA_ADDRESS}",
            motion=f"scpi:{host}:{port}",
            allowed_hosts=["testserver"],
        )
        with TestClient(create_app(settings, build_devices(settings))) as client:

            def cam_state() -> str:
                return client.get("/api/health").json()["camera"]["state"]

            def new_pose(after: int):
                def ok() -> bool:
                    r = client.get("/api/pose/latest")
                    return (
                        r.status_code == 200
                        and r.json()["ok"]
                        and (r.json()["frame_index"] > after)
                    )

                return ok

            def last_index() -> int:
                return client.get("/api/pose/latest").json()["frame_index"]

            _until(new_pose(0))
            for _ in tqdm(range(repeats), desc="devices", unit="repeat"):
                _until(lambda: cam_state() == "ok")
                lab.camera.drop_clients()
                t_deg = _until(lambda: cam_state() == "degraded")
                t0 = time.monotonic()
                _until(new_pose(last_index()))
                out["drop"].append((t_deg, t_deg + time.monotonic() - t0))

                _until(lambda: cam_state() == "ok")
                lab.camera.close()
                t_deg = _until(lambda: cam_state() == "degraded")
                time.sleep(OFF_S)
                index = last_index()
                lab.camera = TofCam660Emulator(lab.world, CAMERA_ADDRESS).start()
                out["camera_off"].append((t_deg, _until(new_pose(index))))

                lab.table.close()
                t_deg = _until(lambda: client.get("/api/motion").json()["state"] == "degraded")
                time.sleep(OFF_S)
                lab.table = RateTableEmulator(lab.world, host, port).start()
                back = _until(lambda: client.get("/api/motion").json()["state"] == "ok")
                out["table_off"].append((t_deg, back))
    return out


LABELS = {
    "drop": ("camera: command link dropped", "after the drop"),
    "camera_off": ("camera: off for 2 s", "after it is back"),
    "table_off": ("rate table: controller off for 2 s", "after it is back"),
}


def markdown(data: dict[str, list[tuple[float, float]]]) -> str:
    rows = []
    for key, pairs in data.items():
        a = np.array(pairs)
        what, since = LABELS[key]
        rows.append(
            [
                what,
                f"{np.median(a[:, 0]) * 1000:.0f} / {a[:, 0].max() * 1000:.0f}",
                f"{np.median(a[:, 1]) * 1000:.0f} / {a[:, 1].max() * 1000:.0f}",
                since,
                str(len(a)),
            ]
        )
    return table(
        [
            "fault",
            "degraded after, ms (median / max)",
            "working again, ms (median / max)",
            "working again counted",
            "repeats",
        ],
        rows,
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    all_cores()  # the server, its drivers and the emulators share the machine, as in use
    print(markdown(run(args.repeats)))


if __name__ == "__main__":
    main()
