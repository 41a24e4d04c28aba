"""Campaigns with camera settings per set-point or per sweep, and with metadata, through
the API on the simulated lab: validation against the camera's limits, the runner applying
the settings (the frames are rendered with them) and restoring the camera's own, the
metadata's round trip, and the report's per-setting statistics."""

from __future__ import annotations

import subprocess

import numpy as np
import pytest

from backend.services.store import load_device_settings
from tests.backend.conftest import AUTH, make_settings, running_app, wait_for
from tofpose import __version__
from tofpose.io.recording import open_recording

AT_2M = {"yaw_deg": 0, "pitch_deg": 0, "roll_deg": 0, "rail_mm": 13000}  # 2 m from the target
BASE = {"name": "cam", "catalog": "paper-target", "frames_per_point": 4, "settle_s": 0.2}


@pytest.fixture
def fast_client(tmp_path):
    settings = make_settings(tmp_path / "data", sim_time_scale=5.0)
    with running_app(settings) as c:
        yield c


def _create(c, body) -> dict:
    r = c.post("/api/campaigns", json=body, headers=AUTH)
    assert r.status_code == 201, r.text
    return r.json()


def _run(c, body, timeout_s=90.0) -> dict:
    cid = _create(c, body)["id"]
    assert c.post(f"/api/campaigns/{cid}/start", headers=AUTH).status_code == 200
    return wait_for(
        lambda: (x := c.get(f"/api/campaigns/{cid}").json())["status"] in ("done", "paused") and x,
        timeout_s,
        "the campaign to finish",
    )


@pytest.mark.parametrize(
    ("extra", "loc", "needle"),
    [
        (
            {"setpoints": [AT_2M, {**AT_2M, "camera": {"integration_time_us": 5000}}]},
            ["body", "setpoints", 1, "camera", "integration_time_us"],
            "integration_time_us 5000 us is outside the 'sim' camera's range 10 to 4000 us",
        ),
        (
            {"setpoints": [AT_2M], "camera_sweep": {"integration_time_us": [100, 5, 200]}},
            ["body", "camera_sweep", "integration_time_us", 1],
            "integration_time_us 5 us is outside the 'sim' camera's range 10 to 4000 us",
        ),
        (
            {"setpoints": [{**AT_2M, "camera": {"modulation_frequency_mhz": 30}}]},
            ["body", "setpoints", 0, "camera", "modulation_frequency_mhz"],
            "modulation_frequency_mhz 30 MHz is outside the 'sim' camera's range 1 to 24 MHz",
        ),
        (
            {"setpoints": [AT_2M], "camera": {"integration_time_us": 9000}},
            ["body", "camera", "integration_time_us"],
            "range 10 to 4000 us",
        ),
        (
            {
                "setpoints": [{**AT_2M, "camera": {"integration_time_us": 100}}],
                "camera_sweep": {"integration_time_us": [100, 200]},
            },
            ["body", "camera_sweep"],
            "not both",
        ),
        (
            {"setpoints": [AT_2M], "camera_firmware": "0.0.1-other"},
            ["body", "camera_firmware"],
            f"the connected camera reports {__version__!r}",
        ),
    ],
)
def test_camera_settings_outside_the_limits_are_refused_naming_field_and_range(
    client, extra, loc, needle
):
    r = client.post("/api/campaigns", json={**BASE, **extra}, headers=AUTH)
    assert r.status_code == 422, r.text
    detail = r.json()["detail"]
    assert any(d["loc"] == loc and needle in d["msg"] for d in detail), detail
    assert client.get("/api/campaigns").json() == []  # nothing stored


def test_a_sweep_repeats_every_set_point_at_each_setting(client):
    body = {
        **BASE,
        "setpoints": [AT_2M, {**AT_2M, "yaw_deg": 5}],
        "camera_sweep": {"integration_time_us": [100, 200], "modulation_frequency_mhz": [6, 12]},
    }
    made = _create(client, body)
    got = [(sp["yaw_deg"], sp["camera"]) for sp in made["setpoints"]]
    settings = [
        {"integration_time_us": t, "modulation_frequency_mhz": f}
        for t in (100.0, 200.0)
        for f in (6.0, 12.0)
    ]
    assert got == [(y, s) for y in (0.0, 5.0) for s in settings]
    assert made["camera_sweep"] == {
        "integration_time_us": [100.0, 200.0],
        "modulation_frequency_mhz": [6.0, 12.0],
    }


@pytest.mark.parametrize(
    ("extra", "named"),
    [
        ({"camera_sweep": {"modulation_frequency_mhz": [6, 12]}}, "at 6 MHz, 12 MHz:"),
        (
            {"setpoints": [AT_2M, {**AT_2M, "camera": {"modulation_frequency_mhz": 12}}]},
            "at 12 MHz and the camera's own where none is given:",
        ),
        (
            {
                "camera": {"modulation_frequency_mhz": 6},
                "setpoints": [AT_2M, {**AT_2M, "camera": {"modulation_frequency_mhz": 12}}],
            },
            "at 6 MHz, 12 MHz:",
        ),
    ],
)
def test_a_raw_recording_over_two_modulation_frequencies_is_refused(client, extra, named):
    """One recording holds one camera model: a recorded campaign measures at one
    frequency (422 naming ``record_raw`` and the frequencies; nothing stored). The same
    set-points without the recording are accepted."""
    body = {**BASE, "setpoints": [AT_2M], **extra}
    r = client.post("/api/campaigns", json={**body, "record_raw": True}, headers=AUTH)
    assert r.status_code == 422, r.text
    [problem] = r.json()["detail"]
    assert problem["loc"] == ["body", "record_raw"]
    assert named in problem["msg"] and "one camera model" in problem["msg"], problem["msg"]
    assert not any(x["name"] == "cam" for x in client.get("/api/campaigns").json())
    _create(client, {**body, "name": "cam unrecorded"})
    one = {"modulation_frequency_mhz": 12}
    _create(
        client,
        {**body, "name": "cam at 12", "record_raw": True, "camera_sweep": None, "camera": one},
    )


def test_metadata_round_trip_device_values_first(client):
    body = {
        **BASE,
        "setpoints": [AT_2M],
        "operator": "A. Operator",
        "target_name": "paper target #2",
        "camera_serial": "EPC-0042",
        "notes": "after the lens was cleaned",
    }
    made = _create(client, body)
    got = client.get(f"/api/campaigns/{made['id']}").json()
    listed = client.get("/api/campaigns").json()[0]
    for c in (made, got, listed):
        assert c["operator"] == "A. Operator" and c["target_name"] == "paper target #2"
        assert c["notes"] == "after the lens was cleaned"
        assert c["camera_serial"] == "EPC-0042"  # the simulator reports none: as given
        assert c["camera_firmware"] == __version__  # read from the device
        assert c["camera_model"] == "tofpose simulated ToF camera"


def _peak_gray(rec, k: int) -> float:
    """Mean of the 30 brightest pixels of frame ``k`` (the reflectors' cores)."""
    gray = rec.frame(k)[0].astype(float).ravel()
    return float(np.mean(np.sort(gray)[-30:]))


def test_the_runner_applies_each_setting_and_restores_the_camera(fast_client):
    """Swept 100, 200 and 400 us at 2 m (the reflectors stay below saturation): every
    stored frame reports the set-point's integration time, the recorded reflector
    amplitude doubles with it, and the camera is back in auto exposure after."""
    c = fast_client
    before = c.get("/api/camera/settings").json()
    assert before["auto_exposure"] is True
    body = {
        **BASE,
        "record_raw": True,
        "setpoints": [AT_2M],
        "camera_sweep": {"integration_time_us": [100, 200, 400]},
    }
    done = _run(c, body)
    assert done["status"] == "done", done["status_reason"]
    items = c.get(f"/api/campaigns/{done['id']}/measurements").json()["items"]
    assert len(items) == 12
    for m in items:
        assert m["integration_time_us"] == [100.0, 200.0, 400.0][m["setpoint_index"]]
    assert sum(m["ok"] for m in items) == 12
    path = c.app.state.tofpose.campaigns.recording_path(done["id"])
    with open_recording(path) as rec:
        peaks = np.array([[_peak_gray(rec, 4 * i + k) for k in range(4)] for i in range(3)])
    ratios = np.median(peaks[1:], axis=1) / np.median(peaks[:-1], axis=1)
    np.testing.assert_allclose(ratios, 2.0, rtol=0.08)
    assert c.get("/api/camera/settings").json() == before


def test_a_recorded_campaign_writes_the_frequency_its_set_points_are_measured_at(
    fast_client,
):
    """Every set-point at 12 MHz with the camera at 6 MHz before: the raw recording's
    ``/camera`` says 12 MHz (the model its frames were taken with, so that a replay
    reads them with it), and the camera is back at 6 MHz after."""
    c = fast_client
    before = c.get("/api/camera/settings").json()
    assert before["modulation_frequency_mhz"] == 6
    at_12 = {**AT_2M, "camera": {"modulation_frequency_mhz": 12}}
    done = _run(c, {**BASE, "record_raw": True, "setpoints": [at_12, at_12]})
    assert done["status"] == "done", done["status_reason"]
    path = c.app.state.tofpose.campaigns.recording_path(done["id"])
    with open_recording(path) as rec:
        assert rec.n_frames == 8
        assert rec.camera.modulation_frequency_hz == 12e6
    assert c.get("/api/camera/settings").json() == before


def test_a_campaign_at_another_frequency_stops_a_live_recording_before_its_frames(
    fast_client,
):
    """A recording on demand runs at 6 MHz; a campaign's set-point sets 12 MHz: the
    recording stops at the first frame taken at 12 MHz (``camera_changed``, both
    frequencies named), its file holds only 6 MHz frames and says 6 MHz."""
    c = fast_client
    r = c.post("/api/recordings", json={"name": "beside a campaign"}, headers=AUTH)
    assert r.status_code == 201, r.text
    rid = r.json()["id"]
    wait_for(lambda: c.get(f"/api/recordings/{rid}").json()["frames"] > 2, 30, "frames")
    at_12 = {**AT_2M, "camera": {"modulation_frequency_mhz": 12}}
    done = _run(c, {**BASE, "name": "at 12 MHz", "setpoints": [at_12]})
    assert done["status"] == "done", done["status_reason"]
    rec = wait_for(
        lambda: (x := c.get(f"/api/recordings/{rid}").json())["state"] == "stopped" and x,
        30,
        "the recording to stop",
    )
    assert rec["stop_reason"] == "camera_changed", rec
    assert "from 6 to 12 MHz" in rec["stop_detail"]
    path = c.app.state.tofpose.recordings.file(rid)
    with open_recording(path) as f:
        assert f.n_frames == rec["frames"] > 2
        assert f.camera.modulation_frequency_hz == 6e6


def test_stop_restores_the_cameras_settings(fast_client):
    c = fast_client
    before = c.get("/api/camera/settings").json()
    body = {
        **BASE,
        "frames_per_point": 2000,
        "setpoints": [{**AT_2M, "camera": {"integration_time_us": 300}}],
    }
    cid = _create(c, body)["id"]
    c.post(f"/api/campaigns/{cid}/start", headers=AUTH)
    wait_for(
        lambda: (
            (p := c.get(f"/api/campaigns/{cid}").json()["progress"]) and p["frames_collected"] > 2
        ),
        60,
        "frames at the set-point",
    )
    assert c.get(f"/api/campaigns/{cid}").json()["progress"]["camera"] == {
        "integration_time_us": 300.0
    }
    during = c.get("/api/camera/settings").json()
    assert (during["integration_time_us"], during["auto_exposure"]) == (300.0, False)
    # a person's change would land between the campaign's frames: refused, nothing changed
    assert f"campaign {cid} ('cam')" in during["locked"]
    r = c.put("/api/camera/settings", json={"integration_time_us": 500}, headers=AUTH)
    assert r.status_code == 409 and r.json()["detail"] == during["locked"], r.text
    assert c.get("/api/camera/settings").json() == during
    # a body that changes nothing is answered, and the campaign's setting is not stored as
    # the camera's own (the server would start with it)
    r = c.put("/api/camera/settings", json={"integration_time_us": 300}, headers=AUTH)
    assert r.status_code == 200 and r.json() == during
    with c.app.state.tofpose.sessions() as session:
        stored = load_device_settings(session, "camera")
    assert not stored or stored.get("integration_time_us") != 300.0, stored
    assert c.post("/api/motion/stop", headers=AUTH).status_code == 200
    paused = wait_for(
        lambda: (x := c.get(f"/api/campaigns/{cid}").json())["status"] == "paused" and x
    )
    assert "STOP pressed" in paused["status_reason"]
    assert wait_for(lambda: c.get("/api/camera/settings").json() == before, 5.0, "the restore")
    assert before["locked"] is None  # nothing holds the settings once the campaign left


def test_the_report_groups_by_integration_time_and_prints_the_metadata(fast_client, tmp_path):
    c = fast_client
    body = {
        **BASE,
        "name": "exposure sweep",
        "setpoints": [AT_2M],
        "camera_sweep": {"integration_time_us": [100, 400]},
        "operator": "B. Tester",
        "target_name": "paper target #2",
        "camera_serial": "EPC-0042",
        "notes": "lens cleaned",
    }
    done = _run(c, body)
    assert done["status"] == "done", done["status_reason"]
    rep = c.get(f"/api/campaigns/{done['id']}/report.json").json()
    assert rep["campaign"]["operator"] == "B. Tester"
    groups = rep["camera_settings"]
    assert [g["setting"] for g in groups] == [
        {"integration_time_us": 100.0},
        {"integration_time_us": 400.0},
    ]
    assert [g["n_frames"] for g in groups] == [4, 4]
    assert all(g["success_rate"] == 1.0 for g in groups)
    html = c.get(f"/api/campaigns/{done['id']}/report.html").text
    pdf = tmp_path / "r.pdf"
    pdf.write_bytes(c.get(f"/api/campaigns/{done['id']}/report.pdf").content)
    pdf_text = subprocess.run(
        ["pdftotext", "-l", "1", str(pdf), "-"], check=True, capture_output=True, text=True
    ).stdout
    for text in (html, pdf_text):
        for needle in ("B. Tester", "paper target #2", "EPC-0042", __version__, "lens cleaned"):
            assert needle in text, needle
    assert (
        "By camera setting" in html
        and "By camera setting"
        in subprocess.run(
            ["pdftotext", str(pdf), "-"], check=True, capture_output=True, text=True
        ).stdout
    )
    for g in groups:  # the table's rows: the setting, then the numbers of the JSON
        t = g["setting"]["integration_time_us"]
        row = f"<td>integration time {t:g} us</td><td>1</td><td>4 of 4 (100 %)</td>"
        assert row + f"<td>{g['range_error_mean_mm']:.3g}</td>" in html
