"""The API contract: schemathesis' own command line, every check and every phase
(examples, coverage, fuzzing, stateful), authenticated, against a live server. Any
undocumented status code, header or body, a 5xx, a schema-valid request refused or an
invalid one accepted, a wrong ``Allow`` header, an auth requirement the document does not
state... fails the run. New operations join automatically.

The command is the one docs/server.md gives; ``schemathesis.toml`` at the repository root
holds the one documented exception (createCatalog's semantic 422).
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import httpx
import pytest

from tests.backend.conftest import AUTH, TOKEN, LiveServer, make_settings

REPO = Path(__file__).resolve().parents[3]
EXAMPLES_PER_OPERATION = 25


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    settings = make_settings(tmp_path_factory.mktemp("schemathesis"))
    with LiveServer(settings) as srv:
        yield srv


def test_schemathesis_all_checks_and_phases_pass(server):
    cli = Path(sys.executable).with_name("schemathesis")
    cmd = [
        str(cli), "run", f"{server.base_url}/openapi.json",
        "--checks", "all", "--phases", "examples,coverage,fuzzing,stateful",
        "-H", f"Authorization: Bearer {TOKEN}",
        "--max-examples", str(EXAMPLES_PER_OPERATION), "--seed", "1",
    ]  # fmt: skip
    run = subprocess.run(
        cmd, cwd=REPO, capture_output=True, text=True, timeout=900,
        env={**os.environ, "NO_COLOR": "1"},
    )  # fmt: skip
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
        if op_id == "getHealth":
            assert sec == [{}]
        elif method == "get":
            assert sec == [{}, {"HTTPBearer": []}], op_id
        else:
            assert sec == [{"HTTPBearer": []}], op_id
            assert {"401", "413"} <= codes, op_id
            h = op["responses"]["401"]["headers"]
            assert "WWW-Authenticate" in h
        for code in codes - {"200", "201", "202", "422"}:
            content = op["responses"][code].get("content", {})
            assert "application/json" in content, (op_id, code)
    assert ops["createCatalog"][1]["responses"]["409"]
    assert ops["getCatalog"][1]["responses"]["404"]
    move = doc["components"]["schemas"]["MoveRequest"]
    assert move["minProperties"] == 1
    assert move["properties"]["yaw_deg"]["minimum"] == -170.0


def test_allow_lists_every_method_of_a_path(server):
    r = httpx.delete(f"{server.base_url}/api/camera/settings", headers=AUTH)
    assert r.status_code == 405
    assert r.headers["allow"] == "GET, PUT"
