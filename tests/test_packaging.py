"""Packaging: every package ships, a non-editable install can create its database and
serves the dashboard (the wheel carries it, setup.py), and the sdist carries what a wheel
built from it needs."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tarfile
import tomllib
import zipfile
from pathlib import Path

import pytest
from setuptools import find_packages

ROOT = Path(__file__).resolve().parents[1]
DIST = ROOT / "frontend" / "dist"  # the built dashboard (make frontend)


def _clean_env(**extra: str) -> dict[str, str]:
    """This environment without TOFPOSE_* settings (a TOFPOSE_FRONTEND_DIR would decide
    where the dashboard is looked for), plus ``extra``."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("TOFPOSE_")}
    return {**env, **extra}


def _declared_packages() -> list[str]:
    with open(ROOT / "pyproject.toml", "rb") as fh:
        return tomllib.load(fh)["tool"]["setuptools"]["packages"]


def test_declared_packages_are_every_package_in_the_tree():
    """The package list is explicit (for the migrations mapping); a new subpackage that is
    not added to it would be missing from the wheel."""
    found = find_packages(str(ROOT), include=["tofpose*", "backend*"])
    expected = sorted(found + ["backend.migrations", "backend.migrations.versions"])
    assert sorted(_declared_packages()) == expected


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("wheel")
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "-q",
            "--no-deps",
            "--no-build-isolation",
            "-w",
            str(out),
            str(ROOT),
        ],
        check=True,
        capture_output=True,
        text=True,
    )
    (whl,) = out.glob("tofpose-*.whl")
    return whl


def test_wheel_carries_the_alembic_scripts(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    versions = sorted(p.name for p in (ROOT / "migrations" / "versions").glob("*.py"))
    assert "backend/migrations/env.py" in names
    assert "backend/migrations/script.py.mako" in names
    assert {f"backend/migrations/versions/{v}" for v in versions} <= names


def test_wheel_carries_the_camera_profiles(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    profiles = sorted((ROOT / "tofpose" / "core" / "profiles").glob("*.json"))
    assert len(profiles) >= 3
    assert {f"tofpose/core/profiles/{p.name}" for p in profiles} <= names


def test_wheel_carries_the_ros2_message_definitions(wheel):
    """The ROS 2 MCAP export declares ROS 2's .msg files, read at run time: they ship."""
    names = set(zipfile.ZipFile(wheel).namelist())
    msgs = sorted((ROOT / "tofpose" / "io" / "interop" / "ros2_msgs").rglob("*.msg"))
    assert len(msgs) >= 10
    assert {p.relative_to(ROOT).as_posix() for p in msgs} <= names
    assert "tofpose/io/interop/ros2_msgs/NOTICE.md" in names


def test_wheel_carries_the_viewer_layouts(wheel):
    """``tofpose export mcap`` copies the shipped Foxglove layout beside its file: it
    ships, with the Rerun blueprint (tofpose/io/interop/viewers.py)."""
    from tofpose.io.interop.viewers import FOXGLOVE_LAYOUT, RERUN_BLUEPRINT

    names = set(zipfile.ZipFile(wheel).namelist())
    for path in (FOXGLOVE_LAYOUT, RERUN_BLUEPRINT):
        assert path.relative_to(ROOT).as_posix() in names


@pytest.fixture(scope="module")
def installed(wheel, tmp_path_factory) -> Path:
    """The wheel installed into a bare directory (run with it as PYTHONPATH)."""
    target = tmp_path_factory.mktemp("site")
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "install",
            "-q",
            "--no-deps",
            "--target",
            str(target),
            str(wheel),
        ],
        check=True,
        capture_output=True,
        text=True,
    )
    return target


def _run_installed(target: Path, script: str, cwd: Path) -> str:
    """Run ``script`` against the installed copy only (no checkout on the path), from
    ``cwd``; its stdout."""
    env = _clean_env(PYTHONPATH=str(target), PYTHONSAFEPATH="1")
    out = subprocess.run(
        [sys.executable, "-c", script],
        check=True,
        capture_output=True,
        text=True,
        cwd=cwd,
        env=env,
    )
    return out.stdout


def test_wheel_carries_the_built_dashboard(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    assets = sorted(p.name for p in (DIST / "assets").iterdir())
    assert assets, "frontend/dist/assets is empty"
    assert "backend/dashboard/index.html" in names
    assert {f"backend/dashboard/assets/{a}" for a in assets} <= names
    page = zipfile.ZipFile(wheel).read("backend/dashboard/index.html")
    assert page == (DIST / "index.html").read_bytes()


def test_installed_wheel_serves_the_dashboard_outside_the_checkout(installed, tmp_path):
    """Run from elsewhere, the installed server finds the wheel's copy of the dashboard
    and serves its page at / and its assets (no lifespan: / needs no database)."""
    script = (
        "import re\n"
        "from fastapi.testclient import TestClient\n"
        "import backend.settings as bs\n"
        "from backend.app import create_app\n"
        f"assert bs.PACKAGED_DASHBOARD.is_relative_to({str(installed)!r}), bs.PACKAGED_DASHBOARD\n"
        f"s = bs.Settings(data_dir={str(tmp_path / 'data')!r}, viser=False,"
        " allowed_hosts=['testserver'])\n"
        "assert s.frontend_dist == bs.PACKAGED_DASHBOARD, s.frontend_dist\n"
        "c = TestClient(create_app(s))\n"
        "r = c.get('/')\n"
        "assert r.status_code == 200, r.status_code\n"
        "for asset in re.findall(r'/assets/[^\"]+', r.text):\n"
        "    assert c.get(asset).status_code == 200, asset\n"
        "print(r.text, end='')\n"
    )
    page = _run_installed(installed, script, cwd=tmp_path)
    assert page == (DIST / "index.html").read_text()
    assert "/assets/" in page


def test_installed_wheel_creates_a_current_database_outside_the_checkout(installed, tmp_path):
    """Installed into a bare directory and run from elsewhere (no source tree on the
    path), the server's start-up upgrade finds the bundled migrations."""
    target = installed
    db = tmp_path / "lab.db"
    script = (
        "import backend.db.engine as e, sqlalchemy as sa\n"
        f"assert e.MIGRATIONS_DIR.is_relative_to({str(target)!r}), e.MIGRATIONS_DIR\n"
        f"eng = e.make_engine('sqlite:///{db}')\n"
        "e.upgrade_database(eng)\n"
        "print(sorted(sa.inspect(eng).get_table_names()))\n"
    )
    tables = _run_installed(target, script, cwd=tmp_path)
    for name in ("alembic_version", "catalogs", "campaigns", "measurements"):
        assert name in tables


@pytest.fixture(scope="module")
def sdist(tmp_path_factory) -> Path:
    """An sdist of the checkout, built as any PEP 517 front end builds one."""
    out = tmp_path_factory.mktemp("sdist")
    script = "import sys\nfrom setuptools import build_meta\nbuild_meta.build_sdist(sys.argv[1])"
    subprocess.run(
        [sys.executable, "-c", script, str(out)],
        check=True,
        capture_output=True,
        text=True,
        cwd=ROOT,
        env=_clean_env(),
    )
    (tar,) = out.glob("tofpose-*.tar.gz")
    return tar


@pytest.fixture
def unpacked_without_dashboard(sdist, tmp_path) -> Path:
    """The sdist unpacked, its built dashboard removed: a source tree never built."""
    with tarfile.open(sdist) as tar:
        tar.extractall(tmp_path, filter="data")
    (tree,) = tmp_path.glob("tofpose-*")
    shutil.rmtree(tree / "frontend" / "dist")
    return tree


def _no_npm_env() -> dict[str, str]:
    """PATH with only this interpreter's directory: no npm (nor node)."""
    return _clean_env(PATH=str(Path(sys.executable).parent))


def test_sdist_carries_the_dashboard_and_its_sources(sdist):
    with tarfile.open(sdist) as tar:
        names = {n.split("/", 1)[1] for n in tar.getnames() if "/" in n}
    assert {"setup.py", "MANIFEST.in", "pyproject.toml", "frontend/dist/index.html"} <= names
    assert {f"frontend/dist/assets/{p.name}" for p in (DIST / "assets").iterdir()} <= names
    sources = {
        "index.html",
        "package.json",
        "package-lock.json",
        "tsconfig.json",
        "vite.config.ts",
        "src/main.tsx",
        "src/api/schema.d.ts",
    }
    assert {f"frontend/{f}" for f in sources} <= names
    assert not any(n.startswith("frontend/node_modules") for n in names)


def test_pip_install_from_the_sdist_ships_the_dashboard(sdist, tmp_path):
    """``pip install`` of the sdist (a copy of the source tree) builds a wheel whose
    dashboard comes from the sdist's frontend/dist: no Node.js needed."""
    target = tmp_path / "site"
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "install",
            "-q",
            "--no-deps",
            "--no-build-isolation",
            "--target",
            str(target),
            str(sdist),
        ],
        check=True,
        capture_output=True,
        text=True,
        env=_no_npm_env(),
    )
    page = target / "backend" / "dashboard" / "index.html"
    assert page.read_bytes() == (DIST / "index.html").read_bytes()


def test_a_wheel_without_a_built_dashboard_or_npm_fails_saying_how_to_build_it(
    unpacked_without_dashboard, tmp_path
):
    run = subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "--no-deps",
            "--no-build-isolation",
            "-w",
            str(tmp_path / "out"),
            str(unpacked_without_dashboard),
        ],
        capture_output=True,
        text=True,
        env=_no_npm_env(),
    )
    assert run.returncode != 0
    text = run.stdout + run.stderr
    assert "is not built and npm is not on PATH" in text, text[-3000:]
    assert "make frontend" in text and "cd frontend && npm ci && npm run build" in text
    assert not list((tmp_path / "out").glob("*.whl"))


def test_an_editable_build_needs_no_dashboard(unpacked_without_dashboard, tmp_path):
    """``pip install -e .`` (make's venv) comes before ``make frontend``: it must not need
    the dashboard; the checkout's frontend/dist is served from where it is."""
    out = tmp_path / "out"
    out.mkdir()
    script = "import sys\nfrom setuptools import build_meta\nbuild_meta.build_editable(sys.argv[1])"
    subprocess.run(
        [sys.executable, "-c", script, str(out)],
        check=True,
        capture_output=True,
        text=True,
        cwd=unpacked_without_dashboard,
        env=_no_npm_env(),
    )
    (whl,) = out.glob("tofpose-*.whl")
    assert not [n for n in zipfile.ZipFile(whl).namelist() if "dashboard/" in n]
