"""Campaigns through the API on the simulated devices: create, run, control, reports."""

from __future__ import annotations

import csv
import io
import subprocess
from html.parser import HTMLParser

import cv2
import numpy as np
import pytest

from tests.backend.conftest import AUTH, make_settings, running_app, wait_for
from tests.tofpose.io.interop.test_mcap_export import read_back
from tests.tofpose.io.interop.test_ros2_export import read_back as read_back_ros2

GRID = {
    "name": "grid-1",
    "catalog": "paper-target",
    "frames_per_point": 10,
    "settle_s": 0.5,
    "setpoints": [
        {"yaw_deg": 0, "pitch_deg": 0, "roll_deg": 0, "rail_mm": 11000},
        {"yaw_deg": 5, "pitch_deg": 0, "roll_deg": 0, "rail_mm": 11000},
    ],
}


@pytest.fixture
def fast_client(tmp_path, database_url):
    """The app with the simulated lab running 5x faster than real time, on SQLite and
    (when a server is available) on PostgreSQL."""
    settings = make_settings(tmp_path / "data", sim_time_scale=5.0, database_url=database_url)
    with running_app(settings) as c:
        yield c


def _run(client, body, timeout_s=60.0) -> dict:
    r = client.post("/api/campaigns", json=body, headers=AUTH)
    assert r.status_code == 201, r.text
    cid = r.json()["id"]
    assert client.post(f"/api/campaigns/{cid}/start", headers=AUTH).status_code == 200
    return wait_for(
        lambda: (
            (c := client.get(f"/api/campaigns/{cid}").json())["status"]
            in ("done", "paused", "failed")
            and c
        ),
        timeout_s,
        "the campaign to finish",
    )


class _Tables(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.tables, self.imgs, self.cells = 0, 0, []

    def handle_starttag(self, tag, attrs):
        self.tables += tag == "table"
        self.imgs += tag == "img" and dict(attrs).get("src", "").startswith("data:image/png")

    def handle_data(self, data):
        self.cells.append(data.strip())


def _recompute(rows: list[dict], axis: str, ref: str = "reference_") -> dict:
    """Independent recomputation of one set-point's statistics from CSV rows."""
    ok = [r for r in rows if r["ok"] == "1"]
    e = np.array([float(r[axis]) - float(r[ref + axis]) for r in ok])
    med = np.median(e)
    mad = 1.4826 * np.median(np.abs(e - med))
    k = e if mad == 0 else e[np.abs(e - med) <= 5.0 * mad]
    return {
        "n": len(k),
        "bias": k.mean(),
        "std": k.std(ddof=1),
        "max_abs": np.abs(k).max(),
        "rms": np.sqrt(np.mean(k**2)),
    }


def test_a_grid_campaign_runs_to_completion_and_every_report_downloads(fast_client, tmp_path):
    c = fast_client
    done = _run(c, GRID)
    assert done["status"] == "done" and done["n_done"] == 2, done
    page = c.get(f"/api/campaigns/{done['id']}/measurements?limit=5").json()
    assert page["total"] == 20 and len(page["items"]) == 5
    # Frames are attributed only at rest: each frame's encoders are at its set-point.
    allm = c.get(f"/api/campaigns/{done['id']}/measurements?limit=100").json()["items"]
    for m in allm:
        sp = GRID["setpoints"][m["setpoint_index"]]
        assert abs(m["encoders"]["yaw"] - sp["yaw_deg"]) < 0.01
        assert abs(m["encoders"]["rail"] - sp["rail_mm"]) < 0.5
        assert m["truth"] is not None and m["reference"] is not None
        assert m["lab_truth"] == m["reference"]  # the deprecated older name, one release
    base = f"/api/campaigns/{done['id']}/report"

    r = c.get(base + ".csv")
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/csv")
    rows = list(csv.DictReader(io.StringIO(r.text)))
    required = [
        "setpoint_index",
        "frame_index",
        "time_s",
        "ok",
        "x_mm",
        "y_mm",
        "z_mm",
        "pitch_deg",
        "yaw_deg",
        "roll_deg",
        "truth_x_mm",
        "truth_y_mm",
        "truth_z_mm",
        "truth_pitch_deg",
        "truth_yaw_deg",
        "truth_roll_deg",
        *(f"reference_{a}" for a in ("x_mm", "y_mm", "z_mm", "pitch_deg", "yaw_deg", "roll_deg")),
    ]
    assert set(required) <= set(rows[0]) and len(rows) == 20
    assert not [k for k in rows[0] if "lab_truth" in k or "calibrated_truth" in k]
    # every frame keeps the relative state at it; where the filter fused the pose, the
    # target is at rest within its sigmas (the table stands still at a set-point). This
    # simulated bench runs faster than real time, so the filter, tuned for a real table's
    # accelerations, may still refuse the first poses after a stop ("rejected") and
    # restart ("reset") from them
    statuses = [row["filter_status"] for row in rows]
    assert set(statuses) <= {"updated", "initialised", "rejected", "reset"}, statuses
    assert statuses.count("updated") >= len(rows) // 2, statuses
    for row in rows:
        if row["filter_status"] != "updated":
            continue
        for axis in "xyz":
            rate, sigma = float(row[f"rate_{axis}_deg_s"]), float(row[f"sigma_rate_{axis}_deg_s"])
            assert abs(rate) < 3 * sigma + 0.05, (axis, rate, sigma)
            assert float(row[f"sigma_vel_{axis}_mm_s"]) > 0

    report = c.get(base + ".json").json()
    assert report["reference"] == "lab" and report["n_frames"] == 20
    for sp in report["setpoints"]:
        sp_rows = [r for r in rows if int(r["setpoint_index"]) == sp["setpoint_index"]]
        for axis in ("x_mm", "z_mm", "yaw_deg", "roll_deg"):
            want = _recompute(sp_rows, axis)
            got = sp["axes"][axis]
            assert got["n"] == want["n"]
            for k in ("bias", "std", "max_abs", "rms"):
                assert got[k] == pytest.approx(want[k], rel=1e-9, abs=1e-12), (axis, k)
            assert got["passed"] == (got["max_abs"] <= got["requirement"])
    exact = c.get(base + ".json?reference=exact").json()
    # Against the pose that was rendered, x/y errors are far smaller than against the
    # lab's reference, which carries the simulated mount error (~2 mm, 0.3 deg).
    assert exact["overall"]["axes"]["x_mm"]["rms"] < 2.0 < report["overall"]["axes"]["x_mm"]["rms"]

    r = c.get(base + ".html")
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/html")
    parsed = _Tables()
    parsed.feed(r.text)
    assert parsed.tables >= 1 + 2 * 2 and parsed.imgs == 4
    assert "x" in parsed.cells and "x_mm" not in parsed.cells  # human headers, not identifiers
    assert "http" not in r.text.split("<body>")[0]

    r = c.get(base + ".pdf")
    assert r.status_code == 200 and r.content[:5] == b"%PDF-"
    pdf = tmp_path / "report.pdf"
    pdf.write_bytes(r.content)
    subprocess.run(
        ["pdftoppm", "-r", "40", "-png", "-f", "1", "-l", "1", str(pdf), str(tmp_path / "page")],
        check=True,
    )
    page1 = cv2.imread(str(next(tmp_path.glob("page*.png"))), cv2.IMREAD_GRAYSCALE)
    ink = (page1 < 128).mean()
    assert 0.005 < ink < 0.5, f"page 1 ink fraction {ink:.4f}: blank or black"


def test_generators_make_the_set_points(fast_client):
    c = fast_client
    cases = [
        ({"kind": "grid", "yaw_deg": [-5, 0, 5], "pitch_deg": [0, 3]}, 6),
        ({"kind": "range_sweep", "rail_start_mm": 9000, "rail_stop_mm": 13000, "points": 5}, 5),
        ({"kind": "stability", "rail_mm": 14303}, 1),
        ({"kind": "attitude_steps", "axis": "roll", "steps_deg": [0, 1, 2, 5, 0]}, 5),
        ({"kind": "calibration", "rails_mm": [10000, 12000]}, 18),
    ]
    for i, (gen, n) in enumerate(cases):
        r = c.post("/api/campaigns", json={"name": f"g{i}", "generator": gen}, headers=AUTH)
        assert r.status_code == 201, r.text
        camp = r.json()
        assert camp["n_setpoints"] == n and len(camp["setpoints"]) == n
        assert camp["status"] == "draft" and camp["estimated_duration_s"] > 0
    sweep = c.get("/api/campaigns").json()[-2]  # newest first: g1 is second to last
    assert [sp["rail_mm"] for sp in c.get(f"/api/campaigns/{sweep['id']}").json()["setpoints"]] == [
        9000,
        10000,
        11000,
        12000,
        13000,
    ]


@pytest.mark.parametrize(
    ("body", "status", "needle"),
    [
        ({**GRID, "setpoints": []}, 422, "at least 1 item"),
        ({k: v for k, v in GRID.items() if k != "setpoints"}, 422, "no set-points"),
        ({**GRID, "setpoints": [{}]}, 422, "at least one of yaw_deg"),
        ({**GRID, "setpoints": [{"yaw_deg": 200}]}, 422, "set-point 0: yaw set-point 200"),
        ({**GRID, "setpoints": [{"yaw_deg": 0}] * 5001}, 422, "setpoints"),
        (
            {**GRID, "frames_per_point": 100_000, "setpoints": [{"yaw_deg": 0}] * 11},
            422,
            "maximum 1000000 frames",
        ),
        ({**GRID, "catalog": "nope"}, 422, "no catalog named 'nope'"),
        ({**GRID, "generator": {"kind": "stability"}}, 422, "not both"),
        (
            {
                "name": "x",
                "generator": {
                    "kind": "range_sweep",
                    "rail_start_mm": 1,
                    "rail_stop_mm": 2,
                    "points": 1,
                },
            },
            422,
            "points",
        ),
        ({**GRID, "setpoints": [{"yaw_deg": None}]}, 422, "null is not a set-point"),
    ],
)
def test_bad_campaigns_are_refused_and_nothing_is_stored(fast_client, body, status, needle):
    client = fast_client
    r = client.post("/api/campaigns", json=body, headers=AUTH)
    assert r.status_code == status, r.text
    detail = r.json()["detail"]
    text = detail if isinstance(detail, str) else " ".join(f"{e['loc']} {e['msg']}" for e in detail)
    assert needle in text
    assert client.get("/api/campaigns").json() == []


def test_unknown_ids_names_taken_and_auth(fast_client):
    client = fast_client
    assert client.get("/api/campaigns/99").status_code == 404
    assert client.post("/api/campaigns/99/start", headers=AUTH).status_code == 404
    assert client.get("/api/campaigns/99/report.csv").status_code == 404
    assert client.post("/api/campaigns", json=GRID).status_code == 401
    assert client.post("/api/campaigns", json=GRID, headers=AUTH).status_code == 201
    r = client.post("/api/campaigns", json=GRID, headers=AUTH)
    assert r.status_code == 409 and "'grid-1' already exists" in r.json()["detail"]
    assert len(client.get("/api/campaigns").json()) == 1


def test_the_state_machine_is_served_and_is_what_the_commands_obey(client):
    """``GET /api/campaigns/states`` (what the dashboard offers per state) and the 409s
    of the commands come from one table; the API document names the states' enum."""
    table = client.get("/api/campaigns/states").json()
    assert table["states"] == [
        "draft",
        "queued",
        "running",
        "paused",
        "interrupted",
        "done",
        "failed",
        "cancelled",
    ]
    assert table["finished"] == ["done", "failed", "cancelled"]
    moves = {(t["from_state"], t["command"]): t["to_state"] for t in table["transitions"]}
    assert moves[("draft", "start")] == "queued" and ("draft", "pause") not in moves
    schemas = client.get("/openapi.json").json()["components"]["schemas"]
    assert schemas["CampaignState"]["enum"] == table["states"]
    enum = {"$ref": "#/components/schemas/CampaignState"}
    for name in ("CampaignPublic", "ProgressPublic"):
        assert schemas[name]["properties"]["status"] == enum
    cid = client.post("/api/campaigns", json={**GRID, "name": "sm"}, headers=AUTH).json()["id"]
    for command in ("pause", "resume"):  # not allowed from draft
        assert ("draft", command) not in moves
        r = client.post(f"/api/campaigns/{cid}/{command}", headers=AUTH)
        assert r.status_code == 409 and r.json()["detail"].startswith(f"campaign {cid} is draft:")
    assert (
        client.post(f"/api/campaigns/{cid}/cancel", headers=AUTH).json()["status"]
        == (moves[("draft", "cancel")])
    )


def test_a_running_campaign_owns_the_turntable_and_stop_pauses_it(fast_client):
    c = fast_client
    body = {**GRID, "name": "long", "frames_per_point": 400}
    cid = c.post("/api/campaigns", json=body, headers=AUTH).json()["id"]
    other = c.post("/api/campaigns", json={**GRID, "name": "other"}, headers=AUTH).json()["id"]
    assert c.post(f"/api/campaigns/{cid}/start", headers=AUTH).status_code == 200
    wait_for(lambda: c.get(f"/api/campaigns/{cid}").json()["status"] == "running")
    r = c.post("/api/motion/move", json={"yaw_deg": 1}, headers=AUTH)
    assert r.status_code == 409 and "owns the motion system" in r.json()["detail"]
    r = c.post("/api/motion/jog", json={"yaw_deg": 1}, headers=AUTH)
    assert r.status_code == 409 and "owns the motion system" in r.json()["detail"]
    motion = c.get("/api/motion").json()
    assert (motion["owner_campaign_id"], motion["owner_campaign_name"]) == (cid, "long")
    r = c.post(f"/api/campaigns/{other}/start", headers=AUTH)
    assert r.status_code == 409 and "queue" in r.json()["detail"]
    assert c.post(f"/api/campaigns/{cid}/resume", headers=AUTH).status_code == 409
    assert c.post("/api/motion/stop", headers=AUTH).status_code == 200
    paused = wait_for(
        lambda: (x := c.get(f"/api/campaigns/{cid}").json())["status"] == "paused" and x
    )
    assert "STOP pressed" in paused["status_reason"]  # whichever of runner and service saw it first
    # the runner stores "paused", then gives the motion system back
    motion = wait_for(
        lambda: (m := c.get("/api/motion").json())["owner_campaign_id"] is None and m,
        5.0,
        "the campaign to let go of the motion system",
    )
    assert motion["stop_latched"] is True
    r = c.post("/api/motion/move", json={"yaw_deg": 1}, headers=AUTH)
    assert r.status_code == 409 and "release it first" in r.json()["detail"]  # STOP latched
    assert c.post("/api/motion/release", headers=AUTH).status_code == 200
    assert c.post("/api/motion/move", json={"yaw_deg": 1}, headers=AUTH).status_code == 202
    assert c.post(f"/api/campaigns/{cid}/cancel", headers=AUTH).status_code == 200
    assert c.get(f"/api/campaigns/{cid}").json()["status"] == "cancelled"
    r = c.post(f"/api/campaigns/{cid}/resume", headers=AUTH)
    assert r.status_code == 409 and "cancelled" in r.json()["detail"]


def test_a_campaign_holds_the_motion_system_before_it_reads_running(client):
    """The runner claims the turntable before it stores ``running``: a person who sees
    the campaign running (and the test above polls for just that) can never slip a move
    in between. Checked at the moment the status is stored, not by timing."""
    svc = client.app.state.tofpose.campaigns
    seen = []
    store = svc.repository.set_status

    def set_status(campaign_id, state, *args, **kwargs):
        if state == "running":
            owner = svc.motion.owner
            seen.append(None if owner is None else owner.campaign_id)
        return store(campaign_id, state, *args, **kwargs)

    svc.repository.set_status = set_status
    far = "2099-01-01T00:00:00+00:00"  # queued, never due: the runner is called below
    cid = client.post("/api/campaigns", json={**GRID, "name": "order"}, headers=AUTH).json()["id"]
    client.post(f"/api/campaigns/{cid}/start", json={"at": far}, headers=AUTH)
    svc._run(cid)
    assert seen == [cid]
    assert client.get(f"/api/campaigns/{cid}").json()["status"] == "done"
    assert svc.motion.owner is None  # given back at the end


def test_a_database_failure_as_a_campaign_starts_leaves_the_motion_system_free(client):
    """Storing ``running`` fails (a locked or lost database): the runner gives the
    turntable back it had just claimed, and a person can move it."""
    svc = client.app.state.tofpose.campaigns
    store = svc.repository.set_status

    def set_status(campaign_id, state, *args, **kwargs):
        if state == "running":
            raise RuntimeError("database is locked")
        return store(campaign_id, state, *args, **kwargs)

    svc.repository.set_status = set_status
    far = "2099-01-01T00:00:00+00:00"
    cid = client.post("/api/campaigns", json={**GRID, "name": "db"}, headers=AUTH).json()["id"]
    client.post(f"/api/campaigns/{cid}/start", json={"at": far}, headers=AUTH)
    with pytest.raises(RuntimeError, match="database is locked"):
        svc._run(cid)
    assert svc.motion.owner is None
    assert client.post("/api/motion/move", json={"yaw_deg": 1}, headers=AUTH).status_code == 202


def test_a_campaign_paused_or_cancelled_after_the_scheduler_picked_it_never_runs(client):
    """The runner claims a campaign only if it is still queued, under the lock the
    commands take: a pause or cancel that lands between the scheduler's pick and the
    runner's claim is kept, and the turntable is never claimed (before, the runner
    overwrote it with ``running`` and moved the table). The runner is called here as the
    scheduler would, for a campaign paused (or cancelled) just after being picked."""
    svc = client.app.state.tofpose.campaigns
    far = "2099-01-01T00:00:00+00:00"  # queued, but never due: the scheduler leaves it
    for command, state in (("pause", "paused"), ("cancel", "cancelled")):
        cid = client.post("/api/campaigns", json={**GRID, "name": command}, headers=AUTH).json()[
            "id"
        ]
        assert (
            client.post(f"/api/campaigns/{cid}/start", json={"at": far}, headers=AUTH).json()[
                "status"
            ]
            == "queued"
        )
        assert client.post(f"/api/campaigns/{cid}/{command}", headers=AUTH).status_code == 200
        svc._run(cid)  # the runner, as if the scheduler had picked it a moment before
        c = client.get(f"/api/campaigns/{cid}").json()
        assert (c["status"], c["n_done"]) == (state, 0)
        assert client.get(f"/api/campaigns/{cid}/measurements").json()["total"] == 0
        assert client.get("/api/motion").json()["owner_campaign_id"] is None


def test_a_stop_pressed_between_the_pick_and_the_claim_keeps_the_campaign_from_starting(
    client,
):
    """STOP before the runner claims the motion system (the scheduler picked the campaign
    with the STOP count of that moment): the campaign is paused, never run, and the
    table is not claimed."""
    svc = client.app.state.tofpose.campaigns
    cid = client.post("/api/campaigns", json={**GRID, "name": "stopped"}, headers=AUTH).json()["id"]
    assert (
        client.post(
            f"/api/campaigns/{cid}/start", json={"at": "2099-01-01T00:00:00+00:00"}, headers=AUTH
        ).json()["status"]
        == "queued"
    )
    stops_at_pick = svc.motion.stops
    assert client.post("/api/motion/stop", headers=AUTH).status_code == 200
    svc._run(cid, stops_at_pick)  # the runner the scheduler started before the STOP
    c = client.get(f"/api/campaigns/{cid}").json()
    assert (c["status"], c["n_done"]) == ("paused", 0)
    assert c["status_reason"].startswith("STOP pressed before it started")
    assert client.get("/api/motion").json()["owner_campaign_id"] is None
    # the latch alone (no STOP since the pick) keeps a queued campaign from starting, and
    # a campaign cannot be started while it holds
    assert client.get("/api/motion").json()["stop_latched"] is True
    cid = client.post("/api/campaigns", json={**GRID, "name": "latched"}, headers=AUTH).json()["id"]
    r = client.post(
        f"/api/campaigns/{cid}/start", json={"at": "2099-01-01T00:00:00+00:00"}, headers=AUTH
    )
    assert r.status_code == 409 and "release it" in r.json()["detail"]
    assert client.post("/api/motion/release", headers=AUTH).status_code == 200
    assert (
        client.post(
            f"/api/campaigns/{cid}/start", json={"at": "2099-01-01T00:00:00+00:00"}, headers=AUTH
        ).json()["status"]
        == "queued"
    )
    assert client.post("/api/motion/stop", headers=AUTH).json()["stop_latched"] is True
    svc._run(cid)
    assert client.get(f"/api/campaigns/{cid}").json()["status"] == "paused"
    assert client.get("/api/motion").json()["owner_campaign_id"] is None


def test_pause_then_resume_measures_every_set_point_once(fast_client):
    c = fast_client
    body = {
        **GRID,
        "name": "pr",
        "frames_per_point": 15,
        "setpoints": [{"yaw_deg": y, "rail_mm": 12000} for y in (0, 2, 4, 6)],
    }
    cid = c.post("/api/campaigns", json=body, headers=AUTH).json()["id"]
    c.post(f"/api/campaigns/{cid}/start", headers=AUTH)
    wait_for(lambda: c.get(f"/api/campaigns/{cid}").json()["n_done"] >= 1, 60)
    assert c.post(f"/api/campaigns/{cid}/pause", headers=AUTH).status_code == 200
    wait_for(lambda: c.get(f"/api/campaigns/{cid}").json()["status"] == "paused")
    done_at_pause = c.get(f"/api/campaigns/{cid}").json()["n_done"]
    assert c.get(f"/api/campaigns/{cid}/measurements").json()["total"] == 15 * done_at_pause
    assert c.post(f"/api/campaigns/{cid}/resume", headers=AUTH).status_code == 200
    final = wait_for(
        lambda: (x := c.get(f"/api/campaigns/{cid}").json())["status"] == "done" and x, 60
    )
    assert final["n_done"] == 4
    items = c.get(f"/api/campaigns/{cid}/measurements").json()["items"]
    assert len(items) == 60
    assert [sum(m["setpoint_index"] == i for m in items) for i in range(4)] == [15] * 4
    r = c.post(f"/api/campaigns/{cid}/resume", headers=AUTH)
    assert r.status_code == 409 and "nothing left to do" in r.json()["detail"]


def test_progress_reaches_the_websocket(fast_client):
    c = fast_client
    body = {**GRID, "name": "ws", "frames_per_point": 5}
    cid = c.post("/api/campaigns", json=body, headers=AUTH).json()["id"]
    with c.websocket_connect("/ws/live") as ws:
        ws.receive_json()
        c.post(f"/api/campaigns/{cid}/start", headers=AUTH)
        seen = []
        while not seen or seen[-1]["status"] != "done":
            m = ws.receive_json()
            if m["type"] == "campaign":
                seen.append(m["data"])
    assert seen[-1]["n_done"] == 2 and seen[-1]["campaign_id"] == cid
    assert any(s["status"] == "running" for s in seen)


def test_the_cli_writes_the_same_report_from_the_database(tmp_path, capsys):
    from tofpose.cli import main

    data = tmp_path / "data"
    with running_app(make_settings(data, sim_time_scale=5.0)) as c:
        done = _run(c, {**GRID, "frames_per_point": 4})
        api_csv = c.get(f"/api/campaigns/{done['id']}/report.csv").text
    url = f"sqlite:///{data / 'tofpose.db'}"
    out = tmp_path / "r.csv"
    assert main(["report", "--db", url, str(done["id"]), "--format", "csv", "--out", str(out)]) == 0
    assert out.read_text() == api_csv
    pdf = tmp_path / "r.pdf"
    assert main(["report", "--db", url, str(done["id"]), "--format", "pdf", "--out", str(pdf)]) == 0
    assert pdf.read_bytes()[:5] == b"%PDF-"
    assert main(["report", "--db", url, "77", "--out", str(out)]) == 2
    assert "no campaign with id 77" in capsys.readouterr().err


def test_raw_recording_holds_exactly_the_stored_frames_and_reprocesses(fast_client, tmp_path):
    """record_raw: after a pause mid-set-point the file holds only committed frames;
    after resume the downloaded recording re-processed by `tofpose estimate` gives the
    stored poses."""
    from tofpose.cli import main
    from tofpose.io.interop import ros2_topics, topics
    from tofpose.io.recording import open_recording

    c = fast_client
    body = {
        **GRID,
        "name": "raw",
        "frames_per_point": 12,
        "record_raw": True,
        "setpoints": [{"yaw_deg": y, "rail_mm": 12000} for y in (0, 3, 6)],
    }
    cid = c.post("/api/campaigns", json=body, headers=AUTH).json()["id"]
    c.post(f"/api/campaigns/{cid}/start", headers=AUTH)
    wait_for(
        lambda: (
            (p := c.get(f"/api/campaigns/{cid}").json()["progress"])
            and p["n_done"] >= 1
            and p["frames_collected"] >= 3
        ),
        60,
    )
    assert c.get(f"/api/campaigns/{cid}/recording.h5").status_code == 409  # still writing
    c.post(f"/api/campaigns/{cid}/pause", headers=AUTH)
    wait_for(lambda: c.get(f"/api/campaigns/{cid}").json()["status"] == "paused")
    stored = c.get(f"/api/campaigns/{cid}/measurements").json()["total"]
    r = c.get(f"/api/campaigns/{cid}/recording.h5")
    assert r.status_code == 200
    (tmp_path / "paused.h5").write_bytes(r.content)
    with open_recording(tmp_path / "paused.h5") as rec:
        assert rec.n_frames == stored and stored % 12 == 0
    c.post(f"/api/campaigns/{cid}/resume", headers=AUTH)
    wait_for(lambda: c.get(f"/api/campaigns/{cid}").json()["status"] == "done", 60)
    rec_path = tmp_path / "raw.h5"
    rec_path.write_bytes(c.get(f"/api/campaigns/{cid}/recording.h5").content)
    items = c.get(f"/api/campaigns/{cid}/measurements").json()["items"]
    with open_recording(rec_path) as rec:
        assert rec.n_frames == len(items) == 36
        assert rec.truth_t_mm is not None and rec.reference_t_mm is not None
        for k, m in enumerate(items):
            assert rec.time_s[k] == pytest.approx(m["time_s"])
            np.testing.assert_allclose(
                rec.reference_t_mm[k], [m["reference"][a] for a in ("x_mm", "y_mm", "z_mm")]
            )
    out = tmp_path / "poses.csv"
    assert main(["estimate", str(rec_path), "--out", str(out)]) == 0
    poses = list(csv.DictReader(out.open()))
    diffs = [
        abs(float(p["x_mm"]) - m["x_mm"])
        for p, m in zip(poses, items, strict=True)
        if p["ok"] == "1" and m["ok"]
    ]
    assert len(diffs) >= 30 and np.median(diffs) < 0.5
    # the same recording as MCAP: its frames, the references and a pose per frame
    r = c.get(f"/api/campaigns/{cid}/recording.mcap")
    assert r.status_code == 200 and r.headers["content-type"] == "application/x-mcap"
    (tmp_path / "raw.mcap").write_bytes(r.content)
    messages, _, _ = read_back(tmp_path / "raw.mcap")
    with open_recording(rec_path) as rec:
        assert len(messages[topics.GRAY]) == rec.n_frames
        for k in (0, rec.n_frames - 1):
            g = messages[topics.GRAY][k][1]
            np.testing.assert_array_equal(
                np.frombuffer(g.data, "<u2").reshape(240, 320), rec.frame(k)[0]
            )
            lab = messages[topics.REFERENCE][k][1]
            assert lab["t_camera_target_mm"] == rec.reference_t_mm[k].tolist()
    est = [p for _, p in messages[topics.ESTIMATE]]
    assert sum(e["ok"] for e in est) >= 30
    # as ROS 2 messages: the same frames and a pose with its covariance where there is one
    r = c.get(f"/api/campaigns/{cid}/recording.mcap", params={"profile": "ros2"})
    assert r.status_code == 200 and r.headers["content-type"] == "application/x-mcap"
    assert f'filename="campaign-{cid}.ros2.mcap"' in r.headers["content-disposition"]
    (tmp_path / "raw.ros2.mcap").write_bytes(r.content)
    ros2 = read_back_ros2(tmp_path / "raw.ros2.mcap")
    with open_recording(rec_path) as rec:
        assert len(ros2[ros2_topics.AMPLITUDE]) == rec.n_frames
        _, amplitude = ros2[ros2_topics.AMPLITUDE][0]
        np.testing.assert_array_equal(amplitude.data.view("<u2").reshape(240, 320), rec.frame(0)[0])
    assert len(ros2[ros2_topics.POSE]) == sum(e["ok"] for e in est)
    other = c.post("/api/campaigns", json={**GRID, "name": "no-raw"}, headers=AUTH).json()
    for suffix in ("h5", "mcap"):
        r = c.get(f"/api/campaigns/{other['id']}/recording.{suffix}")
        assert r.status_code == 404 and "record_raw was off" in r.json()["detail"]


def test_the_campaigns_camera_settings_are_applied_and_then_restored(fast_client):
    c = fast_client
    body = {
        **GRID,
        "name": "cam",
        "frames_per_point": 40,
        "camera": {"modulation_frequency_mhz": 12.0, "frame_rate_hz": 15.0},
    }
    before = c.get("/api/camera/settings").json()
    assert before["modulation_frequency_mhz"] == 6.0
    cid = c.post("/api/campaigns", json=body, headers=AUTH).json()["id"]
    c.post(f"/api/campaigns/{cid}/start", headers=AUTH)
    wait_for(
        lambda: (p := c.get(f"/api/campaigns/{cid}").json()["progress"]) and p["frames_collected"],
        60,
        "a measured frame",
    )
    during = c.get("/api/camera/settings").json()
    assert (during["modulation_frequency_mhz"], during["frame_rate_hz"]) == (12.0, 15.0)
    done = wait_for(
        lambda: (x := c.get(f"/api/campaigns/{cid}").json())["status"] != "running" and x, 60
    )
    assert done["status"] == "done" and done["camera"]["modulation_frequency_mhz"] == 12.0
    assert c.get("/api/camera/settings").json() == before  # the camera's own again


def _write_recording_with_both_truths(path, n_frames: int) -> None:
    """A small simulated recording whose /reference is its /truth off by a known error
    (0.5, -0.4, 0.3 deg and (4, -3, 6) mm, as a mis-mounted bench would be): frame i
    shows the target at 2 m, turned by i deg of yaw, 20 frames/s."""
    from tests.conftest import facing_pose, render
    from tofpose.core.camera import CameraModel
    from tofpose.core.catalog import paper_target
    from tofpose.core.geometry import RigidTransform
    from tofpose.io.recording import RecordingWriter

    T_lab_exact = RigidTransform.from_euler_deg(0.5, -0.4, 0.3, (4.0, -3.0, 6.0))
    with RecordingWriter(
        path, CameraModel(), paper_target(), with_truth=True, with_reference=True
    ) as w:
        for i in range(n_frames):
            T_exact = facing_pose(2000.0, yaw_deg=float(i), offset_mm=(30.0, -20.0))
            T_lab = T_lab_exact.compose(T_exact)
            f = render(T_exact, seed=100 + i)
            w.append(
                f.gray,
                f.distance_mm,
                0.05 * i,
                T_exact.R,
                T_exact.t_mm,
                lab_R_camera_target=T_lab.R,
                lab_t_camera_target_mm=T_lab.t_mm,
            )


def _facing_pose_columns(R, t_mm) -> dict[str, float]:
    """A ``T_camera_target`` as a measurement's pose columns (mm, facing Euler deg)."""
    from tofpose.core.geometry import facing_euler_deg

    p, y, r = (float(v) for v in facing_euler_deg(R))
    x, yy, z = (float(v) for v in t_mm)
    return {"x_mm": x, "y_mm": yy, "z_mm": z, "pitch_deg": p, "yaw_deg": y, "roll_deg": r}


def test_a_replayed_recordings_truth_and_reference_are_stored_where_they_belong(tmp_path):
    """A campaign on a replayed simulated recording with a truth and a reference: each row's
    ``truth_*`` is the input's /truth and its ``reference_*`` the input's /reference (not
    /truth as the reference), and the campaign's raw recording keeps both as they came in."""
    from tofpose.io.recording import open_recording

    n_in = 5
    source = tmp_path / "both.h5"
    _write_recording_with_both_truths(source, n_in)
    # the simulated turntable only gives the campaign something to move: a replay's
    # frames carry no encoder reading, so nothing of the table reaches the rows
    settings = make_settings(
        tmp_path / "data", camera=f"replay:{source}", motion="sim", sim_time_scale=5.0
    )
    body = {
        "name": "replayed",
        "frames_per_point": 8,
        "settle_s": 0.1,
        "record_raw": True,
        "setpoints": [{"yaw_deg": 0.0}],
    }
    with running_app(settings) as c:
        done = _run(c, body)
        assert done["status"] == "done", done
        items = c.get(f"/api/campaigns/{done['id']}/measurements?limit=100").json()["items"]
        raw = tmp_path / "raw.h5"
        raw.write_bytes(c.get(f"/api/campaigns/{done['id']}/recording.h5").content)
        exact_report = c.get(f"/api/campaigns/{done['id']}/report.json?reference=exact")
    assert len(items) == 8
    with open_recording(source) as src, open_recording(raw) as out:
        assert out.n_frames == len(items)
        assert out.truth_R is not None and out.reference_R is not None
        for k, m in enumerate(items):
            i = (m["frame_index"] - 1) % n_in  # the replay's frame numbers start at 1
            assert m["encoders"] is None
            for got, R, t in (
                (m["truth"], src.truth_R[i], src.truth_t_mm[i]),
                (m["reference"], src.reference_R[i], src.reference_t_mm[i]),
            ):
                assert got == pytest.approx(_facing_pose_columns(R, t), abs=1e-9), (k, i)
            np.testing.assert_array_equal(out.truth_R[k], src.truth_R[i])
            np.testing.assert_array_equal(out.truth_t_mm[k], src.truth_t_mm[i])
            np.testing.assert_array_equal(out.reference_R[k], src.reference_R[i])
            np.testing.assert_array_equal(out.reference_t_mm[k], src.reference_t_mm[i])
        # the two references really differ, so a swap or a copy could not pass
        assert abs(items[0]["truth"]["x_mm"] - items[0]["reference"]["x_mm"]) > 1.0
    assert exact_report.status_code == 200, exact_report.text  # the rows have an exact truth
