"""The dashboard's TypeScript types are generated from the server's OpenAPI document;
these fail when either committed file is stale (regenerate: `tofpose openapi --out
frontend/openapi.json && (cd frontend && npm run types)`)."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

from backend.main import openapi_document

FRONTEND = Path(__file__).resolve().parents[2] / "frontend"


def test_the_committed_openapi_document_is_the_servers():
    committed = json.loads((FRONTEND / "openapi.json").read_text())
    assert committed == json.loads(json.dumps(openapi_document())), (
        "frontend/openapi.json is stale: run `tofpose openapi --out frontend/openapi.json`"
    )


def test_the_committed_types_are_generated_from_it(tmp_path):
    out = tmp_path / "schema.d.ts"
    subprocess.run(
        [
            str(FRONTEND / "node_modules" / ".bin" / "openapi-typescript"),
            "openapi.json",
            "-o",
            str(out),
        ],
        cwd=FRONTEND,
        check=True,
        capture_output=True,
    )
    committed = (FRONTEND / "src" / "api" / "schema.d.ts").read_text()
    assert out.read_text() == committed, "schema.d.ts is stale: run `npm run types`"
    assert "ErrorPublic" in committed and "PosePublic" in committed  # error bodies typed
