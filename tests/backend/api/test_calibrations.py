"""Calibration from a campaign on the simulated lab: the simulator's known mount and
placement errors are recovered, and a report against the calibrated reference shows the
x/y error of the lab's nominal reference gone."""

from __future__ import annotations

import numpy as np
import pytest

from backend.drivers.factory import build_devices
from tests.backend.api.test_campaigns import _run
from tests.backend.conftest import AUTH, make_settings, running_app
from tofpose.core.geometry import RigidTransform, rotation_angle_deg

PLACEMENT_ERROR = RigidTransform.from_euler_deg(-0.15, 0.1, 0.3, (3.0, -2.0, 4.0))


@pytest.fixture
def lab(tmp_path):
    settings = make_settings(tmp_path / "data", sim_time_scale=5.0, frame_rate_hz=20.0)
    devices = build_devices(settings)
    devices.world.bench.geometry.placement_error = PLACEMENT_ERROR
    with running_app(settings, devices) as c:
        yield c, devices.world.bench.geometry


def test_calibration_recovers_mount_and_placement_and_fixes_the_report(lab):
    c, geom = lab
    cal_campaign = _run(
        c,
        {
            "name": "cal",
            "frames_per_point": 12,
            "settle_s": 0.2,
            "generator": {"kind": "calibration", "rails_mm": [11000, 12500]},
        },
        timeout_s=180,
    )
    assert cal_campaign["status"] == "done", cal_campaign
    r = c.post(
        "/api/calibrations",
        json={"campaign_id": cal_campaign["id"], "name": "bench-1"},
        headers=AUTH,
    )
    assert r.status_code == 201, r.text
    cal = r.json()
    true_mount = geom.T_inner_camera.compose(geom.mount_error)
    true_place = geom.T_lab_target.compose(geom.placement_error)
    M, P = np.array(cal["mount"]["matrix"]), np.array(cal["placement"]["matrix"])
    mount_deg = rotation_angle_deg(M[:3, :3], true_mount.R)
    mount_mm = float(np.linalg.norm(M[:3, 3] - true_mount.t_mm))
    place_deg = rotation_angle_deg(P[:3, :3], true_place.R)
    place_mm = float(np.linalg.norm(P[:3, 3] - true_place.t_mm))
    print(
        f"mount {mount_deg:.4f} deg {mount_mm:.3f} mm; placement {place_deg:.4f} deg "
        f"{place_mm:.3f} mm; residual {cal['residual_rms_mm']:.3f} mm "
        f"{cal['residual_rms_deg']:.4f} deg"
    )
    # attitude: within 4 of its own sigmas (the geodesic angle is the norm of the
    # per-axis errors, so against the norm of the per-axis sigmas), and well inside the
    # 0.15 deg a sensor test needs (one CI run read 0.023 deg for the placement: the
    # frames differ from run to run; 0.02 was a fixed bound)
    for angle, sigma in (
        (mount_deg, cal["mount_sigma_deg"]),
        (place_deg, cal["placement_sigma_deg"]),
    ):
        print(f"{angle:.4f} deg against sigmas {sigma}")
        assert angle < 4.0 * float(np.linalg.norm(sigma)) and angle < 0.05, (angle, sigma)
    # Five runs of this campaign gave translation errors of 0.11-0.53 mm against reported
    # per-axis sigmas of 0.13-0.28 mm (the frames, hence the noise, differ from run to run):
    # the bound is ~2x the median error, and each axis must lie within 4 of its own sigmas.
    assert mount_mm < 0.8 and place_mm < 0.8
    for got, true, sigma in (
        (M, true_mount, cal["mount_sigma_mm"]),
        (P, true_place, cal["placement_sigma_mm"]),
    ):
        z = np.abs(got[:3, 3] - true.t_mm) / np.array(sigma)
        assert np.all(z < 4.0), (z, sigma)
    assert c.get("/api/calibrations").json()[0]["name"] == "bench-1"

    grid = _run(
        c,
        {
            "name": "check",
            "frames_per_point": 10,
            "settle_s": 0.2,
            "generator": {"kind": "grid", "yaw_deg": [-5, 5], "rail_mm": [11500, 12500]},
        },
        timeout_s=120,
    )
    base = f"/api/campaigns/{grid['id']}/report.json"
    nominal = c.get(base).json()["overall"]["axes"]
    calibrated = c.get(base + f"?calibration={cal['id']}").json()
    assert calibrated["reference"] == "calibrated"
    exact = c.get(base + "?reference=exact").json()["overall"]["axes"]
    for a in ("x_mm", "y_mm"):
        got = calibrated["overall"]["axes"][a]["rms"]
        print(a, "rms nominal", nominal[a]["rms"], "calibrated", got, "exact", exact[a]["rms"])
        assert got < 0.25 * nominal[a]["rms"]
        assert got < exact[a]["rms"] + 0.5  # down to the noise floor of the exact truth


def test_bad_calibration_requests(lab):
    c, _ = lab
    assert (
        c.post("/api/calibrations", json={"campaign_id": 9, "name": "x"}, headers=AUTH).status_code
        == 404
    )
    one = _run(
        c, {"name": "one", "frames_per_point": 3, "settle_s": 0.1, "setpoints": [{"yaw_deg": 0}]}
    )
    r = c.post("/api/calibrations", json={"campaign_id": one["id"], "name": "x"}, headers=AUTH)
    assert r.status_code == 422 and "at least 3 observations" in r.text
    assert c.get("/api/calibrations").json() == []
    assert c.get(f"/api/campaigns/{one['id']}/report.json?calibration=5").status_code == 404
