"""Shared fixtures: the paper camera and target, and simulated frames with known truth;
and the test tiers (``pytest -m unit`` for the fast loop while developing)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tofpose.core.camera import CameraModel
from tofpose.core.catalog import paper_target
from tofpose.core.geometry import RigidTransform, rotation_from_euler_deg
from tofpose.sim.bench import R_FACING
from tofpose.sim.render import SensorModel, render_frame
from tofpose.sim.scene import TargetScene


def facing_pose(distance_mm, pitch_deg=0.0, yaw_deg=0.0, roll_deg=0.0, offset_mm=(0.0, 0.0)):
    """T_camera_target for a target facing the camera, rotated by small Euler angles."""
    R = rotation_from_euler_deg(pitch_deg, yaw_deg, roll_deg) @ R_FACING
    return RigidTransform(R, np.array([offset_mm[0], offset_mm[1], distance_mm], float))


def render(T, *, seed=0, noise=True, scene=None, sensor=None, camera=None):
    camera = camera or CameraModel()
    sensor = sensor or SensorModel(noise=noise)
    rng = np.random.default_rng(seed) if noise else None
    return render_frame(camera, scene or TargetScene(), T, sensor, rng)


@pytest.fixture
def camera():
    return CameraModel()


@pytest.fixture
def catalog():
    return paper_target()


# -- test tiers --------------------------------------------------------------------------
#: tests that drive a browser (Debian's chromium through Playwright)
_BROWSER = ("tests/e2e/",)
#: tests that run the server, devices, subprocesses, clusters or whole benchmarks
_INTEGRATION = (
    "tests/backend/",
    "tests/bench/",
    "tests/frontend/",
    "tests/tofpose/batch/",
    "tests/tofpose/study/",
    "tests/tofpose/io/interop/",
    "tests/tofpose/test_cli.py",
    "tests/tofpose/core/test_threads.py",
    "tests/test_packaging.py",
)
#: long runs under load (memory and rate over seconds of traffic)
_SOAK = ("tests/backend/test_soak.py",)
_ROOT = Path(__file__).resolve().parents[1]


def pytest_collection_modifyitems(config, items) -> None:
    """Every test gets exactly one tier marker from where it lives: ``browser``,
    ``soak``, ``integration`` or ``unit`` (the rest: the pipeline, the simulator and the
    kernels against their oracles), and ``postgres`` besides when it runs against the
    PostgreSQL server (the ``database_url`` fixture's second parameter). ``make test``
    runs them all; ``pytest -m unit`` is the developer's loop."""
    for item in items:
        path = Path(str(item.fspath)).resolve().relative_to(_ROOT).as_posix()
        if path.startswith(_BROWSER):
            item.add_marker(pytest.mark.browser)
        elif path.startswith(_SOAK):
            item.add_marker(pytest.mark.soak)
        elif path.startswith(_INTEGRATION):
            item.add_marker(pytest.mark.integration)
        else:
            item.add_marker(pytest.mark.unit)
        callspec = getattr(item, "callspec", None)
        if callspec is not None and callspec.params.get("database_url") == "postgresql":
            item.add_marker(pytest.mark.postgres)
