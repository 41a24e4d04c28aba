"""GET / PUT /api/reference: the live error is measured against the nominal lab geometry
(and says so) until a calibration is selected. Known truth: the simulated bench has a
mount error on purpose; a calibration holding its true mount and placement removes that
error from the live error, leaving the pipeline's own."""

from __future__ import annotations

import numpy as np

from backend.db.models import CalibrationRow
from backend.services.live.live_reference import NOMINAL_LABEL
from tests.backend.conftest import AUTH, latest_pose


def _store_true_geometry(client) -> int:
    state = client.app.state.tofpose
    g = state.devices.world.bench.geometry
    mount = g.T_inner_camera.compose(g.mount_error).as_matrix().tolist()
    placement = g.T_lab_target.compose(g.placement_error).as_matrix().tolist()
    with state.sessions() as s, s.begin():
        row = CalibrationRow(
            name="true-geometry",
            mount=mount,
            placement=placement,
            sigmas=[0.0] * 12,
            residual_mm=[0.0],
            residual_deg=[0.0],
            chi2_per_dof=1.0,
            n_observations=0,
        )
        s.add(row)
        s.flush()
        return row.id


def _mean_error_mm(client, n: int = 10) -> float:
    p, errors = latest_pose(client), []
    for _ in range(n):
        p = latest_pose(client, p["frame_index"])
        errors.append(p["reference"]["position_error_mm"])
    return float(np.median(errors))


def test_the_live_error_says_its_reference_and_a_calibration_removes_the_bench_error(client):
    ref = client.get("/api/reference").json()
    assert ref["source"] == "nominal" and ref["label"] == NOMINAL_LABEL
    assert ref["n_calibrations"] == 0 and ref["calibrated_available"] is True
    pose = latest_pose(client)
    assert pose["reference"]["label"] == NOMINAL_LABEL
    # the deprecated older name carries the same lab reference for one release
    old = pose["truth"]
    assert old == {
        **{k: v for k, v in pose["reference"].items() if k != "label"},
        "reference": NOMINAL_LABEL,
    }
    nominal_error_mm = _mean_error_mm(client)
    assert nominal_error_mm > 5.0  # the simulated bench's mount error shows in it
    cid = _store_true_geometry(client)
    r = client.put("/api/reference", json={"calibration_id": cid}, headers=AUTH)
    assert r.status_code == 200, r.text
    assert r.json()["source"] == "calibration" and r.json()["n_calibrations"] == 1
    pose = latest_pose(client, latest_pose(client)["frame_index"] + 1)
    assert pose["reference"]["label"] == f"calibration {cid} ('true-geometry')"
    calibrated_error_mm = _mean_error_mm(client)
    assert calibrated_error_mm < 2.0 < nominal_error_mm, (calibrated_error_mm, nominal_error_mm)
    back = client.put("/api/reference", json={"calibration_id": None}, headers=AUTH)
    assert back.json()["label"] == NOMINAL_LABEL


def test_bad_reference_requests_change_nothing(client):
    assert client.put("/api/reference", json={"calibration_id": 1}).status_code == 401
    r = client.put("/api/reference", json={"calibration_id": 99}, headers=AUTH)
    assert r.status_code == 404 and "no calibration with id 99" in r.json()["detail"]
    for body in ({}, {"calibration_id": "x"}, {"calibration_id": 0}, {"id": 1}):
        assert client.put("/api/reference", json=body, headers=AUTH).status_code == 422, body
    assert client.get("/api/reference").json()["source"] == "nominal"
