"""Re-processing a campaign's recording with another camera calibration, through the
API: the token; bad requests named with nothing stored; a run on a LocalCluster gives,
byte for byte, what ``tofpose estimate`` writes for the downloaded recording with that
camera (and without it, for the baseline), and a comparison that is exactly zero for the
recording's own camera; a queued job can be cancelled."""

from __future__ import annotations

import json

from tests.backend.conftest import AUTH, make_settings, running_app, wait_for

CAMPAIGN = {
    "name": "raw",
    "catalog": "paper-target",
    "frames_per_point": 6,
    "settle_s": 0.2,
    "record_raw": True,
    "setpoints": [{"yaw_deg": y, "rail_mm": 11000} for y in (0, 4)],
}


def _campaign(c, body=CAMPAIGN) -> int:
    cid = c.post("/api/campaigns", json=body, headers=AUTH).json()["id"]
    assert c.post(f"/api/campaigns/{cid}/start", headers=AUTH).status_code == 200
    wait_for(
        lambda: c.get(f"/api/campaigns/{cid}").json()["status"] == "done",
        60,
        "the campaign to finish",
    )
    return cid


def _finished(c, jid: int) -> dict:
    return wait_for(
        lambda: (
            (j := c.get(f"/api/reprocessings/{jid}").json())["status"]
            in ("complete", "failed", "cancelled")
            and j
        ),
        240,
        "the re-processing",
    )


def test_a_recording_is_reprocessed_as_the_cli_would_with_each_camera(tmp_path):
    from tofpose.cli import main
    from tofpose.io.recording import open_recording

    settings = make_settings(
        tmp_path / "data", sim_time_scale=5.0, dask_scheduler="", study_workers=1
    )
    with running_app(settings) as c:
        cid = _campaign(c)
        rec_path = tmp_path / f"campaign-{cid}.h5"
        rec_path.write_bytes(c.get(f"/api/campaigns/{cid}/recording.h5").content)
        with open_recording(rec_path) as rec:
            own = rec.camera.to_dict()
            n_frames = rec.n_frames
        longer = {**own, "fx": own["fx"] * 1.01, "fy": own["fy"] * 1.01}  # a 1 % focal change

        assert c.post(f"/api/campaigns/{cid}/reprocess", json={"camera": longer}).status_code == 401
        same = c.post(f"/api/campaigns/{cid}/reprocess", json={"camera": own}, headers=AUTH)
        other = c.post(f"/api/campaigns/{cid}/reprocess", json={"camera": longer}, headers=AUTH)
        assert same.status_code == other.status_code == 201, (same.text, other.text)
        same, other = _finished(c, same.json()["id"]), _finished(c, other.json()["id"])
        assert same["status"] == other["status"] == "complete", (same, other)
        assert same["frames"] == other["frames"] == n_frames == 12

        # the recording's own camera: the run is its baseline, to the last digit
        s = same["summary"]
        assert s["ok_a"] == s["ok_b"] == n_frames and s["gained"] == s["lost"] == 0
        assert s["attitude_diff_deg"]["max"] == 0.0 and s["position_diff_mm"]["max"] == 0.0
        # a 1 % longer focal length moves the poses (the image scale enters the range fit)
        o = other["summary"]
        assert o["ok_b"] > 0 and o["position_diff_mm"]["p50"] > 0.0

        # byte for byte what `tofpose estimate` writes for the recording, with each camera
        cam_file = tmp_path / "longer.json"
        cam_file.write_text(json.dumps(longer))
        main(
            [
                "estimate",
                str(rec_path),
                "--out",
                str(tmp_path / "longer.csv"),
                "--camera",
                str(cam_file),
            ]
        )
        main(["estimate", str(rec_path), "--out", str(tmp_path / "own.csv")])
        jid = other["id"]
        assert (
            c.get(f"/api/reprocessings/{jid}/files/poses.csv").content
            == (tmp_path / "longer.csv").read_bytes()
        )
        assert (
            c.get(f"/api/reprocessings/{jid}/files/baseline.csv").content
            == (tmp_path / "own.csv").read_bytes()
        )
        png = c.get(f"/api/reprocessings/{jid}/files/compare.png")
        assert png.status_code == 200 and png.content[:4] == b"\x89PNG"
        rows = c.get(f"/api/reprocessings/{jid}/files/compare.csv").text.splitlines()
        assert len(rows) == 1 + n_frames
        listed = c.get(f"/api/reprocessings?campaign_id={cid}").json()
        assert [j["id"] for j in listed] == [other["id"], same["id"]]
        assert c.get("/api/reprocessings?campaign_id=999").json() == []


def test_bad_requests_are_named_and_nothing_is_stored(tmp_path):
    settings = make_settings(tmp_path / "data", sim_time_scale=5.0)
    with running_app(settings) as c:
        cid = _campaign(c)
        no_raw = _campaign(c, {**CAMPAIGN, "name": "no-raw", "record_raw": False})
        with_cam = c.get(f"/api/campaigns/{cid}/recording.h5")
        assert with_cam.status_code == 200
        bad = [
            ({"camera": {"fx": 100.0}}, "missing"),  # not a camera
            (
                {
                    "camera": {
                        "width": 64,
                        "height": 48,
                        "fx": 50.0,
                        "fy": 50.0,
                        "cx": 32.0,
                        "cy": 24.0,
                    }
                },
                "does not match the recording's 320x240",
            ),
        ]
        for body, words in bad:
            r = c.post(f"/api/campaigns/{cid}/reprocess", json=body, headers=AUTH)
            assert r.status_code == 422, r.text
            d = r.json()["detail"][0]
            assert d["loc"] == ["body", "camera"] and words in d["msg"], d
        r = c.post(f"/api/campaigns/{cid}/reprocess", json={"tracking": "yes"}, headers=AUTH)
        assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["body", "tracking"]
        r = c.post(f"/api/campaigns/{no_raw}/reprocess", json={}, headers=AUTH)
        # the campaign exists; its state (no recording) forbids this: a conflict
        assert r.status_code == 409 and "record_raw was off" in r.json()["detail"]
        assert c.post("/api/campaigns/99/reprocess", json={}, headers=AUTH).status_code == 404
        assert c.get("/api/reprocessings").json() == []
        assert not (settings.data_dir / "reprocessings").exists() or not any(
            (settings.data_dir / "reprocessings").iterdir()
        )
        assert c.get("/api/reprocessings/3").status_code == 404
        assert c.get("/api/reprocessings/3/files/poses.csv").status_code == 404


def test_an_unreachable_scheduler_fails_the_job_and_a_queued_one_can_be_cancelled(tmp_path):
    settings = make_settings(tmp_path / "data", sim_time_scale=5.0)  # scheduler: a closed port
    with running_app(settings) as c:
        cid = _campaign(c)
        # a study first, so that the re-processing waits behind it in the shared queue
        study = {"name": "ahead", "seed": 1, "frames_per_cell": 2, "grid": {"range_m": [2.0]}}
        c.post("/api/studies", json=study, headers=AUTH)
        first = c.post(f"/api/campaigns/{cid}/reprocess", json={}, headers=AUTH).json()
        second = c.post(f"/api/campaigns/{cid}/reprocess", json={}, headers=AUTH).json()
        assert c.post(f"/api/reprocessings/{second['id']}/cancel").status_code == 401
        r = c.post(f"/api/reprocessings/{second['id']}/cancel", headers=AUTH)
        assert r.status_code == 200 and r.json()["status"] == "cancelled"
        failed = _finished(c, first["id"])
        assert failed["status"] == "failed" and "tcp://127.0.0.1:9" in failed["error"], failed
        assert c.get(f"/api/reprocessings/{first['id']}/files/poses.csv").status_code == 409
        assert c.get(f"/api/reprocessings/{second['id']}").json()["status"] == "cancelled"
