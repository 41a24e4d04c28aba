"""Migration 0008 (campaign camera settings and metadata) keeps a campaign stored at 0007:
its rows, set-points and measurements read back unchanged, with the new fields empty."""

from __future__ import annotations

from sqlalchemy import text
from sqlalchemy.orm import sessionmaker

from backend.db.engine import make_engine, upgrade_database
from backend.services.campaigns.campaign_repository import CampaignRepository


def test_upgrade_from_0007_keeps_a_stored_campaign(tmp_path):
    engine = make_engine(f"sqlite:///{tmp_path / 'old.db'}")
    upgrade_database(engine, "0007")
    with engine.begin() as conn:
        conn.execute(
            text(
                "INSERT INTO campaigns (id, name, status, status_reason, catalog_name, "
                "frames_per_point, settle_s, lock_timeout_s, requirements, camera_settings, "
                "record_raw, notes, created_at) VALUES (7, 'old grid', 'done', '', "
                "'paper-target', 3, 0.5, 5.0, '{\"x_mm\": 6.0}', '{\"frame_rate_hz\": 15.0}', "
                "0, 'kept notes', '2026-11-30 10:00:00')"
            )
        )
        conn.execute(
            text(
                'INSERT INTO setpoints (id, campaign_id, "index", yaw_deg, rail_mm, status) '
                "VALUES (70, 7, 0, 5.0, 12000.0, 'done')"
            )
        )
        conn.execute(
            text(
                "INSERT INTO measurements (setpoint_id, frame_index, frame_time_s, ok, reason, "
                "n_matched, x_mm, lab_truth_x_mm) VALUES (70, 11, 1.25, 1, '', 7, 3.5, 3.0)"
            )
        )
    upgrade_database(engine, "0008")
    with engine.connect() as conn:
        assert conn.execute(text("SELECT version_num FROM alembic_version")).scalar() == "0008"
        m = conn.execute(
            text("SELECT frame_index, x_mm, lab_truth_x_mm, integration_time_us FROM measurements")
        ).one()
    assert tuple(m) == (11, 3.5, 3.0, None)
    upgrade_database(engine)  # the repository reads the head's columns
    c = CampaignRepository(sessionmaker(engine)).get(7)
    assert (c.name, c.status.value, c.notes, c.camera) == (
        "old grid",
        "done",
        "kept notes",
        {"frame_rate_hz": 15.0},
    )
    assert (c.operator, c.target_name, c.camera_serial, c.camera_firmware) == ("", "", "", "")
    assert c.camera_sweep is None
    (sp,) = c.setpoints
    assert (sp.yaw_deg, sp.rail_mm, sp.status, sp.camera) == (5.0, 12000.0, "done", None)
    engine.dispose()
