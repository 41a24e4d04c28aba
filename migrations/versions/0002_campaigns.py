"""Campaigns, their set-points and per-frame measurements.

Revision ID: 0002
Revises: 0001
Create Date: 2026-11-23
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0002"
down_revision = "0001"
branch_labels = None
depends_on = None

POSE_COLUMNS = ("x_mm", "y_mm", "z_mm", "pitch_deg", "yaw_deg", "roll_deg")


def upgrade() -> None:
    op.create_table(
        "campaigns",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("name", sa.String(length=200), nullable=False),
        sa.Column("status", sa.String(length=16), nullable=False),
        sa.Column("catalog_name", sa.String(length=128), nullable=False),
        sa.Column("frames_per_point", sa.Integer(), nullable=False),
        sa.Column("dwell_s", sa.Float(), nullable=False),
        sa.Column("notes", sa.Text(), nullable=False),
        sa.Column("camera_settings", sa.JSON(), nullable=True),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("started_at", sa.DateTime(timezone=True), nullable=True),
        sa.Column("finished_at", sa.DateTime(timezone=True), nullable=True),
        sa.PrimaryKeyConstraint("id"),
    )
    op.create_index("ix_campaigns_status", "campaigns", ["status"])
    op.create_table(
        "setpoints",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("campaign_id", sa.Integer(), nullable=False),
        sa.Column("index", sa.Integer(), nullable=False),
        sa.Column("yaw_deg", sa.Float(), nullable=True),
        sa.Column("pitch_deg", sa.Float(), nullable=True),
        sa.Column("roll_deg", sa.Float(), nullable=True),
        sa.Column("rail_mm", sa.Float(), nullable=True),
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
        *(sa.Column(c, sa.Float(), nullable=True) for c in POSE_COLUMNS),
        *(sa.Column(c, sa.Float(), nullable=True) for c in ("qw", "qx", "qy", "qz")),
        *(sa.Column(f"truth_{c}", sa.Float(), nullable=True) for c in POSE_COLUMNS),
        sa.Column("encoders", sa.JSON(), nullable=True),
        sa.ForeignKeyConstraint(["setpoint_id"], ["setpoints.id"], ondelete="CASCADE"),
        sa.PrimaryKeyConstraint("id"),
    )
    op.create_index("ix_measurements_setpoint_id", "measurements", ["setpoint_id"])


def downgrade() -> None:
    op.drop_index("ix_measurements_setpoint_id", table_name="measurements")
    op.drop_table("measurements")
    op.drop_table("setpoints")
    op.drop_index("ix_campaigns_status", table_name="campaigns")
    op.drop_table("campaigns")
