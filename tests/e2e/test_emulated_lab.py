"""The dashboard, unchanged, on the whole system run against the two device emulators
(the TOFcam-660 protocol and the SCPI rate table) over one simulated lab."""

from __future__ import annotations

import pytest

from backend.drivers.factory import build_devices
from backend.emulators.lab import EmulatedLab
from tests.backend.conftest import TOKEN, LiveServer, make_settings
from tests.e2e.conftest import SHOTS

CAMERA_ADDRESS = "127.0.0.6"


@pytest.fixture
def server(tmp_path):
    with EmulatedLab(camera_address=CAMERA_ADDRESS, table_port=0) as lab:
        lab.world.time_scale = 3.0
        host, port = lab.table.address
        settings = make_settings(
            tmp_path / "data", camera=f"tofcam660:{CAMERA_ADDRESS}", motion=f"scpi:{host}:{port}"
        )
        with LiveServer(settings, build_devices(settings)) as srv:
            yield srv


def test_dashboard_drives_the_emulated_lab(server, page_for):
    page = page_for(server.base_url, TOKEN)
    page.goto(server.base_url + "/")
    page.get_by_test_id("pose-x").wait_for(timeout=20_000)
    page.get_by_test_id("frame-index").wait_for(timeout=20_000)  # raw frames drawn
    page.wait_for_function(
        "document.querySelector('[data-testid=camera-device]')?.innerText"
        ".includes('ESPROS TOFcam-660 3.59 at 127.0.0.6')",
        timeout=10_000,
    )
    assert "ACUTROL3000" in page.get_by_test_id("motion-device").inner_text()
    x0 = float(page.get_by_test_id("pose-x").inner_text())
    page.get_by_test_id("target-yaw").fill("10")
    page.get_by_test_id("go-yaw").click()  # through the SCPI driver and the emulator
    page.wait_for_function(
        "Math.abs(parseFloat(document.querySelector('[data-testid=pos-yaw]').innerText) - 10)"
        " < 0.01",
        timeout=20_000,
    )
    page.wait_for_timeout(1500)
    x1 = float(page.get_by_test_id("pose-x").inner_text())
    assert x1 < x0 - 300.0, (x0, x1)  # the emulated camera saw the emulated table turn
    page.screenshot(path=str(SHOTS / "dashboard-emulated-lab.png"))
