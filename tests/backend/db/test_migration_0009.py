"""Migration 0009 (which pose a measurement holds: ``pixel_fit``) keeps the measurements
stored at 0008, with the new column null (the fit did not run live before), and a
measurement stored after it keeps what it says."""

from __future__ import annotations

from sqlalchemy import text

from backend.db.engine import make_engine, upgrade_database


def test_upgrade_from_0008_keeps_the_measurements_with_no_fit(tmp_path):
    engine = make_engine(f"sqlite:///{tmp_path / 'old.db'}")
    upgrade_database(engine, "0008")
    with engine.begin() as conn:
        conn.execute(
            text(
                "INSERT INTO campaigns (id, name, status, status_reason, catalog_name, "
                "frames_per_point, settle_s, lock_timeout_s, requirements, record_raw, notes, "
                "created_at) VALUES (8, 'before the fit', 'done', '', 'paper-target', 1, 0.5, "
                "5.0, '{}', 0, '', '2026-12-01 10:00:00')"
            )
        )
        conn.execute(
            text(
                'INSERT INTO setpoints (id, campaign_id, "index", status) '
                "VALUES (80, 8, 0, 'done')"
            )
        )
        conn.execute(
            text(
                "INSERT INTO measurements (setpoint_id, frame_index, frame_time_s, ok, reason, "
                "n_matched, x_mm) VALUES (80, 3, 0.5, 1, '', 8, 1.5)"
            )
        )
    upgrade_database(engine)
    with engine.begin() as conn:
        assert conn.execute(text("SELECT version_num FROM alembic_version")).scalar() == "0009"
        row = conn.execute(text("SELECT frame_index, x_mm, pixel_fit FROM measurements")).one()
        assert tuple(row) == (3, 1.5, None)
        conn.execute(
            text(
                "INSERT INTO measurements (setpoint_id, frame_index, frame_time_s, ok, reason, "
                "n_matched, pixel_fit) VALUES (80, 4, 0.6, 1, '', 8, 'ok')"
            )
        )
        fits = conn.execute(text("SELECT pixel_fit FROM measurements ORDER BY frame_index"))
        assert [r[0] for r in fits] == [None, "ok"]
    engine.dispose()
