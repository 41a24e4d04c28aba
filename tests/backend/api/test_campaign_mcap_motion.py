"""A campaign's MCAP (``GET /api/campaigns/{id}/recording.mcap``) carries the turntable:
read back with the ``mcap`` reader, its encoder and set-point messages equal the
campaign's own values (the stored measurements' encoders, the set-points it was given)
and are stamped with the wall clock of the frames they belong to."""

from __future__ import annotations

import time

import h5py
import pytest

from tests.backend.conftest import AUTH, make_settings, running_app, wait_for
from tests.tofpose.io.interop.test_mcap_export import read_back
from tofpose.io.interop import topics

UNITS = {"yaw": "deg", "pitch": "deg", "roll": "deg", "rail": "mm"}
SETPOINTS = [
    {"yaw_deg": 0.0, "pitch_deg": 0.0, "rail_mm": 11000.0},
    {"yaw_deg": 4.0, "roll_deg": 2.0, "rail_mm": 11000.0},  # pitch left where it is
]


@pytest.fixture
def client(tmp_path):
    with running_app(make_settings(tmp_path / "data", sim_time_scale=5.0)) as c:
        yield c


def test_campaign_mcap_has_the_encoders_and_set_points_in_wall_clock_time(client, tmp_path):
    c = client
    body = {
        "name": "turntable-channels",
        "catalog": "paper-target",
        "frames_per_point": 3,
        "settle_s": 0.2,
        "record_raw": True,
        "setpoints": SETPOINTS,
    }
    started_ns = time.time_ns()
    cid = c.post("/api/campaigns", json=body, headers=AUTH).json()["id"]
    assert c.post(f"/api/campaigns/{cid}/start", headers=AUTH).status_code == 200
    wait_for(lambda: c.get(f"/api/campaigns/{cid}").json()["status"] == "done", 90)
    finished_ns = time.time_ns()
    items = c.get(f"/api/campaigns/{cid}/measurements").json()["items"]
    assert len(items) == 6
    (tmp_path / "c.h5").write_bytes(c.get(f"/api/campaigns/{cid}/recording.h5").content)
    with h5py.File(tmp_path / "c.h5", "r") as f:
        wall_ns = f["frames/wall_time_ns"][...]
    assert started_ns <= wall_ns[0] <= wall_ns[-1] <= finished_ns  # the wall clock, recorded
    r = c.get(f"/api/campaigns/{cid}/recording.mcap")
    assert r.status_code == 200
    (tmp_path / "c.mcap").write_bytes(r.content)
    messages, channels, _ = read_back(tmp_path / "c.mcap")  # each decoded by its schema
    assert channels[topics.ENCODERS][:2] == ("tofpose.Encoders", "jsonschema")
    assert channels[topics.SETPOINT][:2] == ("tofpose.SetPoint", "jsonschema")
    encoders, setpoints = messages[topics.ENCODERS], messages[topics.SETPOINT]
    gray_times = [t for t, _ in messages[topics.GRAY]]
    assert len(encoders) == len(setpoints) == len(gray_times) == len(items)
    for k, (m, (t_enc, enc), (t_sp, sp)) in enumerate(zip(items, encoders, setpoints, strict=True)):
        assert t_enc == t_sp == gray_times[k] == wall_ns[k]  # with its frame, wall clock
        assert wall_ns[0] <= t_enc <= wall_ns[-1]
        assert enc == {"index": k, **{f"{a}_{UNITS[a]}": v for a, v in m["encoders"].items()}}
        given = SETPOINTS[m["setpoint_index"]]
        expected = {f"{a}_{u}": given.get(f"{a}_{u}") for a, u in UNITS.items()}
        assert sp == {"index": k, **expected, "setpoint_index": m["setpoint_index"]}
    assert {sp["setpoint_index"] for _, sp in setpoints} == {0, 1}
    assert setpoints[-1][1]["pitch_deg"] is None  # the second set-point leaves pitch alone
