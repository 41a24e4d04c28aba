"""Dynamic campaigns: the motion profile run at a set-point, and whether a measured frame
was taken while it ran.

Revision ID: 0006
Revises: 0005
Create Date: 2026-12-03
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0006"
down_revision = "0005"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("setpoints") as batch:
        batch.add_column(sa.Column("profile", sa.JSON(), nullable=True))
    with op.batch_alter_table("measurements") as batch:
        batch.add_column(sa.Column("in_motion", sa.Boolean(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("measurements") as batch:
        batch.drop_column("in_motion")
    with op.batch_alter_table("setpoints") as batch:
        batch.drop_column("profile")
