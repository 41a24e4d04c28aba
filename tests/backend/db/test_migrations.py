"""The Alembic migrations create exactly the SQLAlchemy models, and upgrade old files."""

from __future__ import annotations

import sqlite3

from alembic.autogenerate import compare_metadata
from alembic.migration import MigrationContext
from alembic.script import ScriptDirectory
from sqlalchemy import inspect, text

from backend.db.engine import alembic_config, make_engine, upgrade_database
from backend.db.models import Base
from tests.backend.conftest import running_app


def test_migrations_match_the_models(tmp_path, database_url):
    """On SQLite and on PostgreSQL: upgrading an empty database gives exactly the models."""
    engine = make_engine(database_url or f"sqlite:///{tmp_path / 'm.db'}")
    upgrade_database(engine)
    with engine.connect() as conn:
        diff = compare_metadata(MigrationContext.configure(conn), Base.metadata)
    assert diff == []
    engine.dispose()


def test_empty_file_becomes_a_current_wal_database(tmp_path):
    path = tmp_path / "empty.db"
    path.touch()
    engine = make_engine(f"sqlite:///{path}")
    upgrade_database(engine)
    with engine.connect() as conn:
        assert conn.execute(text("PRAGMA journal_mode")).scalar() == "wal"
        head = ScriptDirectory.from_config(alembic_config()).get_current_head()
        assert head is not None and head >= "0009"
        assert conn.execute(text("SELECT version_num FROM alembic_version")).scalar() == head
    assert {"catalogs", "campaigns", "setpoints", "measurements"} <= set(
        inspect(engine).get_table_names()
    )
    engine.dispose()


def test_an_old_database_is_upgraded_at_start_keeping_its_data(tmp_path, settings):
    db = settings.data_dir / "tofpose.db"
    settings.data_dir.mkdir(parents=True)
    engine = make_engine(f"sqlite:///{db}")
    upgrade_database(engine, "0001")  # the schema of an older release
    with engine.begin() as conn:
        conn.execute(
            text("INSERT INTO catalogs (name, catalog_json, created_at) VALUES (:n, :j, :t)"),
            {
                "n": "old-target",
                "t": "2026-01-01 00:00:00",
                "j": '{"name": "old-target", "reflectors": ['
                '{"id": 1, "position_mm": [0, 0, 0], "diameter_mm": 50},'
                '{"id": 2, "position_mm": [300, 0, 0], "diameter_mm": 50},'
                '{"id": 3, "position_mm": [0, 200, 40], "diameter_mm": 50}]}',
            },
        )
    engine.dispose()
    assert "campaigns" not in _tables(db)
    with running_app(settings) as c:
        names = [x["name"] for x in c.get("/api/catalogs").json()]
        assert "old-target" in names
    assert {"campaigns", "setpoints", "measurements"} <= _tables(db)


def test_campaign_rows_cascade_to_setpoints_and_measurements(tmp_path):
    from sqlalchemy.orm import Session

    from backend.db.models import CampaignRow, MeasurementRow, SetPointRow

    engine = make_engine(f"sqlite:///{tmp_path / 'c.db'}")
    upgrade_database(engine)
    with Session(engine) as s:
        camp = CampaignRow(name="yaw sweep", catalog_name="paper-target", requirements={})
        sp = SetPointRow(index=0, yaw_deg=10.0)
        sp.measurements.append(
            MeasurementRow(frame_index=1, frame_time_s=0.1, ok=True, x_mm=1.0, truth_x_mm=1.2)
        )
        camp.setpoints.append(sp)
        s.add(camp)
        s.commit()
        assert s.get(MeasurementRow, 1).setpoint.campaign.name == "yaw sweep"
        s.delete(camp)
        s.commit()
        assert s.query(MeasurementRow).count() == 0
    engine.dispose()


def _tables(path) -> set[str]:
    with sqlite3.connect(path) as conn:
        return {r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type='table'")}
