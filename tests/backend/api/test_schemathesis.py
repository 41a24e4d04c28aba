"""The API contract: schemathesis' own command line, every check and every phase
(examples, coverage, fuzzing, stateful), authenticated, against a live server. Any
undocumented status code, header or body, a 5xx, a schema-valid request refused or an
invalid one accepted, a wrong ``Allow`` header, an auth requirement the document does not
state... fails the run. New operations join automatically.

The command is the one docs/server.md gives; ``schemathesis.toml`` at the repository root
holds the documented exceptions (the semantic 422s of createCatalog, createCampaign and
createCalibration: what JSON Schema cannot say). That a campaign takes ``setpoints`` or a
``generator``, not both, it can say: CampaignCreate's ``oneOf``, checked below.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import uuid
from pathlib import Path

import httpx
import jsonschema
import pytest

from tests.backend.conftest import AUTH, TOKEN, LiveServer, make_settings

REPO = Path(__file__).resolve().parents[3]
EXAMPLES_PER_OPERATION = 25


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    # 5 frames/s: the fuzzer starts recordings of the live stream (two at most, until the
    # server stops), which write ~0.3 MB a frame into the temporary data directory
    settings = make_settings(tmp_path_factory.mktemp("schemathesis"), frame_rate_hz=5.0)
    with LiveServer(settings) as srv:
        yield srv


def test_schemathesis_all_checks_and_phases_pass(server):
    cli = Path(sys.executable).with_name("schemathesis")
    cmd = [
        str(cli),
        "run",
        f"{server.base_url}/openapi.json",
        "--checks",
        "all",
        "--phases",
        "examples,coverage,fuzzing,stateful",
        "-H",
        f"Authorization: Bearer {TOKEN}",
        "--max-examples",
        str(EXAMPLES_PER_OPERATION),
        "--seed",
        "1",
    ]
    run = subprocess.run(
        cmd,
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=900,
        env={**os.environ, "NO_COLOR": "1"},
    )
    assert run.returncode == 0, run.stdout[-6000:] + run.stderr[-2000:]
    assert "Tested: 14" in run.stdout or "Tested:" in run.stdout
    # an operation for which nothing was generated would pass vacuously ("2020 generated"
    # is fine: a whole number, not its tail)
    assert not re.search(r"(?<!\d)0 generated", run.stdout), run.stdout[-2000:]


def test_the_document_states_errors_security_and_ids(server):
    doc = httpx.get(f"{server.base_url}/openapi.json").json()
    ops = {
        op["operationId"]: (method, op)
        for item in doc["paths"].values()
        for method, op in item.items()
    }
    assert {"listCatalogs", "createCatalog", "moveAxes", "stopMotion", "getLatestPose"} <= set(ops)
    for op_id, (method, op) in ops.items():
        codes = set(op["responses"])
        sec = op.get("security")
        admin = "admin" in op.get("tags", [])
        if op_id == "getHealth":
            assert sec == [{}]
        elif method == "get" and not admin:
            assert sec == [{}, {"HTTPBearer": []}], op_id
            assert "403" not in codes, op_id  # any key may read
        else:  # state changes (operate) and the admin operations need a key with that scope
            assert sec == [{"HTTPBearer": []}], op_id
            assert {"401", "403"} <= codes, op_id
            assert method in ("get", "delete") or "413" in codes, op_id
            h = op["responses"]["401"]["headers"]
            assert "WWW-Authenticate" in h
        for code in codes - {"200", "201", "202", "204", "422"}:
            content = op["responses"][code].get("content", {})
            assert "application/json" in content, (op_id, code)
    assert {"listAudit", "listKeys", "createKey", "revokeKey"} <= set(ops)
    assert ops["createCatalog"][1]["responses"]["409"]
    assert ops["getCatalog"][1]["responses"]["404"]
    move = doc["components"]["schemas"]["MoveRequest"]
    assert move["minProperties"] == 1
    assert move["properties"]["yaw_deg"]["minimum"] == -170.0


SETPOINTS = [{"yaw_deg": 0.0}]
GENERATOR = {"kind": "stability", "rail_mm": 12000.0}


@pytest.mark.parametrize(
    ("fields", "valid"),
    [
        ({"setpoints": SETPOINTS}, True),
        ({"generator": GENERATOR}, True),
        ({"setpoints": SETPOINTS, "generator": None}, True),
        ({"setpoints": None, "generator": GENERATOR}, True),
        ({"setpoints": SETPOINTS, "generator": GENERATOR}, False),
        ({}, False),
        ({"setpoints": None, "generator": None}, False),
    ],
)
def test_the_document_says_setpoints_or_generator_and_the_server_agrees(server, fields, valid):
    """CampaignCreate's oneOf: exactly one of ``setpoints`` and ``generator``, the other
    absent or null. A body the document calls invalid is the one the server refuses."""
    doc = httpx.get(f"{server.base_url}/openapi.json").json()
    schema = {"$ref": "#/components/schemas/CampaignCreate", "components": doc["components"]}
    body = {"name": f"one-of-{uuid.uuid4().hex[:8]}", **fields}
    assert jsonschema.Draft202012Validator(schema).is_valid(body) is valid
    r = httpx.post(f"{server.base_url}/api/campaigns", json=body, headers=AUTH)
    assert r.status_code == (201 if valid else 422), r.text


def test_allow_lists_every_method_of_a_path(server):
    r = httpx.delete(f"{server.base_url}/api/camera/settings", headers=AUTH)
    assert r.status_code == 405
    assert r.headers["allow"] == "GET, PUT"
