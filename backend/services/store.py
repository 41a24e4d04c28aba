"""Small persistence helpers: the database's health, device settings and user catalogs."""

from __future__ import annotations

from typing import Any

from sqlalchemy import Engine, select, text
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from backend.db.models import CatalogRow, DeviceSettingsRow, utcnow
from tofpose.core.catalog import BUILTIN_CATALOGS, Catalog


def database_answers(engine: Engine) -> bool:
    """Whether the database answers a trivial query now."""
    try:
        with engine.connect() as conn:
            conn.execute(text("SELECT 1"))
    except Exception:
        return False
    return True


def load_device_settings(session: Session, device: str) -> dict[str, Any] | None:
    row = session.scalar(select(DeviceSettingsRow).where(DeviceSettingsRow.device == device))
    return dict(row.settings) if row is not None else None


def save_device_settings(session: Session, device: str, settings: dict[str, Any]) -> None:
    row = session.scalar(select(DeviceSettingsRow).where(DeviceSettingsRow.device == device))
    if row is None:
        session.add(DeviceSettingsRow(device=device, settings=settings))
    else:
        row.settings = settings
        row.updated_at = utcnow()
    session.commit()


def stored_catalogs(session: Session) -> list[tuple[str, Catalog]]:
    rows = session.scalars(select(CatalogRow).order_by(CatalogRow.id)).all()
    return [(r.name, Catalog.from_json(r.catalog_json)) for r in rows]


def find_catalog(session: Session, name: str) -> Catalog | None:
    """A built-in or stored catalog by name, or None."""
    if name in BUILTIN_CATALOGS:
        return BUILTIN_CATALOGS[name]()
    row = session.scalar(select(CatalogRow).where(CatalogRow.name == name))
    return Catalog.from_json(row.catalog_json) if row is not None else None


class NameTakenError(ValueError):
    """A row with this unique name already exists (possibly inserted a moment ago by a
    concurrent request: the database's unique constraint is the arbiter, not a prior
    look-up)."""


def commit_unique(session: Session, what: str) -> None:
    """Commit; a unique-constraint violation (a concurrent request took the name first)
    rolls back and becomes ``NameTakenError(f"{what} already exists")``."""
    try:
        session.commit()
    except IntegrityError as exc:
        session.rollback()
        raise NameTakenError(f"{what} already exists") from exc


def add_catalog(session: Session, name: str, catalog: Catalog) -> None:
    """Store a user catalog; raises ``NameTakenError`` if the name exists (built-in or stored)."""
    if name in BUILTIN_CATALOGS:
        raise NameTakenError(f"a catalog named {name!r} already exists (built in)")
    session.add(CatalogRow(name=name, catalog_json=catalog.to_json()))
    commit_unique(session, f"a catalog named {name!r}")
