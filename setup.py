"""The one build step pyproject.toml cannot declare: the built dashboard (``frontend/dist``)
ships in the wheel as ``backend/dashboard``, where an installed server finds it.

A wheel (``pip install .``, ``pip wheel .``, ``python -m build``) and an sdist always carry
the built dashboard. When ``frontend/dist`` is missing, it is built with npm
(``npm ci && npm run build`` in ``frontend/``); without npm the build fails and says how to
build it. An editable install (``pip install -e .``) needs neither: the server then serves
the checkout's ``frontend/dist`` itself (docs/server.md, "Packaging").
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py
from setuptools.command.sdist import sdist
from setuptools.errors import SetupError

ROOT = Path(__file__).resolve().parent
FRONTEND = ROOT / "frontend"
PACKAGED = Path("backend", "dashboard")  # inside the wheel; backend/settings.py looks here
BUILD_HINT = "make frontend (or: cd frontend && npm ci && npm run build; Node.js 20.19+)"


def is_built(dist: Path) -> bool:
    """A built dashboard: its page and its assets directory."""
    return (dist / "index.html").is_file() and (dist / "assets").is_dir()


def build_frontend(frontend: Path, npm: str) -> None:
    """``npm ci`` from the lock file, then ``npm run build`` (type-check + vite build)."""
    for args in (["ci", "--no-audit", "--no-fund"], ["run", "build"]):
        try:
            subprocess.run([npm, *args], cwd=frontend, check=True)
        except (OSError, subprocess.CalledProcessError) as exc:
            raise SetupError(
                f"tofpose: building the dashboard failed (npm {' '.join(args)} in {frontend}: "
                f"{exc}); fix it, or build it yourself: {BUILD_HINT}"
            ) from exc


def ensure_dashboard(frontend: Path = FRONTEND, npm: str | None = None) -> Path:
    """The built dashboard's directory (``frontend/dist``), built with npm when missing.

    Raises SetupError with a message saying how to build it when it is missing and
    cannot be built here (no npm on PATH, or no frontend sources)."""
    dist = frontend / "dist"
    if is_built(dist):
        return dist
    npm = npm or shutil.which("npm")
    if npm is None or not (frontend / "package.json").is_file():
        why = "npm is not on PATH" if npm is None else f"no frontend sources in {frontend}"
        raise SetupError(
            f"tofpose: the wheel ships the dashboard, but {dist} is not built and {why} to "
            f"build it. Build it first with {BUILD_HINT}, then build the wheel again. An "
            "editable install (pip install -e .) does not need it."
        )
    build_frontend(frontend, npm)
    if not is_built(dist):
        raise SetupError(f"tofpose: npm run build left no dashboard in {dist}")
    return dist


class BuildPyWithDashboard(build_py):
    """build_py, plus the built dashboard copied into the build as ``backend/dashboard``."""

    def run(self) -> None:
        """Build the packages, then copy the dashboard in (not for an editable install)."""
        super().run()
        if self.editable_mode:
            return
        target = Path(self.build_lib) / PACKAGED
        shutil.rmtree(target, ignore_errors=True)
        shutil.copytree(ensure_dashboard(), target)


class SdistWithDashboard(sdist):
    """sdist, with ``frontend/dist`` built first: MANIFEST.in then ships it, so that a
    wheel built from the sdist needs no Node.js."""

    def run(self) -> None:
        """Make sure the dashboard is built, then make the sdist."""
        ensure_dashboard()
        super().run()


if __name__ == "__main__":
    setup(cmdclass={"build_py": BuildPyWithDashboard, "sdist": SdistWithDashboard})
