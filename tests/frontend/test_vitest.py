"""The dashboard's unit tests (vitest, frontend/src/**/*.test.ts: raw frame decoding, colour
maps, the campaign form, the typed client's errors, the polling hook's ordering), run in
`make test` through this file: `npm test` type-checks the sources with the tests (tsc) and
runs them. The raw frame fixture they decode is checked here against the server's encoder,
so that the page and the server cannot drift apart."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np

from backend.services.live.frame_codec import decode_raw_frame, encode_raw_frame

FRONTEND = Path(__file__).resolve().parents[2] / "frontend"
FIXTURE = FRONTEND / "src" / "fixtures" / "raw-frame.json"


def test_the_dashboards_unit_tests_pass():
    npm = shutil.which("npm")
    assert npm, "npm is not on PATH (the dashboard's tests need Node.js)"
    assert (FRONTEND / "node_modules" / ".bin" / "vitest").exists(), (
        "frontend/node_modules lacks vitest: run `make frontend` (npm ci)"
    )
    r = subprocess.run(
        [npm, "test", "--silent"],
        cwd=FRONTEND,
        capture_output=True,
        text=True,
        timeout=600,
        env={**os.environ, "NO_COLOR": "1", "CI": "1"},
    )
    assert r.returncode == 0, f"npm test failed ({r.returncode}):\n{r.stdout}\n{r.stderr}"
    assert " passed" in r.stdout and " failed" not in r.stdout, r.stdout


def test_the_raw_frame_fixture_is_what_the_server_sends():
    fx = json.loads(FIXTURE.read_text())
    nan_for_null = [[np.nan if v is None else v for v in row] for row in fx["distance_mm_in"]]
    message = encode_raw_frame(
        fx["frame_index"],
        np.array(fx["gray_in"], dtype=np.uint16),
        np.array(nan_for_null, dtype=float),
        step=fx["step"],
    )
    assert message.hex() == fx["hex"], "frame_codec's encoding changed: update raw-frame.json"
    index, step, gray, distance = decode_raw_frame(message)
    assert (index, step, gray.shape) == (fx["frame_index"], fx["step"], (fx["height"], fx["width"]))
    assert gray.ravel().tolist() == fx["gray"]
    assert np.nan_to_num(distance, nan=0.0).ravel().tolist() == fx["distance_mm"]
