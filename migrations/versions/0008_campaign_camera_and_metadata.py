"""Campaigns with camera settings per set-point (or a sweep) and metadata: operator,
target, the camera's model, serial and firmware; each measurement's integration time.

Existing campaigns keep every row: the new text columns are "" and the JSON and float
columns null (the camera as it was, integration time not recorded).

Revision ID: 0008
Revises: 0007
Create Date: 2026-12-06
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0008"
down_revision = "0007"
branch_labels = None
depends_on = None

TEXT_COLUMNS = ("operator", "target_name", "camera_model", "camera_serial", "camera_firmware")


def upgrade() -> None:
    with op.batch_alter_table("campaigns") as batch:
        batch.add_column(sa.Column("camera_sweep", sa.JSON(), nullable=True))
        for name in TEXT_COLUMNS:
            batch.add_column(
                sa.Column(name, sa.String(length=200), nullable=False, server_default="")
            )
    with op.batch_alter_table("setpoints") as batch:
        batch.add_column(sa.Column("camera", sa.JSON(), nullable=True))
    with op.batch_alter_table("measurements") as batch:
        batch.add_column(sa.Column("integration_time_us", sa.Float(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("measurements") as batch:
        batch.drop_column("integration_time_us")
    with op.batch_alter_table("setpoints") as batch:
        batch.drop_column("camera")
    with op.batch_alter_table("campaigns") as batch:
        for name in reversed(TEXT_COLUMNS):
            batch.drop_column(name)
        batch.drop_column("camera_sweep")
