"""The README's quick start, run as written: the request bodies are read out of the
README's code block, so the README cannot drift from what the server accepts. It must
end in a report whose verdict is the right one for the simulated bench: per axis the
same pass/fail as against the pose the simulator rendered, with the reference named
and its own 1-sigma stated."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np

from backend.main import report as report_cli
from tests.backend.api.test_campaigns import _run
from tests.backend.conftest import AUTH, make_settings, running_app

README = Path(__file__).resolve().parents[2] / "README.md"
AXES = ("x_mm", "y_mm", "z_mm", "pitch_deg", "yaw_deg", "roll_deg")


def _quickstart_bodies() -> list[dict]:
    """The ``-d '...'`` JSON bodies of the quick start's code block, in order."""
    text = README.read_text()
    section = text[text.index("## Run a campaign and get its report") :]
    block = section[section.index("```sh") : section.index("```", section.index("```sh") + 5)]
    return [json.loads(b) for b in re.findall(r"-d '(\{.*?\})'", block, flags=re.DOTALL)]


def test_the_readme_quick_start_ends_in_the_right_verdict(tmp_path, capsys):
    cal_body, calibration_body, grid_body = _quickstart_bodies()
    settings = make_settings(tmp_path / "data", sim_time_scale=5.0, frame_rate_hz=20.0)
    with running_app(settings) as c:
        cal = _run(c, cal_body, timeout_s=300)
        assert (cal["id"], cal["status"]) == (1, "done"), cal  # the README says campaign 1
        r = c.post("/api/calibrations", json=calibration_body, headers=AUTH)
        assert r.status_code == 201 and r.json()["id"] == 1, r.text
        grid = _run(c, grid_body, timeout_s=120)
        assert (grid["id"], grid["status"]) == (2, "done"), grid
        base = "/api/campaigns/2/report.json"
        calibrated = c.get(base + "?calibration=1").json()
        exact = c.get(base + "?reference=exact").json()
        nominal = c.get(base).json()
    over_cal, over_exact = calibrated["overall"]["axes"], exact["overall"]["axes"]
    verdicts = {a: (over_cal[a]["passed"], over_exact[a]["passed"]) for a in AXES}
    with capsys.disabled():
        print(
            "max |error| calibrated / exact:",
            {a: (over_cal[a]["max_abs"], over_exact[a]["max_abs"]) for a in AXES},
            verdicts,
        )
    own = calibrated["calibration"]
    # the calibrated reference errs by the calibration's own stated 1-sigma (mount and
    # placement, in the axis's unit): the two references' largest errors differ by at
    # most that error, so they must agree to 3 of its sigmas (a fixed 15 % of the
    # requirement, 0.0225 deg in pitch, was ~2 of them: 1 run in 4 failed alone)
    unit_sigma = {
        "deg": np.hypot(own["mount_sigma_deg"], own["placement_sigma_deg"]),
        "mm": np.hypot(own["mount_sigma_mm"], own["placement_sigma_mm"]),
    }
    for a, (cal_v, exact_v) in verdicts.items():
        # where the rendered pose's own error lies within the margin of the requirement,
        # the reference's error can tip the verdict either way: there the errors must
        # agree to that margin; everywhere else the verdict must be the same
        req = calibrated["requirements"][a]
        margin = max(0.15 * req, 3.0 * unit_sigma[a.rsplit("_", 1)[1]])
        assert abs(over_cal[a]["max_abs"] - over_exact[a]["max_abs"]) < margin, a
        if abs(over_exact[a]["max_abs"] - req) > margin:
            assert cal_v == exact_v, (a, verdicts)
    # the uncalibrated reference carries the bench's own ~11 mm: far from the rendered pose
    assert max(nominal["overall"]["axes"][a]["rms"] for a in ("x_mm", "y_mm")) > 3.0 * max(
        over_cal[a]["rms"] for a in ("x_mm", "y_mm")
    )
    assert own["id"] == 1 and own["name"] == "bench-1"
    assert 0 < own["mount_sigma_mm"] < 1.0 and 0 < own["placement_sigma_deg"] < 0.05
    # the CLI takes the same option and writes the same verdict
    out = tmp_path / "report.json"
    code = report_cli(
        {
            "campaign_id": 2,
            "db": settings.resolved_database_url,
            "format": "json",
            "reference": "lab",
            "calibration": 1,
            "out": str(out),
        }
    )
    assert code == 0 and "reference calibration 1" in capsys.readouterr().out
    from_cli = json.loads(out.read_text())
    assert {a: from_cli["overall"]["axes"][a]["passed"] for a in AXES} == {
        a: v[0] for a, v in verdicts.items()
    }
