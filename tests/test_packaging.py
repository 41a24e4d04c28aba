"""Packaging: every package ships, and a non-editable install can create its database."""

from __future__ import annotations

import os
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest
from setuptools import find_packages

ROOT = Path(__file__).resolve().parents[1]


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
        [sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-build-isolation",
         "-w", str(out), str(ROOT)],
        check=True, capture_output=True, text=True,
    )  # fmt: skip
    (whl,) = out.glob("tofpose-*.whl")
    return whl


def test_wheel_carries_the_alembic_scripts(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    versions = sorted(p.name for p in (ROOT / "migrations" / "versions").glob("*.py"))
    assert "backend/migrations/env.py" in names
    assert "backend/migrations/script.py.mako" in names
    assert {f"backend/migrations/versions/{v}" for v in versions} <= names


def test_installed_wheel_creates_a_current_database_outside_the_checkout(wheel, tmp_path):
    """Installed into a bare directory and run from elsewhere (no source tree on the
    path), the server's start-up upgrade finds the bundled migrations."""
    target = tmp_path / "site"
    subprocess.run(
        [sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--target", str(target),
         str(wheel)],
        check=True, capture_output=True, text=True,
    )  # fmt: skip
    db = tmp_path / "lab.db"
    script = (
        "import backend.db.engine as e, sqlalchemy as sa\n"
        f"assert e.MIGRATIONS_DIR.is_relative_to({str(target)!r}), e.MIGRATIONS_DIR\n"
        f"eng = e.make_engine('sqlite:///{db}')\n"
        "e.upgrade_database(eng)\n"
        "print(sorted(sa.inspect(eng).get_table_names()))\n"
    )
    env = {**os.environ, "PYTHONPATH": str(target), "PYTHONSAFEPATH": "1"}
    out = subprocess.run(
        [sys.executable, "-c", script],
        check=True, capture_output=True, text=True, cwd=tmp_path, env=env,
    )  # fmt: skip
    tables = out.stdout
    for name in ("alembic_version", "catalogs", "campaigns", "measurements"):
        assert name in tables
