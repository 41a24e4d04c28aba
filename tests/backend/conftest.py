"""Fixtures for backend tests: an app on a temp SQLite file with simulated devices."""

from __future__ import annotations

import os
import threading
import time
import uuid
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from backend.app import create_app
from backend.drivers.base import CameraFrame, MotionStatus
from backend.drivers.factory import Devices, build_devices
from backend.settings import Settings

TOKEN = "test-token-0123456789"
AUTH = {"Authorization": f"Bearer {TOKEN}"}


def make_settings(data_dir: Path, **kw) -> Settings:
    kw.setdefault("api_token", TOKEN)
    kw.setdefault("frame_rate_hz", 20.0)
    kw.setdefault("retry_backoff_s", (0.02, 0.1))
    kw.setdefault("allowed_hosts", ["testserver"])  # the TestClient's Host header
    kw.setdefault("viser", False)  # the 3-D scene runs where a test asks for it
    # poses from the first frame on (the background compile has a test of its own)
    kw.setdefault("kernels_in_background", False)
    # studies go to a scheduler that is not there (they fail at once, naming it), so that
    # a fuzzer's studies do not load the machine; tests of studies set their own
    kw.setdefault("dask_scheduler", "tcp://127.0.0.1:9")
    return Settings(data_dir=data_dir, **kw)


class FlakyCamera:
    """Wraps a camera; while ``failing`` is set, ``read`` raises like a dropped device."""

    def __init__(self, inner) -> None:
        self.inner = inner
        self.name = inner.name
        self.failing = threading.Event()
        self.reads = 0

    def read(self, timeout_s: float) -> CameraFrame:
        self.reads += 1
        if self.failing.is_set():
            time.sleep(0.01)
            raise ConnectionError("camera unplugged (test)")
        return self.inner.read(timeout_s)

    @property
    def model(self):
        return self.inner.model

    def get_settings(self):
        return self.inner.get_settings()

    def apply_settings(self, s):
        return self.inner.apply_settings(s)

    def close(self) -> None:
        self.inner.close()


class SpyMotion:
    """Wraps a motion driver and records every command that reaches it."""

    def __init__(self, inner) -> None:
        self.inner = inner
        self.name = inner.name
        self.axes = inner.axes
        self.calls: list[tuple[str, dict]] = []

    def move_to(self, setpoints: dict[str, float]) -> None:
        self.calls.append(("move_to", dict(setpoints)))
        self.inner.move_to(setpoints)

    def stop(self) -> None:
        self.calls.append(("stop", {}))
        self.inner.stop()

    def run_profile(self, axis: str, profile) -> None:
        self.calls.append(("run_profile", {"axis": axis, "profile": profile}))
        self.inner.run_profile(axis, profile)

    @property
    def profile_unavailable(self) -> str | None:
        return self.inner.profile_unavailable

    def status(self) -> MotionStatus:
        return self.inner.status()

    def close(self) -> None:
        self.inner.close()


POSTGRES_ENV = "TOFPOSE_TEST_POSTGRES_URL"


@pytest.fixture(params=["sqlite", "postgresql"])
def database_url(request) -> Iterator[str | None]:
    """None (the app's default: an SQLite file in the data directory), then a fresh
    PostgreSQL database on the server named by $TOFPOSE_TEST_POSTGRES_URL (an admin URL,
    e.g. postgresql+psycopg://tofpose:tofpose@127.0.0.1:5432/postgres; .ci/run starts
    Debian's PostgreSQL and sets it)."""
    if request.param == "sqlite":
        yield None
        return
    admin = os.environ.get(POSTGRES_ENV)
    if not admin:
        pytest.skip(f"{POSTGRES_ENV} not set: no PostgreSQL server (.ci/run starts one)")
    from sqlalchemy import create_engine, make_url, text

    name = f"tofpose_test_{uuid.uuid4().hex[:12]}"
    engine = create_engine(admin, isolation_level="AUTOCOMMIT")
    with engine.connect() as conn:
        conn.execute(text(f'CREATE DATABASE "{name}"'))
    yield make_url(admin).set(database=name).render_as_string(hide_password=False)
    with engine.connect() as conn:
        conn.execute(text(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)'))
    engine.dispose()


@pytest.fixture
def settings(tmp_path) -> Settings:
    return make_settings(tmp_path / "data")


@contextmanager
def running_app(settings: Settings, devices: Devices | None = None) -> Iterator[TestClient]:
    with TestClient(create_app(settings, devices)) as client:
        yield client


@pytest.fixture
def client(settings) -> Iterator[TestClient]:
    with running_app(settings) as c:
        yield c


@pytest.fixture
def spy_devices(settings) -> Devices:
    devs = build_devices(settings)
    devs.camera = FlakyCamera(devs.camera)
    devs.motion = SpyMotion(devs.motion)
    return devs


def wait_for(pred: Callable[[], object], timeout_s: float = 10.0, what: str = "condition"):
    """Poll ``pred`` until it returns a truthy value; fail the test after the timeout."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = pred()
        if value:
            return value
        time.sleep(0.02)
    pytest.fail(f"timed out after {timeout_s} s waiting for {what}")


def latest_pose(client: TestClient, after_index: int = 0, ok: bool = True) -> dict:
    """Wait for a pose newer than ``after_index`` (and ok, if asked)."""

    def get():
        r = client.get("/api/pose/latest")
        if r.status_code != 200:
            return None
        p = r.json()
        return p if p["frame_index"] > after_index and (p["ok"] or not ok) else None

    return wait_for(get, what=f"a pose after frame {after_index}")


class LiveServer:
    """The app served by uvicorn on a loopback port (free, or ``port``), in a thread."""

    def __init__(self, settings: Settings, devices: Devices | None = None, port: int = 0) -> None:
        import uvicorn

        from tests.backend.serve_process import free_port

        # the app knows its own port (the 3-D scene names the dashboard's origin by it)
        port = port or free_port()
        settings = settings.model_copy(update={"port": port})
        app = create_app(settings, devices)
        config = uvicorn.Config(
            app,
            host="127.0.0.1",
            port=port,
            log_level="warning",
            timeout_graceful_shutdown=settings.shutdown_timeout_s,
        )
        self.server = uvicorn.Server(config)
        self.thread = threading.Thread(target=self.server.run, daemon=True)

    def __enter__(self) -> LiveServer:
        self.thread.start()
        wait_for(lambda: self.server.started, 20.0, "uvicorn to start")
        port = self.server.servers[0].sockets[0].getsockname()[1]
        self.base_url = f"http://127.0.0.1:{port}"
        self.ws_url = f"ws://127.0.0.1:{port}/ws/live"
        return self

    def __exit__(self, *exc) -> None:
        self.server.should_exit = True
        self.thread.join(15.0)


@pytest.fixture
def live_server(settings) -> Iterator[LiveServer]:
    with LiveServer(settings) as server:
        yield server
