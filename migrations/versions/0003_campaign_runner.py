"""Campaign runner: states, settle time, requirements, generator, raw recording; exact
and lab truth per measurement, the pipeline's sigmas, one row per frame per set-point.

The three tables of 0002 had no writer before this revision (no API created campaigns),
so they are recreated rather than altered column by column.

Revision ID: 0003
Revises: 0002
Create Date: 2026-11-23
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0003"
down_revision = "0002"
branch_labels = None
depends_on = None

POSE_COLUMNS = ("x_mm", "y_mm", "z_mm", "pitch_deg", "yaw_deg", "roll_deg")
SIGMA_COLUMNS = (
    "sigma_x_mm",
    "sigma_y_mm",
    "sigma_z_mm",
    "sigma_pitch_deg",
    "sigma_yaw_deg",
    "sigma_roll_deg",
)


def _floats(names) -> list[sa.Column]:
    return [sa.Column(c, sa.Float(), nullable=True) for c in names]


def upgrade() -> None:
    op.drop_index("ix_measurements_setpoint_id", table_name="measurements")
    op.drop_table("measurements")
    op.drop_table("setpoints")
    op.drop_index("ix_campaigns_status", table_name="campaigns")
    op.drop_table("campaigns")
    op.create_table(
        "campaigns",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("name", sa.String(length=200), nullable=False),
        sa.Column("status", sa.String(length=16), nullable=False),
        sa.Column("status_reason", sa.Text(), nullable=False),
        sa.Column("catalog_name", sa.String(length=128), nullable=False),
        sa.Column("frames_per_point", sa.Integer(), nullable=False),
        sa.Column("settle_s", sa.Float(), nullable=False),
        sa.Column("lock_timeout_s", sa.Float(), nullable=False),
        sa.Column("requirements", sa.JSON(), nullable=False),
        sa.Column("generator", sa.JSON(), nullable=True),
        sa.Column("camera_settings", sa.JSON(), nullable=True),
        sa.Column("record_raw", sa.Boolean(), nullable=False),
        sa.Column("recording_path", sa.Text(), nullable=True),
        sa.Column("notes", sa.Text(), nullable=False),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("scheduled_at", sa.DateTime(timezone=True), nullable=True),
        sa.Column("started_at", sa.DateTime(timezone=True), nullable=True),
        sa.Column("finished_at", sa.DateTime(timezone=True), nullable=True),
        sa.PrimaryKeyConstraint("id"),
        sa.UniqueConstraint("name"),
    )
    op.create_index("ix_campaigns_status", "campaigns", ["status"])
    op.create_table(
        "setpoints",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("campaign_id", sa.Integer(), nullable=False),
        sa.Column("index", sa.Integer(), nullable=False),
        *_floats(("yaw_deg", "pitch_deg", "roll_deg", "rail_mm")),
        sa.Column("status", sa.String(length=16), nullable=False),
        sa.Column("completed_at", sa.DateTime(timezone=True), nullable=True),
        sa.ForeignKeyConstraint(["campaign_id"], ["campaigns.id"], ondelete="CASCADE"),
        sa.PrimaryKeyConstraint("id"),
        sa.UniqueConstraint("campaign_id", "index", name="uq_setpoint_index"),
    )
    op.create_table(
        "measurements",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("setpoint_id", sa.Integer(), nullable=False),
        sa.Column("frame_index", sa.Integer(), nullable=False),
        sa.Column("frame_time_s", sa.Float(), nullable=False),
        sa.Column("ok", sa.Boolean(), nullable=False),
        sa.Column("reason", sa.Text(), nullable=False),
        sa.Column("n_matched", sa.Integer(), nullable=False),
        sa.Column("residual_mm", sa.Float(), nullable=True),
        *_floats(POSE_COLUMNS),
        *_floats(("qw", "qx", "qy", "qz")),
        *_floats(SIGMA_COLUMNS),
        *_floats(f"truth_{c}" for c in POSE_COLUMNS),
        *_floats(f"lab_truth_{c}" for c in POSE_COLUMNS),
        sa.Column("encoders", sa.JSON(), nullable=True),
        sa.Column("recording_index", sa.Integer(), nullable=True),
        sa.ForeignKeyConstraint(["setpoint_id"], ["setpoints.id"], ondelete="CASCADE"),
        sa.PrimaryKeyConstraint("id"),
        sa.UniqueConstraint("setpoint_id", "frame_index", name="uq_measurement_frame"),
    )
    op.create_index("ix_measurements_setpoint_id", "measurements", ["setpoint_id"])


def downgrade() -> None:
    raise NotImplementedError("0003 recreated the campaign tables; there is no way back")
