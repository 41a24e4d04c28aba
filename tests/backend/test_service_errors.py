"""The services' errors are answered in one place (``backend.app.SERVICE_ERRORS`` and the
handlers beside it): each with its status and its own sentence, whatever route lets it
through."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from backend.app import SERVICE_ERRORS, create_app
from backend.services.heavy_work import HeavyWorkBusyError
from backend.services.jobs.reprocessing import ReprocessRequestError
from backend.services.motion import MotionDeviceError, MotionLimitError
from tests.backend.conftest import make_settings
from tofpose.lab.motion_profile import LimitProblem


@pytest.fixture
def raising(tmp_path):
    """A client of the app (not started: the answers need no service) with a route that
    raises whatever the test puts in ``error[0]``."""
    app = create_app(make_settings(tmp_path))
    error: list[Exception] = []

    @app.get("/test/raise")
    def raise_it():
        raise error[0]

    return TestClient(app), error


@pytest.mark.parametrize(
    "error_class, status", list(SERVICE_ERRORS.items()), ids=lambda v: getattr(v, "__name__", v)
)
def test_each_service_error_has_its_status_and_its_own_sentence(raising, error_class, status):
    client, error = raising
    error.append(error_class("the service's own sentence"))
    r = client.get("/test/raise")
    assert (r.status_code, r.json()) == (status, {"detail": "the service's own sentence"})


def test_a_busy_pool_says_when_to_try_again(raising):
    client, error = raising
    error.append(HeavyWorkBusyError("busy with 10 others", retry_after_s=7))
    r = client.get("/test/raise")
    assert r.status_code == 503 and r.headers["Retry-After"] == "7"
    assert r.json() == {"detail": "busy with 10 others"}


def test_a_motion_device_failure_says_what_was_refused(raising):
    client, error = raising
    error.append(MotionDeviceError(ConnectionError("link down"), "the move was not sent"))
    r = client.get("/test/raise")
    assert (r.status_code, r.json()) == (503, {"detail": "the move was not sent: link down"})


@pytest.mark.parametrize(
    "error, detail",
    [
        (
            MotionLimitError(
                [LimitProblem("yaw_deg", "yaw 200 deg is beyond +170"), LimitProblem("", "no axis")]
            ),
            [
                {"loc": ["body", "yaw_deg"], "msg": "yaw 200 deg is beyond +170"},
                {"loc": ["body"], "msg": "no axis"},
            ],
        ),
        (
            ReprocessRequestError("camera", "not a camera JSON"),
            [{"loc": ["body", "camera"], "msg": "not a camera JSON"}],
        ),
        (
            ReprocessRequestError("campaign_id", "its recording cannot be read"),
            [{"loc": ["path", "campaign_id"], "msg": "its recording cannot be read"}],
        ),
    ],
    ids=["motion limits", "reprocess body", "reprocess path"],
)
def test_a_refused_request_is_a_422_at_the_field_that_sets_it(raising, error, detail):
    client, errors = raising
    errors.append(error)
    r = client.get("/test/raise")
    assert r.status_code == 422
    assert r.json() == {"detail": [{**d, "type": "value_error"} for d in detail]}
