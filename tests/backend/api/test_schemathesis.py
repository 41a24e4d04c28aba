"""Property-based API test: schemathesis generates requests from our OpenAPI schema,
both valid (positive) and invalid (negative), and sends them, authenticated, to a live
server. No request may produce a server error, and documented responses must match
their schemas.

(We drive the strategies with hypothesis directly: schemathesis' pytest plugin does not
work with the pytest version we use.)
"""

from __future__ import annotations

import pytest
import schemathesis
from hypothesis import HealthCheck, given, settings
from hypothesis.errors import Unsatisfiable
from schemathesis import GenerationMode
from schemathesis.checks import not_a_server_error
from schemathesis.specs.openapi.checks import response_schema_conformance

from tests.backend.conftest import AUTH, LiveServer, make_settings

EXAMPLES_PER_OPERATION = 25


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    with LiveServer(make_settings(tmp_path_factory.mktemp("schemathesis"))) as srv:
        yield srv


@pytest.fixture(scope="module")
def operations(server):
    schema = schemathesis.openapi.from_url(f"{server.base_url}/openapi.json")
    ops = [result.ok() for result in schema.get_all_operations()]
    assert len(ops) >= 12, [op.label for op in ops]
    return ops


@pytest.mark.parametrize("mode", [GenerationMode.POSITIVE, GenerationMode.NEGATIVE])
def test_no_server_errors(server, operations, mode):
    calls = {"n": 0}
    nothing_to_break = []
    for op in operations:

        @given(case=op.as_strategy(generation_mode=mode))
        @settings(
            max_examples=EXAMPLES_PER_OPERATION,
            deadline=None,
            database=None,
            suppress_health_check=list(HealthCheck),
        )
        def run(case):
            calls["n"] += 1
            case.call_and_validate(
                base_url=server.base_url,
                headers=AUTH,
                checks=[not_a_server_error, response_schema_conformance],
            )

        try:
            run()
        except Unsatisfiable:
            # Negative mode on an operation without parameters or body: nothing to violate.
            assert mode is GenerationMode.NEGATIVE
            nothing_to_break.append(op.label)
    assert calls["n"] >= len(operations) - len(nothing_to_break)
    assert len(nothing_to_break) < len(operations) / 2, nothing_to_break
