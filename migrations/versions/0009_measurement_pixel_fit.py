"""Each measurement says which pose it holds: ``pixel_fit`` "ok" when the live pipeline's
pixel-level fit refined it (the server's ``TOFPOSE_PIXEL_FIT``), else why the centroid
pose stands; null when the fit did not run.

Existing measurements keep every row, with null (the fit did not run live before).

Revision ID: 0009
Revises: 0008
Create Date: 2026-12-08
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0009"
down_revision = "0008"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("measurements") as batch:
        batch.add_column(sa.Column("pixel_fit", sa.Text(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("measurements") as batch:
        batch.drop_column("pixel_fit")
