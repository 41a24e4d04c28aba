"""Response schemas: what the pipeline could not compute is sent as JSON null, never NaN;
a campaign's internal view and its public record share their field names."""

from __future__ import annotations

import dataclasses
import json

import jsonschema
import numpy as np
import pytest

from backend.api.presenters import pose_from_sample
from backend.api.schemas.campaigns import CampaignPublic
from backend.api.schemas.pose import PosePublic
from backend.drivers.base import CameraFrame
from backend.services.campaigns.campaign_repository import CampaignView
from backend.services.live.acquisition import LiveSample, frame_point_cloud_mm
from tests.conftest import facing_pose, render
from tofpose.core.camera import CameraModel
from tofpose.core.catalog import paper_target
from tofpose.pipeline import PosePipeline


def _strict_json(text: str) -> dict:
    def refuse(token: str):
        raise ValueError(f"non-JSON constant {token}")

    return json.loads(text, parse_constant=refuse)


@pytest.fixture
def sample_with_gaps() -> tuple[LiveSample, CameraModel]:
    """A real pose result plus one unmatched blob without distance and a singular
    covariance, as the pipeline produces for blobs whose pixels are all invalid."""
    cam = CameraModel()
    T = facing_pose(2000.0)
    f = render(T, seed=3)
    res = PosePipeline(cam, paper_target()).process(f.gray, f.distance_mm)
    assert res.ok and res.covariance is not None
    cov = res.covariance.copy()
    cov[0, 0] = np.nan
    res = dataclasses.replace(
        res, unmatched=[(10.0, 20.0, float("nan")), (30.0, 40.0, 2500.0)], covariance=cov
    )
    frame = CameraFrame(
        gray=f.gray, distance_mm=f.distance_mm, time_s=1.0, index=7, T_camera_target_lab=T
    )
    return LiveSample(frame, res, "paper-target", 1.0, 1.01), cam


def test_blob_without_distance_is_null_not_nan(sample_with_gaps):
    sample, _ = sample_with_gaps
    body = _strict_json(pose_from_sample(sample).model_dump_json())
    jsonschema.validate(body, PosePublic.model_json_schema(mode="serialization"))
    assert body["unmatched"][0]["distance_mm"] is None
    assert body["unmatched"][1]["distance_mm"] == 2500.0
    assert body["attitude_sigma_deg"] is None  # one NaN component: the vector is unknown
    assert all(np.isfinite(body["position_sigma_mm"]))
    assert body["n_matched"] == 8 and body["ok"] is True
    for m, reflector in zip(body["matched"], sample.result.matched, strict=True):
        assert m["centroid_sigma_px"] == reflector.centroid_sigma_px > 0
        assert m["range_sigma_mm"] == reflector.range_sigma_mm >= 1.0


def test_point_cloud_leaves_out_blobs_without_distance(sample_with_gaps):
    sample, cam = sample_with_gaps
    pts, ids = frame_point_cloud_mm(sample, cam)
    assert pts.shape == (9, 3) and len(ids) == 9
    assert np.isfinite(pts).all()
    assert ids[:8] == [m.catalog_id for m in sample.result.matched] and ids[8] is None
    assert np.linalg.norm(pts[8]) == pytest.approx(2500.0)


def test_the_study_specs_physics_families_are_the_simulators():
    """The API's study spec offers exactly the domain-randomisation families the
    simulator draws (a family added to one and not the other is a 422 or a crash)."""
    from typing import get_args

    from backend.api.schemas.studies import PhysicsFamily
    from tofpose.sim.randomise import FAMILIES

    assert get_args(PhysicsFamily) == FAMILIES


def test_attitude_sigmas_are_those_of_pitch_yaw_and_roll():
    """The pose message's attitude 1-sigma is the Euler angles' (the covariance of the
    rotation vector propagated through them), not the rotation vector's: at a yaw of
    40 deg the two differ, and the message's match ``facing_euler_sigma_deg``."""
    from tofpose.core.geometry import facing_euler_sigma_deg

    cam = CameraModel()
    T = facing_pose(2500.0, 0.0, 40.0, 10.0)
    f = render(T, seed=4)
    res = PosePipeline(cam, paper_target()).process(f.gray, f.distance_mm)
    assert res.ok
    frame = CameraFrame(
        gray=f.gray, distance_mm=f.distance_mm, time_s=1.0, index=1, T_camera_target_lab=T
    )
    body = pose_from_sample(LiveSample(frame, res, "paper-target", 1.0, 1.01)).model_dump()
    want = facing_euler_sigma_deg(res.R, res.covariance)
    np.testing.assert_allclose(body["attitude_sigma_deg"], want, rtol=1e-12)
    rotvec = np.degrees(np.sqrt(np.diag(res.covariance)[:3]))
    assert np.abs(want - rotvec).max() > 0.05 * rotvec.max()


def test_the_campaign_view_has_the_public_records_names():
    """Every field of the internal view is a field of ``CampaignPublic`` by the same name
    (the presenter copies, never renames); the public record adds what is computed."""
    view = {f.name for f in dataclasses.fields(CampaignView)}
    public = set(CampaignPublic.model_fields)
    assert view <= public, view - public
    assert public - view == {"n_setpoints", "n_done", "estimated_duration_s", "progress"}


def test_the_lab_reference_is_named_reference_and_its_older_names_are_marked_deprecated(
    sample_with_gaps, client
):
    """One meaning per word (docs/interop.md, "Names: truth and reference"): the live
    pose's lab reference is ``reference``; ``truth`` (live) and ``lab_truth`` (campaign
    frames) hold it under the older names, deprecated in the OpenAPI for one release."""
    sample, _ = sample_with_gaps
    body = _strict_json(pose_from_sample(sample).model_dump_json())
    T = sample.frame.T_camera_target_lab
    assert body["reference"]["z_mm"] == pytest.approx(T.t_mm[2])
    assert body["reference"]["position_error_mm"] < 5.0  # the pose of a clean render
    assert body["truth"]["reference"] == body["reference"]["label"]
    assert body["truth"]["position_error_mm"] == body["reference"]["position_error_mm"]
    schemas = client.get("/openapi.json").json()["components"]["schemas"]
    pose = schemas["PosePublic"]["properties"]
    assert pose["truth"].get("deprecated") is True and not pose["reference"].get("deprecated")
    frames = schemas["MeasurementPublic"]["properties"]
    assert frames["lab_truth"].get("deprecated") is True
    assert not frames["reference"].get("deprecated") and not frames["truth"].get("deprecated")
    assert "rendered" in frames["truth"]["description"]
