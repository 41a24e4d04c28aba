"""The relative-state filter's rates, velocities, their sigmas and status per measurement.

Revision ID: 0005
Revises: 0004
Create Date: 2026-12-02
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0005"
down_revision = "0004"
branch_labels = None
depends_on = None

#: the new float columns of ``measurements`` (backend.db.models.MeasurementRow)
STATE_COLUMNS = tuple(
    f"{prefix}{q}_{axis}_{unit}"
    for prefix in ("", "sigma_")
    for q, unit in (("rate", "deg_s"), ("vel", "mm_s"))
    for axis in "xyz"
)


def upgrade() -> None:
    with op.batch_alter_table("measurements") as batch:
        for name in STATE_COLUMNS:
            batch.add_column(sa.Column(name, sa.Float(), nullable=True))
        batch.add_column(sa.Column("filter_status", sa.String(length=16), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("measurements") as batch:
        batch.drop_column("filter_status")
        for name in reversed(STATE_COLUMNS):
            batch.drop_column(name)
